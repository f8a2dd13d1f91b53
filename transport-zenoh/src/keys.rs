//! The run's Zenoh key space: every key a run uses lies under `formation/<run>/`.
//!
//! | key | payload | who puts → who subscribes |
//! |---|---|---|
//! | `formation/<run>/robot/<i>/hello` | `HelloMsg` | candidate agents → world |
//! | `formation/<run>/robot/<i>/welcome` | `WelcomeMsg` | world → candidates |
//! | `formation/<run>/robot/<i>/<n>/scan` | `ScanMsg` | world → agent `i` |
//! | `formation/<run>/robot/<i>/<n>/cmd` | `CmdMsg` | agent `i` → world |
//! | `formation/<run>/robot/<i>/<n>/control` | `ControlMsg` | world → agent `i` |
//! | `formation/<run>/robot/<i>/<n>/status` | `StatusMsg` | agent `i` → world |
//! | `formation/<run>/swap/request` | `SwapRequestMsg` | `formation swap` → world |
//! | `formation/<run>/swap/reply` | `SwapReplyMsg` | world → `formation swap` |
//! | `formation/<run>/record/live` | live-recording messages (`formation_record::live`) | world → `formation record --connect` |
//! | `formation/<run>/record/setup` | queryable: the run under way's setup | world → a recorder that joined late |
//! | `formation/<run>/world` | liveliness token | world |
//! | `formation/<run>/robot/<i>/<n>/agent/<pid>` | liveliness token | agent `i` |
//!
//! The data keys are the iceoryx2 service names ([`formation_proto::wire`]), so both transports
//! name a channel alike; `<n>` is the incarnation, the agent's accepted nonce in 16 hex digits.

use formation_proto::wire::RunId;

/// The world's liveliness token.
pub fn world_token(run: &RunId) -> String {
    format!("formation/{run}/world")
}

/// The liveliness token of agent process `pid` driving robot `robot` as incarnation
/// `incarnation`.
pub fn agent_token(run: &RunId, robot: usize, incarnation: u64, pid: u32) -> String {
    format!("formation/{run}/robot/{robot}/{incarnation:016x}/agent/{pid}")
}

/// The world's record channel: every run's setup, ticks and end, for remote recorders.
pub fn record_live(run: &RunId) -> String {
    format!("formation/{run}/record/live")
}

/// The world's queryable of the setup of the run under way (for a recorder that joined late).
pub fn record_setup(run: &RunId) -> String {
    format!("formation/{run}/record/setup")
}

/// Every agent's liveliness token of the run.
pub fn agent_tokens(run: &RunId) -> String {
    format!("formation/{run}/robot/*/*/agent/*")
}

/// `(robot, incarnation, pid)` of an agent token's key; `None` for any other key.
pub fn parse_agent_token(run: &RunId, key: &str) -> Option<(usize, u64, u32)> {
    let rest = key.strip_prefix(&format!("formation/{run}/robot/"))?;
    let mut parts = rest.split('/');
    let robot = parts.next()?.parse().ok()?;
    let incarnation = u64::from_str_radix(parts.next()?, 16).ok()?;
    if parts.next()? != "agent" {
        return None;
    }
    let pid = parts.next()?.parse().ok()?;
    parts.next().is_none().then_some((robot, incarnation, pid))
}

/// Everything of robot `robot` in the run (its lobby, every incarnation).
pub fn robot_space(run: &RunId, robot: usize) -> String {
    format!("formation/{run}/robot/{robot}/**")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn agent_tokens_round_trip_and_other_keys_are_not_tokens() {
        let run = RunId::new("t1").unwrap();
        let key = agent_token(&run, 2, 0xab, 4321);
        assert_eq!(key, "formation/t1/robot/2/00000000000000ab/agent/4321");
        assert_eq!(parse_agent_token(&run, &key), Some((2, 0xab, 4321)));
        let other = RunId::new("t2").unwrap();
        for bad in [
            agent_token(&other, 2, 0xab, 4321),
            format!("{key}/x"),
            "formation/t1/robot/2/00000000000000ab/scan".to_string(),
            "formation/t1/robot/x/00000000000000ab/agent/1".to_string(),
            world_token(&run),
        ] {
            assert_eq!(parse_agent_token(&run, &bad), None, "{bad}");
        }
    }
}

//! Deliberate misbehaviour for fault-injection tests: an agent that crashes, hangs, answers late
//! or sends NaN after a number of ticks. Off unless `--fault` (or `FORMATION_AGENT_FAULT`) names a
//! mode; every command it alters carries the fault-injected status bit.

use std::time::Duration;

/// One misbehaviour mode. Syntax: `crash-after=N`, `hang-after=N`, `late-ms=X`, `nan-after=N`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fault {
    /// Abort the process (no cleanup, like a crash) after answering N ticks.
    CrashAfter(u64),
    /// Stop answering (and stop reacting to anything) after answering N ticks.
    HangAfter(u64),
    /// Sleep this long before publishing every command.
    LateBy(Duration),
    /// Publish NaN wheel speeds from the N-th answered tick on.
    NanAfter(u64),
}

/// Why a fault spec was rejected.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "fault {spec:?} is not valid: use crash-after=N, hang-after=N, late-ms=X or nan-after=N \
     (N, X: whole numbers)"
)]
pub struct FaultSpecError {
    /// The rejected text.
    pub spec: String,
}

impl std::str::FromStr for Fault {
    type Err = FaultSpecError;

    fn from_str(spec: &str) -> Result<Fault, FaultSpecError> {
        let error = || FaultSpecError {
            spec: spec.to_owned(),
        };
        let (mode, value) = spec.split_once('=').ok_or_else(error)?;
        let n: u64 = value.trim().parse().map_err(|_| error())?;
        match mode.trim() {
            "crash-after" => Ok(Fault::CrashAfter(n)),
            "hang-after" => Ok(Fault::HangAfter(n)),
            "late-ms" => Ok(Fault::LateBy(Duration::from_millis(n))),
            "nan-after" => Ok(Fault::NanAfter(n)),
            _ => Err(error()),
        }
    }
}

/// What to do with the command about to be published, the `answered`-th of this process.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FaultAction {
    /// Publish it as it is.
    None,
    /// Abort the process now.
    Crash,
    /// Never answer again.
    Hang,
    /// Sleep, then publish.
    Delay(Duration),
    /// Publish NaN instead.
    Nan,
}

impl Fault {
    /// The action for the command after `answered` commands were already published.
    pub fn action(&self, answered: u64) -> FaultAction {
        match *self {
            Fault::CrashAfter(n) if answered >= n => FaultAction::Crash,
            Fault::HangAfter(n) if answered >= n => FaultAction::Hang,
            Fault::LateBy(d) => FaultAction::Delay(d),
            Fault::NanAfter(n) if answered >= n => FaultAction::Nan,
            _ => FaultAction::None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn specs_parse_and_bad_ones_are_refused() {
        assert_eq!("crash-after=5".parse(), Ok(Fault::CrashAfter(5)));
        assert_eq!(
            "late-ms=80".parse(),
            Ok(Fault::LateBy(Duration::from_millis(80)))
        );
        for bad in ["crash", "crash-after=x", "explode=3", "nan-after=-1"] {
            assert!(bad.parse::<Fault>().is_err(), "{bad}");
        }
    }

    #[test]
    fn faults_trigger_after_the_given_number_of_answers() {
        let crash = Fault::CrashAfter(3);
        assert_eq!(crash.action(2), FaultAction::None);
        assert_eq!(crash.action(3), FaultAction::Crash);
        assert_eq!(Fault::NanAfter(0).action(0), FaultAction::Nan);
        assert_eq!(Fault::HangAfter(1).action(0), FaultAction::None);
        assert_eq!(
            Fault::LateBy(Duration::from_millis(5)).action(0),
            FaultAction::Delay(Duration::from_millis(5))
        );
    }
}

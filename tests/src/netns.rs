//! Two network namespaces joined by a veth pair, for the Zenoh tests across a network: the world
//! runs in one, the agents in the other, and only the veth joins them (the tests keep Zenoh's
//! shared memory off, since `/dev/shm` is shared between namespaces).
//!
//! [`NetPair::create`] needs root and `ip netns`; where either is missing it returns the reason,
//! and the tests fail with it. Every pair has names of its own and is deleted on drop (deleting
//! a namespace deletes its end of the veth, and with it the other end).

use std::path::Path;
use std::process::{Command, Stdio};
use std::sync::atomic::{AtomicUsize, Ordering};

/// The world's address on the veth.
pub const WORLD_IP: &str = "10.213.0.1";
/// The agents' address on the veth.
pub const AGENTS_IP: &str = "10.213.0.2";

/// Two namespaces, `world` and `agents`, joined by a veth pair.
pub struct NetPair {
    /// The world's namespace.
    pub world: String,
    /// The agents' namespace.
    pub agents: String,
    /// The agents' end of the veth (in `agents`).
    pub agents_veth: String,
}

fn ip(args: &[&str]) -> Result<(), String> {
    let output = Command::new("ip")
        .args(args)
        .stdin(Stdio::null())
        .output()
        .map_err(|e| format!("running ip {}: {e}", args.join(" ")))?;
    if output.status.success() {
        Ok(())
    } else {
        Err(format!(
            "ip {} failed: {}",
            args.join(" "),
            String::from_utf8_lossy(&output.stderr).trim()
        ))
    }
}

impl NetPair {
    /// Creates the pair, or says why it cannot (not root, no `ip netns`).
    pub fn create() -> Result<NetPair, String> {
        static COUNTER: AtomicUsize = AtomicUsize::new(0);
        let n = COUNTER.fetch_add(1, Ordering::Relaxed);
        let tag = format!("{:x}{n}", std::process::id());
        let pair = NetPair {
            world: format!("fmw{tag}"),
            agents: format!("fma{tag}"),
            agents_veth: format!("va{tag}"),
        };
        let world_veth = format!("vw{tag}");
        ip(&["netns", "add", &pair.world])?;
        // From here on, drop deletes whatever was made.
        ip(&["netns", "add", &pair.agents])?;
        ip(&[
            "link",
            "add",
            &world_veth,
            "netns",
            &pair.world,
            "type",
            "veth",
            "peer",
            "name",
            &pair.agents_veth,
            "netns",
            &pair.agents,
        ])?;
        for (ns, veth, address) in [
            (&pair.world, &world_veth, WORLD_IP),
            (&pair.agents, &pair.agents_veth, AGENTS_IP),
        ] {
            ip(&[
                "-n",
                ns,
                "addr",
                "add",
                &format!("{address}/24"),
                "dev",
                veth,
            ])?;
            ip(&["-n", ns, "link", "set", veth, "up"])?;
            ip(&["-n", ns, "link", "set", "lo", "up"])?;
        }
        Ok(pair)
    }

    /// `program` run inside namespace `ns`.
    fn exec(ns: &str, program: &Path) -> Command {
        let mut command = Command::new("ip");
        command.args(["netns", "exec", ns]).arg(program);
        command
    }

    /// `program` run in the world's namespace.
    pub fn in_world(&self, program: &Path) -> Command {
        NetPair::exec(&self.world, program)
    }

    /// `program` run in the agents' namespace.
    pub fn in_agents(&self, program: &Path) -> Command {
        NetPair::exec(&self.agents, program)
    }

    /// Takes the agents' end of the veth down (`up = false`) or up again.
    pub fn set_link(&self, up: bool) {
        let state = if up { "up" } else { "down" };
        ip(&["-n", &self.agents, "link", "set", &self.agents_veth, state])
            .unwrap_or_else(|e| panic!("{e}"));
    }

    /// Drops `percent` % of the TCP packets leaving the agents' namespace over the veth, at
    /// random, with nftables; the reason when `nft` is missing or refuses.
    pub fn drop_percent(&self, percent: u32) -> Result<(), String> {
        let rules = format!(
            "table inet fmloss {{\n chain out {{\n  type filter hook output priority 0;\n  \
             oifname \"{veth}\" meta l4proto tcp numgen random mod 100 < {percent} drop\n }}\n}}\n",
            veth = self.agents_veth
        );
        let output = Command::new("ip")
            .args(["netns", "exec", &self.agents, "nft", "-f", "-"])
            .stdin(Stdio::piped())
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .and_then(|mut child| {
                use std::io::Write;
                if let Some(mut stdin) = child.stdin.take() {
                    stdin.write_all(rules.as_bytes())?;
                }
                child.wait_with_output()
            })
            .map_err(|e| format!("running nft (Debian package nftables): {e}"))?;
        if output.status.success() {
            Ok(())
        } else {
            Err(format!(
                "nft refused the loss rule: {}",
                String::from_utf8_lossy(&output.stderr).trim()
            ))
        }
    }
}

impl Drop for NetPair {
    fn drop(&mut self) {
        for ns in [&self.agents, &self.world] {
            let _ = ip(&["netns", "del", ns]);
        }
    }
}

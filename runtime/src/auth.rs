//! The launch secret: how the world tells the agents its own launch started from any other
//! process on the host.
//!
//! The launcher draws 32 random bytes per launch ([`LaunchSecret::generate`]) and writes them,
//! hex-encoded on one line, to the standard input of the world and of every agent it starts
//! ([`LaunchSecret::read_line`] reads them back). The secret never travels over shared memory:
//! an agent that asks to drive robot `i` sends a fresh random nonce and an HMAC-SHA256 over the
//! run id, the robot, its pid and that nonce ([`LaunchSecret::prove`]); the world checks it
//! ([`LaunchSecret::verify`]) and refuses every nonce it has seen before, so a copied greeting
//! does not open a second door.
//!
//! What this protects against, and what not, is written down in ARCHITECTURE.md ("Threat model"):
//! processes of other users are kept out by file modes; processes of the same user are trusted
//! only as far as the secret reaches (a same-user process that can read another's memory or
//! standard input could also read the secret).

use hmac::{Hmac, Mac};
use sha2::Sha256;

use formation_proto::wire::RunId;

/// Bytes of a launch secret.
pub const SECRET_LEN: usize = 32;
/// Bytes of a proof (an HMAC-SHA256 tag).
pub use formation_proto::wire::PROOF_LEN;

/// Domain separation: a proof for this purpose is never valid for any other.
const HELLO_CONTEXT: &[u8] = b"formation/hello/v1";

/// Why a secret could not be made or read.
#[derive(Debug, thiserror::Error)]
pub enum SecretError {
    /// The operating system's random source failed.
    #[error("the operating system's random source failed ({0}); cannot make a launch secret")]
    Random(String),
    /// Reading standard input failed.
    #[error("reading the launch secret from standard input: {0}")]
    Read(#[source] std::io::Error),
    /// Standard input did not start with a secret line.
    #[error(
        "standard input did not start with a launch secret ({reason}); formation-world and \
         formation-agent are started by `formation run`, which writes one; when starting them by \
         hand, pipe the same {len}-hex-digit secret into both (e.g. from `openssl rand -hex 32`)",
        len = SECRET_LEN * 2
    )]
    Malformed {
        /// What was wrong.
        reason: String,
    },
}

/// The secret of one launch. Its `Debug` output never shows the bytes.
#[derive(Clone, PartialEq, Eq)]
pub struct LaunchSecret([u8; SECRET_LEN]);

impl std::fmt::Debug for LaunchSecret {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("LaunchSecret(..)")
    }
}

impl LaunchSecret {
    /// A fresh secret from the operating system's random source.
    pub fn generate() -> Result<LaunchSecret, SecretError> {
        let mut bytes = [0u8; SECRET_LEN];
        getrandom::fill(&mut bytes).map_err(|e| SecretError::Random(e.to_string()))?;
        Ok(LaunchSecret(bytes))
    }

    /// The secret as one line of lowercase hex, with its newline: what goes on a child's stdin.
    pub fn to_line(&self) -> String {
        let mut line = String::with_capacity(SECRET_LEN * 2 + 1);
        for byte in self.0 {
            line.push_str(&format!("{byte:02x}"));
        }
        line.push('\n');
        line
    }

    /// Parses the hex line [`LaunchSecret::to_line`] writes (surrounding whitespace allowed).
    pub fn parse(line: &str) -> Result<LaunchSecret, SecretError> {
        let text = line.trim();
        let malformed = |reason: String| SecretError::Malformed { reason };
        if text.len() != SECRET_LEN * 2 {
            return Err(malformed(format!(
                "the first line has {} characters, not {}",
                text.len(),
                SECRET_LEN * 2
            )));
        }
        let mut bytes = [0u8; SECRET_LEN];
        for (i, byte) in bytes.iter_mut().enumerate() {
            let pair = text.get(2 * i..2 * i + 2).unwrap_or("");
            *byte = u8::from_str_radix(pair, 16)
                .map_err(|_| malformed("the first line is not hexadecimal".into()))?;
        }
        Ok(LaunchSecret(bytes))
    }

    /// Reads the first line of `input` (at most a few hundred bytes, so an endless input cannot
    /// grow memory) and parses it. Reads byte by byte so that nothing after the line is consumed.
    pub fn read_line(input: &mut dyn std::io::Read) -> Result<LaunchSecret, SecretError> {
        const MAX_LINE: usize = 256;
        let mut line = Vec::with_capacity(SECRET_LEN * 2 + 1);
        let mut byte = [0u8; 1];
        loop {
            match input.read(&mut byte) {
                Ok(0) => break,
                Ok(_) if byte[0] == b'\n' => break,
                Ok(_) => {
                    line.push(byte[0]);
                    if line.len() > MAX_LINE {
                        return Err(SecretError::Malformed {
                            reason: format!("the first line is longer than {MAX_LINE} bytes"),
                        });
                    }
                }
                Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                Err(e) => return Err(SecretError::Read(e)),
            }
        }
        if line.is_empty() {
            return Err(SecretError::Malformed {
                reason: "standard input was empty or closed".into(),
            });
        }
        let text = String::from_utf8(line).map_err(|_| SecretError::Malformed {
            reason: "the first line is not text".into(),
        })?;
        LaunchSecret::parse(&text)
    }

    fn mac(&self, run: &RunId, robot: usize, pid: u32, nonce: u64) -> Hmac<Sha256> {
        // A key of any length is accepted by HMAC, so this never fails for 32 bytes.
        let mut mac = <Hmac<Sha256> as Mac>::new_from_slice(&self.0)
            .unwrap_or_else(|_| unreachable!("HMAC takes keys of any length"));
        mac.update(HELLO_CONTEXT);
        mac.update(&(run.as_str().len() as u64).to_le_bytes());
        mac.update(run.as_str().as_bytes());
        mac.update(&(robot as u64).to_le_bytes());
        mac.update(&pid.to_le_bytes());
        mac.update(&nonce.to_le_bytes());
        mac
    }

    /// The proof that the agent `pid` asking to drive `robot` of `run` with `nonce` holds this
    /// secret.
    pub fn prove(&self, run: &RunId, robot: usize, pid: u32, nonce: u64) -> [u8; PROOF_LEN] {
        self.mac(run, robot, pid, nonce)
            .finalize()
            .into_bytes()
            .into()
    }

    /// Whether `proof` is [`LaunchSecret::prove`] of these values (compared in constant time).
    pub fn verify(
        &self,
        run: &RunId,
        robot: usize,
        pid: u32,
        nonce: u64,
        proof: &[u8; PROOF_LEN],
    ) -> bool {
        self.mac(run, robot, pid, nonce).verify_slice(proof).is_ok()
    }
}

/// A fresh random nonce for one greeting.
pub fn fresh_nonce() -> Result<u64, SecretError> {
    let mut bytes = [0u8; 8];
    getrandom::fill(&mut bytes).map_err(|e| SecretError::Random(e.to_string()))?;
    Ok(u64::from_le_bytes(bytes))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run() -> RunId {
        RunId::new("r1").unwrap()
    }

    #[test]
    fn a_proof_holds_only_for_its_own_secret_robot_pid_and_nonce() {
        let secret = LaunchSecret::generate().unwrap();
        let proof = secret.prove(&run(), 2, 1234, 99);
        assert!(secret.verify(&run(), 2, 1234, 99, &proof));
        assert!(!secret.verify(&run(), 1, 1234, 99, &proof), "other robot");
        assert!(!secret.verify(&run(), 2, 1235, 99, &proof), "other pid");
        assert!(!secret.verify(&run(), 2, 1234, 98, &proof), "other nonce");
        let other_run = RunId::new("r2").unwrap();
        assert!(!secret.verify(&other_run, 2, 1234, 99, &proof), "other run");
        let other = LaunchSecret::generate().unwrap();
        assert_ne!(secret, other);
        assert!(!other.verify(&run(), 2, 1234, 99, &proof), "other secret");
    }

    #[test]
    fn the_secret_line_round_trips_and_bad_lines_are_refused() {
        let secret = LaunchSecret::generate().unwrap();
        let line = secret.to_line();
        assert_eq!(line.len(), SECRET_LEN * 2 + 1);
        let mut input = std::io::Cursor::new(format!("{line}rest of the input"));
        assert_eq!(LaunchSecret::read_line(&mut input).unwrap(), secret);
        assert_eq!(
            input.position() as usize,
            line.len(),
            "nothing after the line is read"
        );
        for bad in ["", "\n", "abc\n", &"zz".repeat(SECRET_LEN)] {
            let err =
                LaunchSecret::read_line(&mut std::io::Cursor::new(bad.to_string())).expect_err(bad);
            assert!(err.to_string().contains("launch secret"), "{err}");
        }
        let endless = std::io::repeat(b'a');
        let err = LaunchSecret::read_line(&mut endless.take(1 << 30)).expect_err("endless line");
        assert!(err.to_string().contains("longer than"), "{err}");
        assert_eq!(format!("{secret:?}"), "LaunchSecret(..)");
    }

    use std::io::Read as _;
}

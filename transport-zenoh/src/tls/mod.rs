//! Zenoh over mutual TLS (feature `tls`): each principal of a team proves who it is with a
//! certificate of the team's own certificate authority, and the world's access rules name it by
//! the certificate's common name.
//!
//! The principals are the world (`world`), each robot's agent (`robot-<i>`), the recorder
//! (`recorder`) and the operator of `formation swap` (`operator`): the names of the logins, so
//! the rules of [`super::access`] hold unchanged, keyed by certificate instead of password.
//!
//! Files, beside the login files in a credentials folder (0700), written by
//! `formation credentials --tls` ([`issue`]):
//!
//! | file | holds | who reads it |
//! |---|---|---|
//! | `ca.pem` | the team's certificate authority | every principal |
//! | `ca.key.pem` (0600) | the authority's key | `formation credentials --renew` only: keep it off the robots |
//! | `<principal>.pem` | the principal's certificate, common name = its login | the principal |
//! | `<principal>.key.pem` (0600) | the principal's key | the principal |
//!
//! What Zenoh 1.10 leaves unsafe, and what is done about it here:
//!
//! - A client whose certificate the router refuses gets no error from Zenoh, only retries: a
//!   client first checks its own certificate against `ca.pem`, its dates and its name
//!   ([`check`]), then makes one handshake of its own with the world ([`probe`]), which names
//!   the router's refusal (unknown authority, expired, no certificate) within seconds.
//! - Zenoh's client trusts the public web roots besides the configured authority, and checks the
//!   world's name against the endpoint's host (which fails on IP addresses): the probe trusts
//!   `ca.pem` alone and checks the world's certificate is `world`'s, and Zenoh's own name check
//!   is off. The router trusts `ca.pem` alone for clients (Zenoh's mTLS verifier).
//! - Peers that meet directly bypass a router's rules: every client connects to the world's
//!   router only, in client mode, with scouting off, and the router listens on `tls/` only.

pub mod check;
pub mod issue;
pub mod probe;

use std::path::{Path, PathBuf};
use std::time::SystemTime;

use formation_proto::files::{FileRefusal, read_bounded};

pub use check::{CertificateFacts, CertificateProblem};
pub use probe::ProbeFailure;

/// The world's principal name: the common name of its certificate.
pub const WORLD_PRINCIPAL: &str = "world";

/// The largest PEM file read (a key or a certificate is a few hundred bytes).
const MAX_PEM_BYTES: u64 = 64 << 10;

/// Days left under which a principal's certificate is said to expire soon.
pub const EXPIRY_WARNING_DAYS: u64 = 14;

/// The team's certificate authority in credentials folder `dir`.
pub fn ca_file(dir: &Path) -> PathBuf {
    dir.join("ca.pem")
}

/// The certificate authority's private key in credentials folder `dir`.
pub fn ca_key_file(dir: &Path) -> PathBuf {
    dir.join("ca.key.pem")
}

/// Principal `principal`'s certificate in credentials folder `dir`.
pub fn certificate_file(dir: &Path, principal: &str) -> PathBuf {
    dir.join(format!("{principal}.pem"))
}

/// Principal `principal`'s private key in credentials folder `dir`.
pub fn key_file(dir: &Path, principal: &str) -> PathBuf {
    dir.join(format!("{principal}.key.pem"))
}

/// Why TLS could not be used.
#[derive(Debug, thiserror::Error)]
pub enum TlsError {
    /// A file of the principal's TLS credentials is missing or unreadable.
    #[error(
        "cannot read {what} {path}: {source}; a tls/ endpoint needs the team's TLS credentials \
         (`formation credentials --tls --robots N --out DIR` writes ca.pem and, per principal, \
         NAME.pem and NAME.key.pem beside its login file)"
    )]
    Read {
        /// Which file ("the certificate authority", "the certificate of robot-1", ...).
        what: String,
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// Our own certificate is not usable.
    #[error("{path}: {problem}")]
    Certificate {
        /// The certificate file.
        path: PathBuf,
        /// What is wrong with it.
        problem: CertificateProblem,
    },
    /// The world refused the handshake, or is not the team's world.
    #[error(transparent)]
    Handshake(#[from] ProbeFailure),
    /// Writing the credentials failed.
    #[error(transparent)]
    Issue(#[from] issue::IssueError),
}

/// One principal's TLS credentials as paths: the team's authority, its certificate, its key.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TlsIdentity {
    /// The principal the certificate must name (`world`, `robot-<i>`, `recorder`, `operator`).
    pub principal: String,
    /// The team's certificate authority (`ca.pem`).
    pub ca: PathBuf,
    /// The principal's certificate.
    pub certificate: PathBuf,
    /// The principal's private key.
    pub key: PathBuf,
}

/// A principal's TLS credentials read into memory.
#[derive(Clone)]
pub struct LoadedIdentity {
    pub ca_pem: Vec<u8>,
    pub certificate_pem: Vec<u8>,
    pub key_pem: Vec<u8>,
}

impl TlsIdentity {
    /// Principal `principal`'s files in credentials folder `dir`.
    pub fn in_folder(dir: &Path, principal: &str) -> TlsIdentity {
        TlsIdentity {
            principal: principal.to_string(),
            ca: ca_file(dir),
            certificate: certificate_file(dir, principal),
            key: key_file(dir, principal),
        }
    }

    /// Reads the three files, bounded.
    pub fn load(&self) -> Result<LoadedIdentity, TlsError> {
        let principal = &self.principal;
        Ok(LoadedIdentity {
            ca_pem: read_pem("the certificate authority", &self.ca)?,
            certificate_pem: read_pem(
                &format!("the certificate of {principal}"),
                &self.certificate,
            )?,
            key_pem: read_pem(&format!("the private key of {principal}"), &self.key)?,
        })
    }

    /// Reads the files and checks the certificate against the authority, its dates and its
    /// name at `now`; warns when it expires within [`EXPIRY_WARNING_DAYS`].
    pub fn load_checked(&self, now: SystemTime) -> Result<LoadedIdentity, TlsError> {
        let loaded = self.load()?;
        let facts = check::check_certificate(
            &loaded.ca_pem,
            &loaded.certificate_pem,
            &self.principal,
            now,
        )
        .map_err(|problem| TlsError::Certificate {
            path: self.certificate.clone(),
            problem,
        })?;
        if let Some(days) = facts.days_left(now)
            && days < EXPIRY_WARNING_DAYS
        {
            tracing::warn!(
                "{}: the certificate of {} expires in {days} days; renew it with `formation \
                 credentials --tls --renew {} --out DIR`",
                self.certificate.display(),
                self.principal,
                self.principal
            );
            eprintln!(
                "warning: the certificate of {} ({}) expires in {days} days; renew it with \
                 `formation credentials --tls --renew {} --out DIR`",
                self.principal,
                self.certificate.display(),
                self.principal
            );
        }
        Ok(loaded)
    }

    /// The paths as Zenoh's configuration takes them.
    fn paths(&self) -> Result<[&str; 3], String> {
        fn text(path: &Path) -> Result<&str, String> {
            path.to_str()
                .ok_or_else(|| format!("{} is not a UTF-8 path", path.display()))
        }
        Ok([text(&self.ca)?, text(&self.certificate)?, text(&self.key)?])
    }

    /// Zenoh's `transport/link/tls` section for a router that listens with this identity and
    /// admits only clients with a certificate of the same authority.
    pub fn apply_listen(&self, config: &mut ::zenoh::Config) -> Result<(), String> {
        let section = self.section("listen")?;
        insert(config, &section.into())
    }

    /// Zenoh's `transport/link/tls` section for a client that connects with this identity. The
    /// world's name is checked by [`probe`] (against `ca.pem` alone), not by Zenoh (which would
    /// compare it with an IP address).
    pub fn apply_connect(&self, config: &mut ::zenoh::Config) -> Result<(), String> {
        let mut section = self.section("connect")?;
        section.insert("verify_name_on_connect".into(), false.into());
        insert(config, &section.into())
    }

    /// The entries of Zenoh's `transport/link/tls` section that both sides write: the authority,
    /// this identity's certificate and key for `side` (`listen` or `connect`), mutual TLS, and
    /// links closed when a certificate expires.
    fn section(&self, side: &str) -> Result<serde_json::Map<String, serde_json::Value>, String> {
        let [ca, certificate, key] = self.paths()?;
        let mut section = serde_json::Map::new();
        section.insert("root_ca_certificate".into(), ca.into());
        section.insert(format!("{side}_certificate"), certificate.into());
        section.insert(format!("{side}_private_key"), key.into());
        section.insert("enable_mtls".into(), true.into());
        section.insert("close_link_on_expiration".into(), true.into());
        Ok(section)
    }
}

fn insert(config: &mut ::zenoh::Config, section: &serde_json::Value) -> Result<(), String> {
    config
        .insert_json5("transport/link/tls", &section.to_string())
        .map_err(|e| format!("setting the TLS credentials: {e}"))
}

fn read_pem(what: &str, path: &Path) -> Result<Vec<u8>, TlsError> {
    let fail = |source| TlsError::Read {
        what: what.to_string(),
        path: path.to_path_buf(),
        source,
    };
    read_bounded(path, MAX_PEM_BYTES).map_err(|refusal| match refusal {
        FileRefusal::Io(source) => fail(source),
        FileRefusal::NotAFile { kind } => fail(std::io::Error::other(format!(
            "it is {kind}, not a regular file"
        ))),
        FileRefusal::TooLarge { .. } => fail(std::io::Error::other(format!(
            "it is larger than {MAX_PEM_BYTES} bytes, which no PEM key or certificate is"
        ))),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_principal_s_files_sit_in_its_credentials_folder() {
        let id = TlsIdentity::in_folder(Path::new("/c"), "robot-1");
        assert_eq!(id.ca, Path::new("/c/ca.pem"));
        assert_eq!(id.certificate, Path::new("/c/robot-1.pem"));
        assert_eq!(id.key, Path::new("/c/robot-1.key.pem"));
    }

    #[test]
    fn zenoh_takes_the_listen_and_connect_sections() {
        let id = TlsIdentity::in_folder(Path::new("/c"), "world");
        let mut config = ::zenoh::Config::default();
        id.apply_listen(&mut config).expect("listen section");
        id.apply_connect(&mut config).expect("connect section");
    }

    #[test]
    fn a_missing_file_names_itself_and_the_command_that_writes_it() {
        let id = TlsIdentity::in_folder(Path::new("/nonexistent-formation-tls"), "robot-1");
        let e = id.load().err().expect("no files").to_string();
        assert!(
            e.contains("/nonexistent-formation-tls/ca.pem")
                && e.contains("formation credentials --tls"),
            "{e}"
        );
    }
}

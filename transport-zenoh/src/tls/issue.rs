//! Making a team's certificates with `rcgen`: the team's own certificate authority, and per
//! principal an ECDSA P-256 key and a certificate whose common name (and DNS name) is the
//! principal's login, signed by the authority, valid for a chosen number of days.
//!
//! Renewing one principal signs a new certificate with the same authority: every other
//! principal's certificate stays valid, and only the renewed one's files change.

use std::path::{Path, PathBuf};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use formation_proto::files::FileRefusal;
use rcgen::{
    BasicConstraints, CertificateParams, DnType, ExtendedKeyUsagePurpose, IsCa, Issuer, KeyPair,
    KeyUsagePurpose, SerialNumber,
};

use super::{WORLD_PRINCIPAL, ca_file, ca_key_file, certificate_file, key_file};
use crate::access::{OPERATOR_USER, RECORDER_USER, robot_user};

/// The longest validity asked for, in days (about 100 years).
pub const MAX_VALID_DAYS: u32 = 36_500;

/// How far before its making a certificate is valid from, for hosts whose clocks lag a little.
const CLOCK_SKEW: Duration = Duration::from_secs(3600);

/// Why certificates could not be made.
#[derive(Debug, thiserror::Error)]
pub enum IssueError {
    /// rcgen refused.
    #[error("cannot make the certificate of {principal}: {source}")]
    Make {
        /// The principal.
        principal: String,
        /// rcgen's error.
        source: rcgen::Error,
    },
    /// A validity out of range.
    #[error("certificates are valid for 1 to {MAX_VALID_DAYS} days, not {0}")]
    ValidDays(u32),
    /// A name that is no principal of a team.
    #[error(
        "{0:?} is no principal of a team: renew world, operator, recorder or robot-<i> (the name \
         of its certificate file without .pem)"
    )]
    UnknownPrincipal(String),
    /// The authority's files could not be read or used.
    #[error(
        "cannot use the team's authority {path}: {reason}; renewing needs ca.pem and ca.key.pem \
         of the folder `formation credentials --tls` wrote"
    )]
    Authority {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        reason: String,
    },
    /// The folder already holds an authority.
    #[error(
        "{0} already holds a certificate authority (ca.pem); remove it, choose another --out, or \
         renew one principal with --renew NAME"
    )]
    Exists(PathBuf),
    /// A file could not be written.
    #[error("cannot write {path}: {source}")]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
}

/// A team's certificate authority: its certificate and its signing key.
pub struct Authority {
    certificate_pem: String,
    key: KeyPair,
}

fn make_error(principal: &str) -> impl FnOnce(rcgen::Error) -> IssueError + '_ {
    move |source| IssueError::Make {
        principal: principal.to_string(),
        source,
    }
}

/// Validity from `at` (less the clock skew) for `days` days.
fn set_validity(
    params: &mut CertificateParams,
    at: SystemTime,
    days: u32,
) -> Result<(), IssueError> {
    if days == 0 || days > MAX_VALID_DAYS {
        return Err(IssueError::ValidDays(days));
    }
    let seconds = |t: SystemTime| {
        let s = t
            .duration_since(UNIX_EPOCH)
            .unwrap_or(Duration::ZERO)
            .as_secs();
        time::OffsetDateTime::from_unix_timestamp(i64::try_from(s).unwrap_or(i64::MAX))
            .unwrap_or(time::OffsetDateTime::UNIX_EPOCH)
    };
    params.not_before = seconds(at.checked_sub(CLOCK_SKEW).unwrap_or(at));
    params.not_after = seconds(at + Duration::from_secs(u64::from(days) * 86_400));
    Ok(())
}

/// A random positive serial number, so that a renewed certificate never repeats one.
fn random_serial() -> SerialNumber {
    let mut bytes = [0u8; 16];
    if getrandom::fill(&mut bytes).is_err() {
        let nanos = SystemTime::now()
            .duration_since(UNIX_EPOCH)
            .unwrap_or(Duration::ZERO)
            .as_nanos();
        bytes = nanos.to_be_bytes();
    }
    bytes[0] &= 0x7f;
    bytes[0] |= 0x01;
    SerialNumber::from_slice(&bytes)
}

impl Authority {
    /// A new authority, valid from `at` for `days` days.
    pub fn create(at: SystemTime, days: u32) -> Result<Authority, IssueError> {
        let what = "the certificate authority";
        let mut params = CertificateParams::default();
        let serial = random_serial();
        let tag: String = serial.to_bytes()[..4]
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect();
        params.distinguished_name = rcgen::DistinguishedName::new();
        params.distinguished_name.push(
            DnType::CommonName,
            format!("formation team authority {tag}"),
        );
        params.is_ca = IsCa::Ca(BasicConstraints::Constrained(0));
        params.key_usages = vec![
            KeyUsagePurpose::KeyCertSign,
            KeyUsagePurpose::CrlSign,
            KeyUsagePurpose::DigitalSignature,
        ];
        params.serial_number = Some(serial);
        set_validity(&mut params, at, days)?;
        let key = KeyPair::generate().map_err(make_error(what))?;
        let certificate = params.self_signed(&key).map_err(make_error(what))?;
        Ok(Authority {
            certificate_pem: certificate.pem(),
            key,
        })
    }

    /// The authority of credentials folder `dir` (its `ca.pem` and `ca.key.pem`).
    pub fn read(dir: &Path) -> Result<Authority, IssueError> {
        let read = |path: PathBuf| {
            formation_proto::files::read_bounded(&path, 64 << 10)
                .map_err(|e| IssueError::Authority {
                    reason: match e {
                        FileRefusal::Io(source) => source.to_string(),
                        FileRefusal::NotAFile { kind } => format!("it is {kind}, not a file"),
                        FileRefusal::TooLarge { .. } => "it is too large for a PEM file".into(),
                    },
                    path: path.clone(),
                })
                .and_then(|bytes| {
                    String::from_utf8(bytes).map_err(|_| IssueError::Authority {
                        reason: "it is not PEM text".into(),
                        path: path.clone(),
                    })
                })
        };
        let certificate_pem = read(ca_file(dir))?;
        let key_path = ca_key_file(dir);
        let key =
            KeyPair::from_pem(&read(key_path.clone())?).map_err(|e| IssueError::Authority {
                path: key_path,
                reason: e.to_string(),
            })?;
        let authority = Authority {
            certificate_pem,
            key,
        };
        authority.issuer()?;
        Ok(authority)
    }

    fn issuer(&self) -> Result<Issuer<'static, &KeyPair>, IssueError> {
        Issuer::from_ca_cert_pem(&self.certificate_pem, &self.key).map_err(|e| {
            IssueError::Authority {
                path: PathBuf::from("ca.pem"),
                reason: e.to_string(),
            }
        })
    }

    /// The authority's certificate, PEM.
    pub fn certificate_pem(&self) -> &str {
        &self.certificate_pem
    }

    /// The authority's private key, PEM (PKCS#8).
    pub fn key_pem(&self) -> String {
        self.key.serialize_pem()
    }
}

/// A key and a certificate for `principal` signed by `authority`, valid from `at` for `days`
/// days: `(certificate PEM, key PEM)`. Its common name and DNS name are the principal's, and it
/// serves both ends of a link (client and server authentication).
pub fn issue_for(
    authority: &Authority,
    principal: &str,
    at: SystemTime,
    days: u32,
) -> Result<(String, String), IssueError> {
    let mut params =
        CertificateParams::new(vec![principal.to_string()]).map_err(make_error(principal))?;
    params.distinguished_name = rcgen::DistinguishedName::new();
    params
        .distinguished_name
        .push(DnType::CommonName, principal.to_string());
    params.key_usages = vec![KeyUsagePurpose::DigitalSignature];
    params.extended_key_usages = vec![
        ExtendedKeyUsagePurpose::ClientAuth,
        ExtendedKeyUsagePurpose::ServerAuth,
    ];
    params.use_authority_key_identifier_extension = true;
    params.serial_number = Some(random_serial());
    set_validity(&mut params, at, days)?;
    let key = KeyPair::generate().map_err(make_error(principal))?;
    let issuer = authority.issuer()?;
    let certificate = params
        .signed_by(&key, &issuer)
        .map_err(make_error(principal))?;
    Ok((certificate.pem(), key.serialize_pem()))
}

/// Every principal of a team of `robots` robots: the world, each robot, the operator, the
/// recorder.
pub fn principals(robots: usize) -> Vec<String> {
    let mut names = vec![WORLD_PRINCIPAL.to_string()];
    names.extend((0..robots).map(robot_user));
    names.push(OPERATOR_USER.to_string());
    names.push(RECORDER_USER.to_string());
    names
}

/// Whether `name` is a principal of some team: `world`, `operator`, `recorder` or `robot-<i>`.
pub fn is_principal(name: &str) -> bool {
    matches!(name, WORLD_PRINCIPAL | OPERATOR_USER | RECORDER_USER)
        || name.strip_prefix("robot-").is_some_and(|i| {
            !i.is_empty() && i.bytes().all(|b| b.is_ascii_digit()) && i.parse::<usize>().is_ok()
        })
}

fn write(path: &Path, text: &str) -> Result<(), IssueError> {
    formation_proto::files::write_atomic(path, text.as_bytes()).map_err(|source| {
        IssueError::Write {
            path: path.to_path_buf(),
            source,
        }
    })
}

/// Writes a new authority and every principal's key and certificate for a team of `robots`
/// robots into `dir` (created 0700 if missing; every file 0600), valid for `days` days from
/// `at`. A folder that already holds an authority is refused.
pub fn write_team(dir: &Path, robots: usize, at: SystemTime, days: u32) -> Result<(), IssueError> {
    if ca_file(dir).exists() {
        return Err(IssueError::Exists(dir.to_path_buf()));
    }
    let authority = Authority::create(at, days)?;
    let mut files = Vec::new();
    for principal in principals(robots) {
        let (certificate, key) = issue_for(&authority, &principal, at, days)?;
        files.push((key_file(dir, &principal), key));
        files.push((certificate_file(dir, &principal), certificate));
    }
    files.push((ca_key_file(dir), authority.key_pem()));
    // The authority's certificate last: its presence marks a complete folder.
    files.push((ca_file(dir), authority.certificate_pem().to_string()));
    for (path, text) in files {
        write(&path, &text)?;
    }
    Ok(())
}

/// Renews `principal`'s key and certificate in `dir` with the folder's authority, valid for
/// `days` days from `at`; the other principals' files are untouched.
pub fn renew(dir: &Path, principal: &str, at: SystemTime, days: u32) -> Result<(), IssueError> {
    if !is_principal(principal) {
        return Err(IssueError::UnknownPrincipal(principal.to_string()));
    }
    let authority = Authority::read(dir)?;
    let (certificate, key) = issue_for(&authority, principal, at, days)?;
    write(&key_file(dir, principal), &key)?;
    write(&certificate_file(dir, principal), &certificate)
}

#[cfg(test)]
mod tests {
    use super::super::check::check_certificate;
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    #[test]
    fn principals_are_the_logins_of_a_team() {
        assert_eq!(
            principals(2),
            ["world", "robot-0", "robot-1", "operator", "recorder"]
        );
        for name in ["world", "robot-0", "robot-12", "operator", "recorder"] {
            assert!(is_principal(name), "{name}");
        }
        for name in ["robot-", "robot-x", "ca", "robot-1.pem", ""] {
            assert!(!is_principal(name), "{name}");
        }
    }

    #[test]
    fn validity_is_bounded() {
        let now = SystemTime::now();
        assert!(matches!(
            Authority::create(now, 0),
            Err(IssueError::ValidDays(0))
        ));
        assert!(matches!(
            Authority::create(now, MAX_VALID_DAYS + 1),
            Err(IssueError::ValidDays(_))
        ));
    }

    #[test]
    fn a_team_s_files_are_private_and_renewing_one_keeps_the_others() {
        let dir = std::env::temp_dir().join(format!("fm-tls-issue-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        let now = SystemTime::now();
        write_team(&dir, 2, now, 30).unwrap();
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode(&dir), 0o700);
        for principal in principals(2) {
            assert_eq!(mode(&key_file(&dir, &principal)), 0o600, "{principal}");
        }
        assert_eq!(mode(&ca_key_file(&dir)), 0o600);
        let read = |p: PathBuf| std::fs::read(p).unwrap();
        let ca = read(ca_file(&dir));
        let world_before = read(certificate_file(&dir, "world"));
        let robot2_before = read(certificate_file(&dir, "robot-1"));
        let later = now + Duration::from_secs(86_400);
        renew(&dir, "robot-1", later, 60).unwrap();
        let robot2_after = read(certificate_file(&dir, "robot-1"));
        assert_ne!(robot2_before, robot2_after);
        assert_eq!(read(certificate_file(&dir, "world")), world_before);
        assert_eq!(read(ca_file(&dir)), ca, "the authority stays");
        for principal in principals(2) {
            let cert = read(certificate_file(&dir, &principal));
            check_certificate(&ca, &cert, &principal, later).expect("still valid");
        }
        let facts = check_certificate(&ca, &robot2_after, "robot-1", later).unwrap();
        assert_eq!(facts.days_left(later), Some(60));
        assert!(matches!(
            write_team(&dir, 2, now, 30),
            Err(IssueError::Exists(_))
        ));
        assert!(matches!(
            renew(&dir, "robot-1.pem", now, 30),
            Err(IssueError::UnknownPrincipal(_))
        ));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

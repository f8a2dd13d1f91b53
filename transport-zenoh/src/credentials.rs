//! A run's credentials for Zenoh, as files: what `formation credentials --robots N --out DIR`
//! writes and what the world, the agents and `formation swap` read.
//!
//! | file | holds | who reads it |
//! |---|---|---|
//! | `DIR/passwords` | `user:password` per line, Zenoh's dictionary | the world's router |
//! | `DIR/launch-secret` | the launch secret (64 hex digits) | the launcher |
//! | `DIR/robot-<i>.json` | robot `i`'s login and the launch secret | robot `i`'s agent, wherever it runs |
//! | `DIR/operator.json` | the operator's login | `formation swap` |
//! | `DIR/recorder.json` | the recorder's login (read-only) | `formation record --connect` |
//! | `DIR/ca.pem`, `DIR/<principal>.pem`, `DIR/<principal>.key.pem` | with `--tls`: the team's authority and each principal's certificate and key ([`super::tls`]) | each principal, beside its login file |
//!
//! Every file is created owner-only (0600, the folder 0700): copy `robot-<i>.json` to robot `i`'s
//! host by a private channel (scp) and nothing else. Reads are bounded and refuse anything but a
//! regular file.

use std::io::Write;
use std::os::unix::fs::{DirBuilderExt, OpenOptionsExt};
use std::path::{Path, PathBuf};

use formation_proto::files::{FileRefusal, read_bounded};
use formation_runtime::auth::{LaunchSecret, SecretError};
use serde::{Deserialize, Serialize};

use super::access::{AccessError, Login, OPERATOR_USER, RECORDER_USER, robot_user};

/// The `format` of a login file.
pub const FORMAT: &str = "formation-transport-zenoh-login";
/// Its version.
pub const VERSION: u32 = 1;
/// The largest credentials file read.
const MAX_FILE_BYTES: u64 = 64 << 10;
/// The most robots one credentials folder is made for.
pub const MAX_ROBOTS: usize = 4096;

/// Credentials that could not be written or read.
#[derive(Debug, thiserror::Error)]
pub enum CredentialsError {
    /// A file could not be read.
    #[error("cannot read credentials file {path}: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A file could not be written.
    #[error("cannot write credentials file {path}: {source}; is the folder writable?")]
    Write {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// A file that is not what it should be.
    #[error(
        "{path} is not a formation credentials file ({reason}); create credentials with \
         `formation credentials --robots N --out DIR`"
    )]
    Malformed {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },
    /// A login file made for another robot.
    #[error("{path} holds the credentials of {user}, not of robot {robot}: use robot-{robot}.json")]
    WrongRobot {
        /// The file.
        path: PathBuf,
        /// The user it holds.
        user: String,
        /// The robot asked for.
        robot: usize,
    },
    /// Too many or no robots.
    #[error("credentials are made for 1 to {MAX_ROBOTS} robots, not {0}")]
    Robots(usize),
    /// The folder already holds credentials.
    #[error(
        "{0} already holds credentials; remove it or choose another --out (new credentials \
         would lock out agents that hold the old ones)"
    )]
    Exists(PathBuf),
    /// The secret could not be drawn or parsed.
    #[error(transparent)]
    Secret(#[from] SecretError),
    /// A login that is not usable.
    #[error(transparent)]
    Access(#[from] AccessError),
    /// Certificates asked of a build without TLS.
    #[error("this build has no TLS: build with `--features tls` to make or renew certificates")]
    NoTls,
    /// The certificates could not be made.
    #[cfg(feature = "tls")]
    #[error(transparent)]
    Certificates(#[from] super::tls::issue::IssueError),
}

/// A login file as written: one user's login, and for a robot the launch secret.
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct LoginFile {
    format: String,
    version: u32,
    user: String,
    password: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    launch_secret: Option<String>,
}

/// Robot `robot`'s credentials: its Zenoh login and the launch secret.
#[derive(Debug)]
pub struct RobotCredentials {
    /// The login as user `robot-<i>`.
    pub login: Login,
    /// The launch secret, which proves the agent belongs to this launch.
    pub secret: LaunchSecret,
}

fn random_password() -> Result<String, SecretError> {
    // 32 random bytes as hex, drawn the way the launch secret is.
    let secret = LaunchSecret::generate()?;
    Ok(secret.to_line().trim().to_string())
}

fn write_private(path: &Path, text: &str) -> Result<(), CredentialsError> {
    let write = || -> std::io::Result<()> {
        let mut file = std::fs::OpenOptions::new()
            .write(true)
            .create_new(true)
            .mode(0o600)
            .open(path)?;
        file.write_all(text.as_bytes())?;
        file.sync_all()
    };
    write().map_err(|source| CredentialsError::Write {
        path: path.to_path_buf(),
        source,
    })
}

/// The path of robot `robot`'s login file in `dir`.
pub fn robot_file(dir: &Path, robot: usize) -> PathBuf {
    dir.join(format!("robot-{robot}.json"))
}

/// The path of the operator's login file in `dir`.
pub fn operator_file(dir: &Path) -> PathBuf {
    dir.join("operator.json")
}

/// The path of the recorder's login file in `dir`.
pub fn recorder_file(dir: &Path) -> PathBuf {
    dir.join("recorder.json")
}

/// The path of the world's password dictionary in `dir`.
pub fn passwords_file(dir: &Path) -> PathBuf {
    dir.join("passwords")
}

/// The path of the launch secret in `dir`.
pub fn secret_file(dir: &Path) -> PathBuf {
    dir.join("launch-secret")
}

/// Creates credentials for robots `0..robots` and the operator in `dir` (created 0700; it must
/// not hold credentials yet), with a fresh launch secret.
pub fn create(dir: &Path, robots: usize) -> Result<(), CredentialsError> {
    if robots == 0 || robots > MAX_ROBOTS {
        return Err(CredentialsError::Robots(robots));
    }
    if passwords_file(dir).exists() {
        return Err(CredentialsError::Exists(dir.to_path_buf()));
    }
    std::fs::DirBuilder::new()
        .recursive(true)
        .mode(0o700)
        .create(dir)
        .map_err(|source| CredentialsError::Write {
            path: dir.to_path_buf(),
            source,
        })?;
    let secret = LaunchSecret::generate()?;
    let mut dictionary = String::new();
    let users = (0..robots)
        .map(|robot| (robot_user(robot), robot_file(dir, robot), true))
        .chain([
            (OPERATOR_USER.to_string(), operator_file(dir), false),
            (RECORDER_USER.to_string(), recorder_file(dir), false),
        ]);
    for (user, path, with_secret) in users {
        let password = random_password()?;
        Login::new(&user, &password)?;
        dictionary.push_str(&format!("{user}:{password}\n"));
        let file = LoginFile {
            format: FORMAT.into(),
            version: VERSION,
            user,
            password,
            launch_secret: with_secret.then(|| secret.to_line().trim().to_string()),
        };
        let text =
            serde_json::to_string_pretty(&file).map_err(|e| CredentialsError::Malformed {
                path: path.clone(),
                reason: e.to_string(),
            })?;
        write_private(&path, &(text + "\n"))?;
    }
    write_private(&secret_file(dir), &secret.to_line())?;
    write_private(&passwords_file(dir), &dictionary)
}

/// [`create`], and the team's certificates ([`super::tls::issue::write_team`]): an authority
/// and, per principal, a key and a certificate valid for `valid_days` days.
pub fn create_with_tls(dir: &Path, robots: usize, valid_days: u32) -> Result<(), CredentialsError> {
    #[cfg(feature = "tls")]
    {
        if valid_days == 0 || valid_days > super::tls::issue::MAX_VALID_DAYS {
            return Err(super::tls::issue::IssueError::ValidDays(valid_days).into());
        }
        create(dir, robots)?;
        let now = std::time::SystemTime::now();
        super::tls::issue::write_team(dir, robots, now, valid_days)?;
        Ok(())
    }
    #[cfg(not(feature = "tls"))]
    {
        let _ = (dir, robots, valid_days);
        Err(CredentialsError::NoTls)
    }
}

/// Renews `principal`'s key and certificate in the team's folder `dir` with its authority,
/// valid for `valid_days` days; the others stay valid.
pub fn renew_certificate(
    dir: &Path,
    principal: &str,
    valid_days: u32,
) -> Result<(), CredentialsError> {
    #[cfg(feature = "tls")]
    {
        let now = std::time::SystemTime::now();
        super::tls::issue::renew(dir, principal, now, valid_days)?;
        Ok(())
    }
    #[cfg(not(feature = "tls"))]
    {
        let _ = (dir, principal, valid_days);
        Err(CredentialsError::NoTls)
    }
}

/// Reads at most `limit` bytes of the regular file `path`.
fn read_file(path: &Path, limit: u64) -> Result<Vec<u8>, CredentialsError> {
    read_bounded(path, limit).map_err(|refusal| match refusal {
        FileRefusal::Io(source) => CredentialsError::Read {
            path: path.to_path_buf(),
            source,
        },
        FileRefusal::NotAFile { kind } => CredentialsError::Malformed {
            path: path.to_path_buf(),
            reason: format!("it is {kind}, not a regular file"),
        },
        FileRefusal::TooLarge { .. } => CredentialsError::Malformed {
            path: path.to_path_buf(),
            reason: format!("it is larger than {limit} bytes"),
        },
    })
}

fn read_login_file(path: &Path) -> Result<LoginFile, CredentialsError> {
    let bytes = read_file(path, MAX_FILE_BYTES)?;
    let malformed = |reason: String| CredentialsError::Malformed {
        path: path.to_path_buf(),
        reason,
    };
    let file: LoginFile = serde_json::from_slice(&bytes).map_err(|e| malformed(e.to_string()))?;
    if file.format != FORMAT || file.version != VERSION {
        return Err(malformed(format!(
            "format {} version {}, expected {FORMAT} version {VERSION}",
            file.format, file.version
        )));
    }
    Ok(file)
}

/// Reads robot `robot`'s login file.
pub fn read_robot(path: &Path, robot: usize) -> Result<RobotCredentials, CredentialsError> {
    let file = read_login_file(path)?;
    if file.user != robot_user(robot) {
        return Err(CredentialsError::WrongRobot {
            path: path.to_path_buf(),
            user: file.user,
            robot,
        });
    }
    let secret_text = file
        .launch_secret
        .ok_or_else(|| CredentialsError::Malformed {
            path: path.to_path_buf(),
            reason: "it holds no launch secret".into(),
        })?;
    Ok(RobotCredentials {
        login: Login::new(&file.user, &file.password)?.in_folder(folder_of(path)),
        secret: LaunchSecret::parse(&secret_text)?,
    })
}

/// Reads a login file of any user (the operator's, for `formation swap`).
pub fn read_login(path: &Path) -> Result<Login, CredentialsError> {
    let file = read_login_file(path)?;
    Ok(Login::new(&file.user, &file.password)?.in_folder(folder_of(path)))
}

/// The folder a login file sits in (`.` for a bare file name): a `tls/` endpoint finds the
/// principal's certificate there.
fn folder_of(path: &Path) -> PathBuf {
    match path.parent() {
        Some(dir) if !dir.as_os_str().is_empty() => dir.to_path_buf(),
        _ => PathBuf::from("."),
    }
}

/// A login file that is not the recorder's.
#[derive(Debug, thiserror::Error)]
#[error(
    "{} holds the login of {user}, not the recorder's: `formation record --connect` needs the \
     read-only recorder login, recorder.json in the team's credentials folder (written by \
     `formation credentials --robots N --out DIR`)",
    path.display()
)]
pub struct NotTheRecorder {
    /// The file.
    pub path: PathBuf,
    /// The user it holds.
    pub user: String,
}

/// Reads the recorder's login file; a file of another user (an agent's, the operator's) is
/// refused.
pub fn read_recorder(path: &Path) -> Result<Login, RecorderLoginError> {
    let login = read_login(path)?;
    if login.user() != RECORDER_USER {
        return Err(RecorderLoginError::NotTheRecorder(NotTheRecorder {
            path: path.to_path_buf(),
            user: login.user().to_string(),
        }));
    }
    Ok(login)
}

/// Why the recorder's login could not be read.
#[derive(Debug, thiserror::Error)]
pub enum RecorderLoginError {
    /// The file could not be read.
    #[error(transparent)]
    Credentials(#[from] CredentialsError),
    /// It holds another user's login.
    #[error(transparent)]
    NotTheRecorder(NotTheRecorder),
}

/// Reads the launch secret of a credentials folder.
pub fn read_secret(dir: &Path) -> Result<LaunchSecret, CredentialsError> {
    let path = secret_file(dir);
    let bytes = read_file(&path, MAX_FILE_BYTES)?;
    let text = String::from_utf8_lossy(&bytes);
    Ok(LaunchSecret::parse(text.trim())?)
}

/// Checks the world's password dictionary can be read, and returns its path.
pub fn check_passwords(dir: &Path) -> Result<PathBuf, CredentialsError> {
    let path = passwords_file(dir);
    read_file(&path, 16 << 20)?;
    Ok(path)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::os::unix::fs::PermissionsExt;

    #[test]
    fn credentials_are_private_and_each_robot_reads_only_its_own() {
        let dir = std::env::temp_dir().join(format!("fm-cred-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        create(&dir, 2).unwrap();
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o777;
        assert_eq!(mode(&dir), 0o700);
        for path in [passwords_file(&dir), robot_file(&dir, 1), secret_file(&dir)] {
            assert_eq!(mode(&path), 0o600, "{}", path.display());
        }
        let robot1 = read_robot(&robot_file(&dir, 1), 1).unwrap();
        assert_eq!(robot1.login.user(), "robot-1");
        assert_eq!(
            robot1.secret.to_line(),
            read_secret(&dir).unwrap().to_line()
        );
        let wrong = read_robot(&robot_file(&dir, 1), 0).unwrap_err().to_string();
        assert!(wrong.contains("robot-0.json"), "{wrong}");
        assert!(read_login(&operator_file(&dir)).is_ok());
        assert_eq!(
            read_recorder(&recorder_file(&dir)).unwrap().user(),
            RECORDER_USER
        );
        let agent = read_recorder(&robot_file(&dir, 1)).unwrap_err().to_string();
        assert!(
            agent.contains("robot-1, not the recorder's") && agent.contains("recorder.json"),
            "{agent}"
        );
        let dictionary = std::fs::read_to_string(passwords_file(&dir)).unwrap();
        assert_eq!(dictionary.lines().count(), 4);
        assert!(dictionary.contains(&format!("robot-1:{}", robot1.login.password())));
        let again = create(&dir, 2).unwrap_err().to_string();
        assert!(again.contains("already holds credentials"), "{again}");
        assert!(matches!(create(&dir, 0), Err(CredentialsError::Robots(0))));
        std::fs::remove_dir_all(&dir).unwrap();
        let missing = read_robot(&robot_file(&dir, 1), 1).unwrap_err().to_string();
        assert!(missing.contains("robot-1.json"), "{missing}");
    }
}

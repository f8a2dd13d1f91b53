//! Who may connect to the world's router, and which keys each may use: Zenoh's own user/password
//! authentication (`auth_usrpwd`) and access control (`access_control`), configured here, never
//! written by hand.
//!
//! Robot `i`'s agent logs in as user `robot-<i>` ([`robot_user`]); `formation swap` logs in as
//! [`OPERATOR_USER`]. The world's router holds the password dictionary ([`WorldAccess`]), refuses
//! a connection whose login fails, and denies by default every message not allowed by these
//! rules (`<r>` is the run, ingress is what a client sends the router, egress what the router
//! sends a client):
//!
//! | user | may send | may receive | may subscribe |
//! |---|---|---|---|
//! | `robot-<i>` | `robot/<i>/hello`, `robot/<i>/*/cmd`, `robot/<i>/*/status`, its token `robot/<i>/*/agent/*` | `robot/<i>/welcome`, `robot/<i>/*/scan`, `robot/<i>/*/control`, the world's token | the same keys, the world's token |
//! | `operator` | `swap/request` | `swap/reply`, the world's token | the same keys, the world's token |
//! | `recorder` | nothing | `record/live`, every robot's `robot/*/*/scan` and `robot/*/*/cmd`, the world's token, replies to its queries of `record/setup` | the same keys, the world's token |
//!
//! so only robot `i`'s credentials receive robot `i`'s scan or command robot `i`, as the
//! one-publisher/one-subscriber limits guarantee on one host.
//!
//! Over a `tls/` endpoint (feature `tls`) each subject is named by its certificate's common name
//! as well as by its login, and Zenoh admits a session to a subject only when both match: robot
//! `i` needs robot `i`'s certificate and robot `i`'s password.

use std::path::PathBuf;

use formation_proto::wire::RunId;
use serde_json::json;

/// The user name of robot `robot`'s agent.
pub fn robot_user(robot: usize) -> String {
    format!("robot-{robot}")
}

/// The user name of `formation swap`.
pub const OPERATOR_USER: &str = "operator";

/// The user name of `formation record --connect`: read-only, it may read every robot's scans
/// and commands and the world's record channel ([`super::keys::record_live`]), and send nothing.
pub const RECORDER_USER: &str = "recorder";

/// Credentials that could not be used.
#[derive(Debug, thiserror::Error)]
pub enum AccessError {
    /// A user name or password with characters the dictionary cannot hold.
    #[error(
        "{what} {value:?} is not usable: use 1 to 128 ASCII letters, digits, '-' or '_' \
         (create credentials with `formation credentials`)"
    )]
    Invalid {
        /// Which field.
        what: &'static str,
        /// The value (a password is not shown).
        value: String,
    },
}

fn check(what: &'static str, value: &str, shown: &str) -> Result<(), AccessError> {
    let ok = !value.is_empty()
        && value.len() <= 128
        && value
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b == b'-' || b == b'_');
    if ok {
        Ok(())
    } else {
        Err(AccessError::Invalid {
            what,
            value: shown.to_string(),
        })
    }
}

/// A client's login: user and password, and, when it was read from a credentials folder, that
/// folder, where a `tls/` endpoint finds the principal's certificate ([`super::tls`]).
#[derive(Clone, PartialEq, Eq)]
pub struct Login {
    user: String,
    password: String,
    folder: Option<PathBuf>,
}

impl std::fmt::Debug for Login {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Login")
            .field("user", &self.user)
            .finish_non_exhaustive()
    }
}

impl Login {
    /// A login; both parts are letters, digits, '-' or '_'.
    pub fn new(user: &str, password: &str) -> Result<Login, AccessError> {
        check("user", user, user)?;
        check("password", password, "(hidden)")?;
        Ok(Login {
            user: user.to_string(),
            password: password.to_string(),
            folder: None,
        })
    }

    /// The login as read from a file of credentials folder `folder`, whose certificate files a
    /// `tls/` endpoint uses.
    pub fn in_folder(mut self, folder: PathBuf) -> Login {
        self.folder = Some(folder);
        self
    }

    /// The credentials folder the login was read from, if any.
    pub fn folder(&self) -> Option<&std::path::Path> {
        self.folder.as_deref()
    }

    /// The user name.
    pub fn user(&self) -> &str {
        &self.user
    }

    /// The password.
    pub fn password(&self) -> &str {
        &self.password
    }

    pub(super) fn apply(&self, config: &mut ::zenoh::Config) -> Result<(), String> {
        let value = json!({ "user": self.user, "password": self.password }).to_string();
        config
            .insert_json5("transport/auth/usrpwd", &value)
            .map_err(|e| format!("setting the login of user {}: {e}", self.user))
    }
}

/// The world's side: the password dictionary and the run's access rules.
#[derive(Debug, Clone)]
pub struct WorldAccess {
    /// A file of `user:password` lines (Zenoh reads it), private to this user.
    pub dictionary_file: PathBuf,
    /// The run whose keys the rules name.
    pub run: RunId,
    /// Robots `0..n_robots` get a rule set each.
    pub n_robots: usize,
}

impl WorldAccess {
    /// The credentials folder: the dictionary's. Over a `tls/` endpoint the world's certificate
    /// and the team's authority are read there too ([`super::tls`]).
    pub fn folder(&self) -> PathBuf {
        match self.dictionary_file.parent() {
            Some(dir) if !dir.as_os_str().is_empty() => dir.to_path_buf(),
            _ => PathBuf::from("."),
        }
    }

    /// Sets the login dictionary and the rules; `by_certificate`: each subject is named by its
    /// certificate's common name as well as by its login, so a session must show both.
    pub(super) fn apply(
        &self,
        config: &mut ::zenoh::Config,
        by_certificate: bool,
    ) -> Result<(), String> {
        let file = self.dictionary_file.to_str().ok_or_else(|| {
            format!(
                "the password file {} is not a UTF-8 path",
                self.dictionary_file.display()
            )
        })?;
        config
            .insert_json5(
                "transport/auth/usrpwd",
                &json!({ "dictionary_file": file }).to_string(),
            )
            .map_err(|e| format!("setting the password file {file}: {e}"))?;
        let acl = self.rules_naming(by_certificate).to_string();
        config
            .insert_json5("access_control", &acl)
            .map_err(|e| format!("setting the access rules: {e}"))
    }

    /// The `access_control` section: deny by default, allow each user its own keys.
    pub fn rules(&self) -> serde_json::Value {
        self.rules_naming(false)
    }

    /// [`WorldAccess::rules`], each subject named by its login and, with `by_certificate`, by
    /// its certificate's common name too (Zenoh matches a subject only when both match).
    pub fn rules_naming(&self, by_certificate: bool) -> serde_json::Value {
        let run = &self.run;
        let world = format!("formation/{run}/world");
        let mut rules = Vec::new();
        let mut subjects = Vec::new();
        let mut policies = Vec::new();
        let mut user_rules = |id: String,
                              user: String,
                              sends: Vec<String>,
                              receives: Vec<String>,
                              token: Option<String>| {
            let mut ids = Vec::new();
            let mut rule = |suffix: &str, messages: &[&str], flow: &str, keys: Vec<String>| {
                allow(
                    &mut rules,
                    &mut ids,
                    format!("{id}-{suffix}"),
                    messages,
                    flow,
                    &keys,
                );
            };
            rule("send", &["put"], "ingress", sends);
            rule(
                "subscribe",
                &["declare_subscriber"],
                "ingress",
                receives.clone(),
            );
            rule("receive", &["put"], "egress", receives);
            rule(
                "watch-world",
                &["declare_liveliness_subscriber", "liveliness_query"],
                "ingress",
                vec![world.clone()],
            );
            rule(
                "see-world",
                &["liveliness_token", "reply"],
                "egress",
                vec![world.clone()],
            );
            if let Some(token) = token {
                rule("token", &["liveliness_token"], "ingress", vec![token]);
            }
            if user == RECORDER_USER {
                let setup = vec![super::keys::record_setup(run)];
                rule("ask-setup", &["query"], "ingress", setup.clone());
                rule("get-setup", &["reply"], "egress", setup);
            }
            let subject = if by_certificate {
                json!({ "id": id, "usernames": [user], "cert_common_names": [user] })
            } else {
                json!({ "id": id, "usernames": [user] })
            };
            subjects.push(subject);
            policies.push(json!({ "rules": ids, "subjects": [id] }));
        };
        for robot in 0..self.n_robots {
            let base = format!("formation/{run}/robot/{robot}");
            user_rules(
                robot_user(robot),
                robot_user(robot),
                vec![
                    format!("{base}/hello"),
                    format!("{base}/*/cmd"),
                    format!("{base}/*/status"),
                ],
                vec![
                    format!("{base}/welcome"),
                    format!("{base}/*/scan"),
                    format!("{base}/*/control"),
                ],
                Some(format!("{base}/*/agent/*")),
            );
        }
        user_rules(
            OPERATOR_USER.to_string(),
            OPERATOR_USER.to_string(),
            vec![format!("formation/{run}/swap/request")],
            vec![format!("formation/{run}/swap/reply")],
            None,
        );
        user_rules(
            RECORDER_USER.to_string(),
            RECORDER_USER.to_string(),
            Vec::new(),
            vec![
                super::keys::record_live(run),
                format!("formation/{run}/robot/*/*/scan"),
                format!("formation/{run}/robot/*/*/cmd"),
            ],
            None,
        );
        deny_by_default(rules, subjects, policies)
    }
}

/// Adds to `rules` the rule `id` that allows `messages` flowing `flow` (`ingress`: what a client
/// sends the router; `egress`: what the router sends a client) on `keys`, and `id` to `ids` (a
/// policy's rules); nothing when `keys` is empty.
pub fn allow(
    rules: &mut Vec<serde_json::Value>,
    ids: &mut Vec<String>,
    id: String,
    messages: &[&str],
    flow: &str,
    keys: &[String],
) {
    if keys.is_empty() {
        return;
    }
    rules.push(json!({
        "id": id,
        "messages": messages,
        "flows": [flow],
        "permission": "allow",
        "key_exprs": keys,
    }));
    ids.push(id);
}

/// A router's `access_control` section: deny by default, allow `rules` to `subjects` as
/// `policies` say.
pub fn deny_by_default(
    rules: Vec<serde_json::Value>,
    subjects: Vec<serde_json::Value>,
    policies: Vec<serde_json::Value>,
) -> serde_json::Value {
    json!({
        "enabled": true,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn logins_are_checked_and_rules_name_each_robot_s_own_keys_only() {
        assert!(Login::new("robot-1", "abcDEF012_-").is_ok());
        let e = Login::new("robot-1", "with space").unwrap_err().to_string();
        assert!(
            e.contains("password") && !e.contains("with space"),
            "the password is not shown: {e}"
        );
        assert!(Login::new("", "x").is_err());
        let access = WorldAccess {
            dictionary_file: PathBuf::from("/nonexistent"),
            run: RunId::new("r1").unwrap(),
            n_robots: 2,
        };
        let rules = access.rules();
        assert_eq!(rules["default_permission"], "deny");
        let text = rules.to_string();
        assert!(text.contains("formation/r1/robot/1/*/scan"));
        let policies = rules["policies"].as_array().unwrap();
        assert_eq!(
            policies.len(),
            4,
            "two robots, the operator and the recorder"
        );
        // The recorder sends nothing and declares no token.
        for rule in rules["rules"].as_array().unwrap() {
            let id = rule["id"].as_str().unwrap();
            if id.starts_with("recorder-") {
                assert!(rule["flows"][0] == "egress" || !rule.to_string().contains("\"put\""));
                assert!(!id.ends_with("-send") && !id.ends_with("-token"), "{rule}");
            }
        }
        // Robot 0's rules never name robot 1's keys.
        let robot0: Vec<&serde_json::Value> = rules["rules"]
            .as_array()
            .unwrap()
            .iter()
            .filter(|r| r["id"].as_str().unwrap().starts_with("robot-0-"))
            .collect();
        assert!(!robot0.is_empty());
        for rule in robot0 {
            assert!(!rule.to_string().contains("robot/1"), "{rule}");
        }
        let mut config = ::zenoh::Config::default();
        access
            .apply(&mut config, false)
            .expect("zenoh takes the rules");
        // Over TLS each subject is its certificate's common name and its login, both.
        let by_certificate = access.rules_naming(true);
        for subject in by_certificate["subjects"].as_array().unwrap() {
            assert_eq!(
                subject["usernames"], subject["cert_common_names"],
                "{subject}"
            );
        }
        assert_eq!(by_certificate["rules"], rules["rules"]);
        let mut config = ::zenoh::Config::default();
        access
            .apply(&mut config, true)
            .expect("zenoh takes the rules");
    }
}

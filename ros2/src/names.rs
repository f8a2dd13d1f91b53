//! ROS 2 names, validated as `rmw`'s validators do: fully qualified topic names, namespaces (and
//! enclaves, which follow the namespace rules) and node names.
//!
//! The rules (`rmw/validate_full_topic_name.h`, `validate_namespace.h`, `validate_node_name.h`,
//! and <http://design.ros2.org/articles/topic_and_service_names.html>):
//! - a topic name starts with `/`, does not end with `/`, has no `//`, uses only `A-Z a-z 0-9 _ /`,
//!   no token (between slashes) starts with a digit, and it is at most 247 characters
//!   (`RMW_TOPIC_MAX_NAME_LENGTH` = 255 - 8 reserved for prefixes);
//! - a namespace follows the same rules, but may be `/` alone, and is at most 245 characters;
//! - a node name is `A-Z a-z 0-9 _`, does not start with a digit, at most 255 characters.
//!
//! Relative names (`scan`), private names (`~/scan`) and substitutions (`{node}`) are expanded by
//! rcl before they reach the middleware; this crate takes only their expanded, absolute form.

use std::fmt;

use thiserror::Error;

/// Longest fully qualified topic name (`RMW_TOPIC_MAX_NAME_LENGTH`).
pub const TOPIC_NAME_MAX_LEN: usize = 255 - 8;
/// Longest namespace (`RMW_NAMESPACE_MAX_LENGTH`).
pub const NAMESPACE_MAX_LEN: usize = TOPIC_NAME_MAX_LEN - 2;
/// Longest node name (`RMW_NODE_NAME_MAX_NAME_LENGTH`).
pub const NODE_NAME_MAX_LEN: usize = 255;

/// Which kind of name was being validated.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NameKind {
    /// A fully qualified topic name.
    Topic,
    /// A node namespace.
    Namespace,
    /// A security enclave.
    Enclave,
    /// A node name.
    Node,
}

impl fmt::Display for NameKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            NameKind::Topic => "topic name",
            NameKind::Namespace => "namespace",
            NameKind::Enclave => "enclave",
            NameKind::Node => "node name",
        })
    }
}

/// Why a name is not a valid ROS 2 name.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum NameError {
    /// The name is empty.
    #[error("{kind} must not be empty")]
    Empty {
        /// What was validated.
        kind: NameKind,
    },
    /// A topic name or namespace that does not start with `/`.
    #[error("{kind} `{name}` must be absolute (start with `/`, as in `/{name}`)")]
    NotAbsolute {
        /// What was validated.
        kind: NameKind,
        /// The name.
        name: String,
    },
    /// A topic name or namespace that ends with `/`.
    #[error("{kind} `{name}` must not end with `/`")]
    EndsWithSlash {
        /// What was validated.
        kind: NameKind,
        /// The name.
        name: String,
    },
    /// A character outside the allowed set.
    #[error("{kind} `{name}` contains {character:?} at {index}; only A-Z, a-z, 0-9 and _ {}are allowed", if matches!(kind, NameKind::Node) { "" } else { "(and / between tokens) " })]
    UnallowedCharacter {
        /// What was validated.
        kind: NameKind,
        /// The name.
        name: String,
        /// Byte index of the character.
        index: usize,
        /// The character.
        character: char,
    },
    /// Two slashes in a row.
    #[error("{kind} `{name}` has an empty token (`//`) at {index}")]
    RepeatedSlash {
        /// What was validated.
        kind: NameKind,
        /// The name.
        name: String,
        /// Byte index of the second slash.
        index: usize,
    },
    /// A token that starts with a digit.
    #[error("{kind} `{name}` has a token starting with a digit at {index}")]
    TokenStartsWithDigit {
        /// What was validated.
        kind: NameKind,
        /// The name.
        name: String,
        /// Byte index of the digit.
        index: usize,
    },
    /// The name is too long.
    #[error("{kind} is {len} characters long; the limit is {max}")]
    TooLong {
        /// What was validated.
        kind: NameKind,
        /// Its length.
        len: usize,
        /// The limit.
        max: usize,
    },
}

/// Validates an absolute slash-separated name (a topic name, a namespace or an enclave).
fn validate_absolute(
    kind: NameKind,
    name: &str,
    max_len: usize,
    root_allowed: bool,
) -> Result<(), NameError> {
    let owned = || name.to_owned();
    if name.is_empty() {
        return Err(NameError::Empty { kind });
    }
    if !name.starts_with('/') {
        return Err(NameError::NotAbsolute {
            kind,
            name: owned(),
        });
    }
    if name == "/" && root_allowed {
        return Ok(());
    }
    if name.ends_with('/') {
        return Err(NameError::EndsWithSlash {
            kind,
            name: owned(),
        });
    }
    let mut previous = '/';
    for (index, character) in name.char_indices() {
        if !(character.is_ascii_alphanumeric() || character == '_' || character == '/') {
            return Err(NameError::UnallowedCharacter {
                kind,
                name: owned(),
                index,
                character,
            });
        }
        if previous == '/' && character == '/' && index > 0 {
            return Err(NameError::RepeatedSlash {
                kind,
                name: owned(),
                index,
            });
        }
        if previous == '/' && character.is_ascii_digit() {
            return Err(NameError::TokenStartsWithDigit {
                kind,
                name: owned(),
                index,
            });
        }
        previous = character;
    }
    if name.len() > max_len {
        return Err(NameError::TooLong {
            kind,
            len: name.len(),
            max: max_len,
        });
    }
    Ok(())
}

/// Declares a name that is validated once, where it is made (`new`): a newtype over its text,
/// which `as_str` gives back and `Display` shows as it is.
macro_rules! validated_name {
    ($(#[$doc:meta])* $name:ident, $as_str_doc:literal) => {
        $(#[$doc])*
        #[derive(Debug, Clone, PartialEq, Eq, Hash)]
        pub struct $name(String);

        impl $name {
            #[doc = $as_str_doc]
            pub fn as_str(&self) -> &str {
                &self.0
            }
        }

        impl fmt::Display for $name {
            fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
                f.write_str(&self.0)
            }
        }
    };
}

validated_name!(
    /// A valid, fully qualified ROS 2 topic name such as `/robot_0/scan`.
    TopicName,
    "The name, leading slash included."
);

validated_name!(
    /// A valid node namespace (`/` for none) or enclave (`/` by default).
    Namespace,
    "The namespace, leading slash included."
);

validated_name!(
    /// A valid node name such as `formation_agent_0`.
    NodeName,
    "The name."
);

impl TopicName {
    /// Validates a fully qualified topic name.
    pub fn new(name: &str) -> Result<TopicName, NameError> {
        validate_absolute(NameKind::Topic, name, TOPIC_NAME_MAX_LEN, false)?;
        Ok(TopicName(name.to_owned()))
    }

    /// The name without its leading slash, as it appears in a data key expression.
    pub fn without_leading_slash(&self) -> &str {
        &self.0[1..]
    }
}

impl Namespace {
    /// The root namespace `/`, which is also the default enclave.
    pub fn root() -> Namespace {
        Namespace("/".to_owned())
    }

    /// Validates a namespace.
    pub fn new(name: &str) -> Result<Namespace, NameError> {
        validate_absolute(NameKind::Namespace, name, NAMESPACE_MAX_LEN, true)?;
        Ok(Namespace(name.to_owned()))
    }

    /// Validates an enclave (the namespace rules).
    pub fn enclave(name: &str) -> Result<Namespace, NameError> {
        validate_absolute(NameKind::Enclave, name, NAMESPACE_MAX_LEN, true)?;
        Ok(Namespace(name.to_owned()))
    }
}

impl NodeName {
    /// Validates a node name.
    pub fn new(name: &str) -> Result<NodeName, NameError> {
        let kind = NameKind::Node;
        let mut chars = name.char_indices();
        match chars.next() {
            None => return Err(NameError::Empty { kind }),
            Some((index, c)) if c.is_ascii_digit() => {
                return Err(NameError::TokenStartsWithDigit {
                    kind,
                    name: name.to_owned(),
                    index,
                });
            }
            Some(_) => {}
        }
        if let Some((index, character)) = name
            .char_indices()
            .find(|&(_, c)| !(c.is_ascii_alphanumeric() || c == '_'))
        {
            return Err(NameError::UnallowedCharacter {
                kind,
                name: name.to_owned(),
                index,
                character,
            });
        }
        if name.len() > NODE_NAME_MAX_LEN {
            return Err(NameError::TooLong {
                kind,
                len: name.len(),
                max: NODE_NAME_MAX_LEN,
            });
        }
        Ok(NodeName(name.to_owned()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn valid_topic_names_are_accepted() {
        for name in ["/scan", "/robot_0/cmd_vel", "/a", "/_private/x1"] {
            assert_eq!(TopicName::new(name).unwrap().as_str(), name);
        }
        assert_eq!(
            TopicName::new("/robot_0/scan")
                .unwrap()
                .without_leading_slash(),
            "robot_0/scan"
        );
    }

    #[test]
    fn each_topic_rule_has_its_error() {
        let kind = NameKind::Topic;
        assert_eq!(TopicName::new(""), Err(NameError::Empty { kind }));
        let cases = [
            (
                "scan",
                NameError::NotAbsolute {
                    kind,
                    name: "scan".into(),
                },
            ),
            (
                "/scan/",
                NameError::EndsWithSlash {
                    kind,
                    name: "/scan/".into(),
                },
            ),
            (
                "/",
                NameError::EndsWithSlash {
                    kind,
                    name: "/".into(),
                },
            ),
            (
                "/cmd-vel",
                NameError::UnallowedCharacter {
                    kind,
                    name: "/cmd-vel".into(),
                    index: 4,
                    character: '-',
                },
            ),
            (
                "/a//b",
                NameError::RepeatedSlash {
                    kind,
                    name: "/a//b".into(),
                    index: 3,
                },
            ),
            (
                "/robot/0scan",
                NameError::TokenStartsWithDigit {
                    kind,
                    name: "/robot/0scan".into(),
                    index: 7,
                },
            ),
        ];
        for (text, error) in cases {
            assert_eq!(TopicName::new(text), Err(error), "{text}");
        }
        let long = format!("/{}", "a".repeat(TOPIC_NAME_MAX_LEN));
        assert_eq!(
            TopicName::new(&long),
            Err(NameError::TooLong {
                kind,
                len: TOPIC_NAME_MAX_LEN + 1,
                max: TOPIC_NAME_MAX_LEN
            })
        );
        assert!(TopicName::new(&long[..TOPIC_NAME_MAX_LEN]).is_ok());
        assert!(TopicName::new("/~/scan").is_err());
        assert!(TopicName::new("/{node}/scan").is_err());
    }

    #[test]
    fn errors_say_what_to_write() {
        let message = TopicName::new("scan").unwrap_err().to_string();
        assert!(message.contains("`/scan`"), "{message}");
    }

    #[test]
    fn namespaces_allow_the_root() {
        assert_eq!(Namespace::new("/").unwrap(), Namespace::root());
        assert!(Namespace::new("/robots/r1").is_ok());
        assert!(matches!(
            Namespace::new("robots"),
            Err(NameError::NotAbsolute {
                kind: NameKind::Namespace,
                ..
            })
        ));
        assert!(matches!(
            Namespace::enclave("/a/"),
            Err(NameError::EndsWithSlash {
                kind: NameKind::Enclave,
                ..
            })
        ));
    }

    #[test]
    fn node_names_are_single_tokens() {
        assert!(NodeName::new("formation_agent_0").is_ok());
        assert_eq!(
            NodeName::new("0agent"),
            Err(NameError::TokenStartsWithDigit {
                kind: NameKind::Node,
                name: "0agent".into(),
                index: 0
            })
        );
        assert!(matches!(
            NodeName::new("a/b"),
            Err(NameError::UnallowedCharacter { character: '/', .. })
        ));
        assert_eq!(
            NodeName::new(""),
            Err(NameError::Empty {
                kind: NameKind::Node
            })
        );
    }
}

//! Data key expressions: where rmw_zenoh publishes a topic's samples.
//!
//! `TopicInfo`'s constructor in rmw_zenoh's `liveliness_utils.cpp` builds
//! `<domain_id>/<topic name without its leading (or trailing) slash>/<DDS type name>/<type hash>`,
//! for example `0/robot_0/cmd_vel/geometry_msgs::msg::dds_::Twist_/RIHS01_9c45…`, and both the
//! publisher and the subscription use it verbatim, so a sample reaches only subscriptions of the
//! same type with the same hash. Distros before Jazzy write `TypeHashNotSupported` as the hash.
//!
//! [`TopicKey::wildcard`] (`<domain>/<topic>/*/*`) lets a subscriber see publishers of another type
//! or hash on its topic, and [`TopicKey::expect_message`] turns such a sample into a clear error.

use std::fmt;
use std::num::ParseIntError;

use thiserror::Error;

use crate::msg::RosMessage;
use crate::names::{NameError, TopicName};
use crate::type_hash::{TypeHashError, TypeHashField};

/// Which type-hash convention a peer's distro follows.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum HashConvention {
    /// Jazzy and later: the RIHS01 hash of the message.
    Rihs01,
    /// Before Jazzy: `TypeHashNotSupported`.
    NotSupported,
}

/// A parsed or constructed data key expression.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct TopicKey {
    /// The ROS domain id.
    pub domain_id: u32,
    /// The fully qualified topic name.
    pub topic: TopicName,
    /// The DDS type name, e.g. `geometry_msgs::msg::dds_::Twist_`.
    pub type_name: String,
    /// The type hash, or the pre-Jazzy placeholder.
    pub type_hash: TypeHashField,
}

/// Why a data key expression could not be parsed, or names another type than expected.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum KeyExprError {
    /// Fewer than the four segments domain, topic, type, hash.
    #[error("key expression `{key}` is not `<domain>/<topic>/<type>/<type hash>`")]
    Malformed {
        /// The key expression.
        key: String,
    },
    /// The domain segment is not a number.
    #[error("key expression `{key}` has a domain id that is not a number")]
    BadDomain {
        /// The key expression.
        key: String,
        /// Why the number did not parse.
        #[source]
        source: ParseIntError,
    },
    /// The topic segments do not form a valid topic name.
    #[error("key expression `{key}` carries an invalid topic name")]
    BadTopic {
        /// The key expression.
        key: String,
        /// What is wrong with the name.
        #[source]
        source: NameError,
    },
    /// The hash segment is neither a RIHS01 hash nor `TypeHashNotSupported`.
    #[error("key expression `{key}` carries an invalid type hash")]
    BadTypeHash {
        /// The key expression.
        key: String,
        /// What is wrong with the hash.
        #[source]
        source: TypeHashError,
    },
    /// A sample of another message type.
    #[error(
        "{topic} carries {found}, but {expected} is needed (check the topic: the agent reads {expected} there)"
    )]
    WrongType {
        /// The topic.
        topic: String,
        /// The DDS type name this side needs.
        expected: &'static str,
        /// The DDS type name the publisher declared.
        found: String,
    },
    /// A sample of the right type name but another definition (hash) or distro.
    #[error(
        "{topic} carries {type_name} with type hash {found}, but this agent speaks the ROS 2 Jazzy definition {expected}{hint}",
        hint = if found == crate::type_hash::TYPE_HASH_NOT_SUPPORTED { " (the publisher runs a distro before Jazzy, without type hashes)" } else { " (the publisher's message definition differs)" }
    )]
    WrongTypeHash {
        /// The topic.
        topic: String,
        /// The DDS type name.
        type_name: &'static str,
        /// The hash this side needs.
        expected: &'static str,
        /// The hash the publisher declared.
        found: String,
    },
}

impl TopicKey {
    /// The key of message type `M` on `topic` in `domain_id`.
    pub fn for_message<M: RosMessage>(
        domain_id: u32,
        topic: TopicName,
        convention: HashConvention,
    ) -> TopicKey {
        TopicKey {
            domain_id,
            topic,
            type_name: M::DDS_TYPE_NAME.to_owned(),
            type_hash: match convention {
                HashConvention::Rihs01 => TypeHashField::Rihs01(M::type_hash()),
                HashConvention::NotSupported => TypeHashField::NotSupported,
            },
        }
    }

    /// `<domain>/<topic>/*/*`: every type and hash on a topic, to notice mismatched publishers.
    pub fn wildcard(domain_id: u32, topic: &TopicName) -> String {
        format!("{domain_id}/{}/*/*", topic.without_leading_slash())
    }

    /// Parses a key expression a sample arrived on.
    pub fn parse(key: &str) -> Result<TopicKey, KeyExprError> {
        let malformed = || KeyExprError::Malformed {
            key: key.to_owned(),
        };
        let (domain, rest) = key.split_once('/').ok_or_else(malformed)?;
        let (rest, hash) = rest.rsplit_once('/').ok_or_else(malformed)?;
        let (topic, type_name) = rest.rsplit_once('/').ok_or_else(malformed)?;
        if topic.is_empty() || type_name.is_empty() {
            return Err(malformed());
        }
        let domain_id = domain.parse().map_err(|source| KeyExprError::BadDomain {
            key: key.to_owned(),
            source,
        })?;
        let topic =
            TopicName::new(&format!("/{topic}")).map_err(|source| KeyExprError::BadTopic {
                key: key.to_owned(),
                source,
            })?;
        let type_hash = TypeHashField::parse(hash).map_err(|source| KeyExprError::BadTypeHash {
            key: key.to_owned(),
            source,
        })?;
        Ok(TopicKey {
            domain_id,
            topic,
            type_name: type_name.to_owned(),
            type_hash,
        })
    }

    /// Checks that this key carries message type `M` with its Jazzy hash.
    pub fn expect_message<M: RosMessage>(&self) -> Result<(), KeyExprError> {
        if self.type_name != M::DDS_TYPE_NAME {
            return Err(KeyExprError::WrongType {
                topic: self.topic.to_string(),
                expected: M::DDS_TYPE_NAME,
                found: self.type_name.clone(),
            });
        }
        if self.type_hash != TypeHashField::Rihs01(M::type_hash()) {
            return Err(KeyExprError::WrongTypeHash {
                topic: self.topic.to_string(),
                type_name: M::DDS_TYPE_NAME,
                expected: M::TYPE_HASH,
                found: self.type_hash.to_string(),
            });
        }
        Ok(())
    }
}

impl fmt::Display for TopicKey {
    /// The key expression itself.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(
            f,
            "{}/{}/{}/{}",
            self.domain_id,
            self.topic.without_leading_slash(),
            self.type_name,
            self.type_hash
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msg::{LaserScan, Twist};

    fn topic(name: &str) -> TopicName {
        TopicName::new(name).unwrap()
    }

    #[test]
    fn twist_key_matches_rmw_zenoh() {
        let key = TopicKey::for_message::<Twist>(0, topic("/cmd_vel"), HashConvention::Rihs01);
        assert_eq!(
            key.to_string(),
            "0/cmd_vel/geometry_msgs::msg::dds_::Twist_/RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a"
        );
        let humble = TopicKey::for_message::<Twist>(
            7,
            topic("/robot_0/cmd_vel"),
            HashConvention::NotSupported,
        );
        assert_eq!(
            humble.to_string(),
            "7/robot_0/cmd_vel/geometry_msgs::msg::dds_::Twist_/TypeHashNotSupported"
        );
    }

    #[test]
    fn keys_parse_back_including_nested_topics() {
        let key =
            TopicKey::for_message::<LaserScan>(3, topic("/robot_2/scan"), HashConvention::Rihs01);
        assert_eq!(TopicKey::parse(&key.to_string()), Ok(key.clone()));
        assert_eq!(key.expect_message::<LaserScan>(), Ok(()));
        assert_eq!(TopicKey::wildcard(3, &key.topic), "3/robot_2/scan/*/*");
    }

    #[test]
    fn mismatched_types_and_hashes_are_named() {
        let twist = TopicKey::for_message::<Twist>(0, topic("/scan"), HashConvention::Rihs01);
        let err = twist.expect_message::<LaserScan>().unwrap_err();
        assert!(matches!(err, KeyExprError::WrongType { .. }));
        assert!(
            err.to_string()
                .contains("sensor_msgs::msg::dds_::LaserScan_")
        );

        let humble =
            TopicKey::for_message::<LaserScan>(0, topic("/scan"), HashConvention::NotSupported);
        let err = humble.expect_message::<LaserScan>().unwrap_err();
        assert!(err.to_string().contains("before Jazzy"), "{err}");

        let mut other =
            TopicKey::for_message::<LaserScan>(0, topic("/scan"), HashConvention::Rihs01);
        other.type_hash = TypeHashField::parse(&format!("RIHS01_{}", "0".repeat(64))).unwrap();
        let err = other.expect_message::<LaserScan>().unwrap_err();
        assert!(err.to_string().contains("definition differs"), "{err}");
    }

    #[test]
    fn malformed_keys_are_refused() {
        let refusal = |key| TopicKey::parse(key).unwrap_err();
        assert!(matches!(refusal("0/scan"), KeyExprError::Malformed { .. }));
        let bad_domain = refusal("x/scan/T_/TypeHashNotSupported");
        assert!(matches!(bad_domain, KeyExprError::BadDomain { .. }));
        let bad_topic = refusal("0/9scan/T_/TypeHashNotSupported");
        assert!(matches!(bad_topic, KeyExprError::BadTopic { .. }));
        let bad_hash = refusal("0/scan/T_/RIHS01_zz");
        assert!(matches!(bad_hash, KeyExprError::BadTypeHash { .. }));
    }
}

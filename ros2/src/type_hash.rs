//! ROS 2 type hashes (REP-2011 `RIHS01_<64 hex digits>`) and the hash field of a key expression.
//!
//! rmw_zenoh_cpp puts the type hash, stringified by `rosidl_stringify_type_hash`, into every data
//! key expression and liveliness token (`rmw_publisher_data.cpp`), so a publisher and a subscriber
//! only meet when their message definitions hash alike. Distros before Jazzy have no type hashes
//! and write `TypeHashNotSupported` in their place.

use std::fmt;

use thiserror::Error;

/// The text rmw_zenoh writes in place of a type hash on distros without them (before Jazzy).
pub const TYPE_HASH_NOT_SUPPORTED: &str = "TypeHashNotSupported";

/// Prefix of a version-1 ROS interface hash.
const RIHS01_PREFIX: &str = "RIHS01_";

/// A version-1 ROS interface hash: SHA-256 over the type description.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct TypeHash(pub [u8; 32]);

/// Why a type hash string could not be parsed.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum TypeHashError {
    /// The string does not start with `RIHS01_`.
    #[error("type hash `{found}` does not start with `RIHS01_` (only version-1 hashes are known)")]
    UnknownVersion {
        /// The string given.
        found: String,
    },
    /// The digits after the prefix are not 64 lowercase hexadecimal digits.
    #[error("type hash `{found}` must be `RIHS01_` followed by 64 lowercase hexadecimal digits")]
    BadDigits {
        /// The string given.
        found: String,
    },
}

impl TypeHash {
    /// Parses `RIHS01_` and 64 lowercase hexadecimal digits, as `rosidl_stringify_type_hash`
    /// writes them.
    pub fn parse(text: &str) -> Result<TypeHash, TypeHashError> {
        let Some(digits) = text.strip_prefix(RIHS01_PREFIX) else {
            return Err(TypeHashError::UnknownVersion {
                found: text.to_owned(),
            });
        };
        let bad = || TypeHashError::BadDigits {
            found: text.to_owned(),
        };
        if digits.len() != 64 {
            return Err(bad());
        }
        let mut out = [0u8; 32];
        for (byte, pair) in out.iter_mut().zip(digits.as_bytes().chunks_exact(2)) {
            let high = lower_hex_value(pair[0]).ok_or_else(bad)?;
            let low = lower_hex_value(pair[1]).ok_or_else(bad)?;
            *byte = high << 4 | low;
        }
        Ok(TypeHash(out))
    }
}

impl TypeHash {
    /// Parses a hash in a constant: a malformed one stops compilation (const evaluation panics),
    /// so no malformed constant can reach run time. Crate-private: run-time text goes through
    /// [`TypeHash::parse`].
    pub(crate) const fn from_constant(text: &str) -> TypeHash {
        let bytes = text.as_bytes();
        let prefix = RIHS01_PREFIX.as_bytes();
        assert!(
            bytes.len() == prefix.len() + 64,
            "a RIHS01 hash is `RIHS01_` and 64 hexadecimal digits"
        );
        let mut i = 0;
        while i < prefix.len() {
            assert!(bytes[i] == prefix[i], "a RIHS01 hash starts with `RIHS01_`");
            i += 1;
        }
        let mut out = [0u8; 32];
        let mut k = 0;
        while k < 32 {
            let high = lower_hex_value(bytes[prefix.len() + 2 * k]);
            let low = lower_hex_value(bytes[prefix.len() + 2 * k + 1]);
            match (high, low) {
                (Some(high), Some(low)) => out[k] = high << 4 | low,
                _ => panic!("a RIHS01 hash has lowercase hexadecimal digits"),
            }
            k += 1;
        }
        TypeHash(out)
    }
}

const fn lower_hex_value(digit: u8) -> Option<u8> {
    match digit {
        b'0'..=b'9' => Some(digit - b'0'),
        b'a'..=b'f' => Some(digit - b'a' + 10),
        _ => None,
    }
}

impl fmt::Display for TypeHash {
    /// `RIHS01_` and 64 lowercase hexadecimal digits.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(RIHS01_PREFIX)?;
        for byte in self.0 {
            write!(f, "{byte:02x}")?;
        }
        Ok(())
    }
}

/// What a key expression carries in its type-hash position.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum TypeHashField {
    /// A Jazzy-or-later RIHS01 hash.
    Rihs01(TypeHash),
    /// `TypeHashNotSupported`, written by distros before Jazzy (Humble, Iron's rmw_zenoh ports).
    NotSupported,
}

impl TypeHashField {
    /// Parses a hash segment: `TypeHashNotSupported` or a RIHS01 hash.
    pub fn parse(text: &str) -> Result<TypeHashField, TypeHashError> {
        if text == TYPE_HASH_NOT_SUPPORTED {
            Ok(TypeHashField::NotSupported)
        } else {
            TypeHash::parse(text).map(TypeHashField::Rihs01)
        }
    }
}

impl fmt::Display for TypeHashField {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            TypeHashField::Rihs01(hash) => hash.fmt(f),
            TypeHashField::NotSupported => f.write_str(TYPE_HASH_NOT_SUPPORTED),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hash_round_trips_through_its_text() {
        let text = "RIHS01_9c45bf16fe0983d80e3cfe750d6835843d265a9a6c46bd2e609fcddde6fb8d2a";
        let hash = TypeHash::parse(text).unwrap();
        assert_eq!(hash.0[0], 0x9c);
        assert_eq!(hash.0[31], 0x2a);
        assert_eq!(hash.to_string(), text);
    }

    #[test]
    fn constant_parsing_agrees_with_run_time_parsing() {
        let text = "RIHS01_64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828";
        const SCAN: TypeHash = TypeHash::from_constant(
            "RIHS01_64c191398013af96509d518dac71d5164f9382553fce5c1f8cca5be7924bd828",
        );
        assert_eq!(Ok(SCAN), TypeHash::parse(text));
    }

    #[test]
    fn malformed_hashes_are_refused_with_the_reason() {
        let refusal = |text: &str| TypeHash::parse(text).unwrap_err();
        let version = refusal("RIHS02_00");
        assert!(matches!(version, TypeHashError::UnknownVersion { .. }));
        assert!(matches!(
            refusal("RIHS01_abc"),
            TypeHashError::BadDigits { .. }
        ));
        let upper = format!("RIHS01_{}", "A".repeat(64));
        assert!(matches!(refusal(&upper), TypeHashError::BadDigits { .. }));
    }

    #[test]
    fn pre_jazzy_placeholder_parses() {
        assert_eq!(
            TypeHashField::parse("TypeHashNotSupported"),
            Ok(TypeHashField::NotSupported)
        );
        assert_eq!(
            TypeHashField::NotSupported.to_string(),
            "TypeHashNotSupported"
        );
    }
}

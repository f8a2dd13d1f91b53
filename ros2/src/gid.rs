//! Entity GIDs as rmw_zenoh derives them: XXH3-128 of the entity's liveliness key expression.
//!
//! `Entity`'s constructor in rmw_zenoh's `liveliness_utils.cpp` hashes the complete liveliness
//! key expression with XXH3 (128 bits, seed 0, default secret) and stores the low 64 bits then
//! the high 64 bits, each in host (little-endian) order, as the 16-byte GID. Every rmw_zenoh
//! process computes the GID of a remote entity the same way from its token, so a publisher that
//! puts this GID in its [attachments](crate::attachment) is the same entity in
//! `ros2 topic info -v` and in the `publisher_gid` of each message's info.
//!
//! The hash is the `xxhash-rust` crate's; `tests/wire_format.rs` checks it against the `xxhash`
//! Python package over every length class, so a change of either side is caught.

use crate::attachment::GID_LEN;

/// The GID rmw_zenoh gives the entity whose liveliness key expression is `token_key`.
pub fn entity_gid(token_key: &str) -> [u8; GID_LEN] {
    xxh3_128(token_key.as_bytes()).to_le_bytes()
}

/// XXH3-128 with seed 0 and the default secret, as `(high << 64) | low`.
pub fn xxh3_128(input: &[u8]) -> u128 {
    xxhash_rust::xxh3::xxh3_128(input)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn empty_input_hash_is_the_published_value() {
        // XXH3-128 of the empty input with seed 0 (xxHash's reference value).
        assert_eq!(xxh3_128(b""), 0x99aa_06d3_0147_98d8_6001_c324_468d_497f);
    }

    #[test]
    fn gid_is_the_low_half_then_the_high_half_little_endian() {
        let hash = xxh3_128(b"@ros2_lv/0/ab/0/0/NN/%/%/talker");
        let gid = entity_gid("@ros2_lv/0/ab/0/0/NN/%/%/talker");
        assert_eq!(gid[..8], (hash as u64).to_le_bytes());
        assert_eq!(gid[8..], ((hash >> 64) as u64).to_le_bytes());
    }
}

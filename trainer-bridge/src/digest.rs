//! A small, stable, dependency-free 64-bit hash (FNV-1a) for dataset ids and shard checksums.
//!
//! `std`'s `DefaultHasher` may change between Rust releases; dataset ids must not, so the
//! algorithm is spelled out here. It detects accidental corruption; it is not cryptographic.

/// Incremental FNV-1a, 64-bit.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) struct Fnv1a64(u64);

impl Fnv1a64 {
    const OFFSET_BASIS: u64 = 0xcbf2_9ce4_8422_2325;
    const PRIME: u64 = 0x0000_0100_0000_01b3;

    /// A fresh hash.
    pub(crate) fn new() -> Fnv1a64 {
        Fnv1a64(Self::OFFSET_BASIS)
    }

    /// Feeds `bytes`.
    pub(crate) fn update(&mut self, bytes: &[u8]) {
        let mut state = self.0;
        for &byte in bytes {
            state ^= u64::from(byte);
            state = state.wrapping_mul(Self::PRIME);
        }
        self.0 = state;
    }

    /// Feeds a length-prefixed field, so that ("ab", "c") and ("a", "bc") hash differently.
    pub(crate) fn update_field(&mut self, bytes: &[u8]) {
        self.update(&(bytes.len() as u64).to_le_bytes());
        self.update(bytes);
    }

    /// The hash as 16 lowercase hex digits.
    pub(crate) fn hex(&self) -> String {
        format!("{:016x}", self.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn hash(bytes: &[u8]) -> String {
        let mut h = Fnv1a64::new();
        h.update(bytes);
        h.hex()
    }

    #[test]
    fn matches_the_published_fnv1a64_test_vectors() {
        assert_eq!(hash(b""), "cbf29ce484222325");
        assert_eq!(hash(b"a"), "af63dc4c8601ec8c");
        assert_eq!(hash(b"foobar"), "85944171f73967e8");
    }

    #[test]
    fn incremental_updates_equal_one_update() {
        let mut h = Fnv1a64::new();
        h.update(b"foo");
        h.update(b"bar");
        assert_eq!(h.hex(), hash(b"foobar"));
    }

    #[test]
    fn length_prefixed_fields_separate_boundaries() {
        let mut a = Fnv1a64::new();
        a.update_field(b"ab");
        a.update_field(b"c");
        let mut b = Fnv1a64::new();
        b.update_field(b"a");
        b.update_field(b"bc");
        assert_ne!(a.hex(), b.hex());
    }
}

//! Entity GIDs as rmw_zenoh derives them: XXH3-128 of the entity's liveliness key expression.
//!
//! `Entity`'s constructor in rmw_zenoh's `liveliness_utils.cpp` hashes the complete liveliness
//! key expression with XXH3 (128 bits, seed 0, default secret; its `simplified_xxhash3.cpp`) and
//! stores the low 64 bits then the high 64 bits, each in host (little-endian) order, as the
//! 16-byte GID. Every rmw_zenoh process computes the GID of a remote entity the same way from its
//! token, so a publisher that puts this GID in its [attachments](crate::attachment) is the same
//! entity in `ros2 topic info -v` and in the `publisher_gid` of each message's info.
//!
//! The hash is implemented here from the XXH3 specification (scalar path only) and checked
//! against the `xxhash` Python package over every length class (`tests/wire_format.rs`).

use crate::attachment::GID_LEN;

const PRIME32_1: u64 = 0x9E37_79B1;
const PRIME32_2: u64 = 0x85EB_CA77;
const PRIME32_3: u64 = 0xC2B2_AE3D;
const PRIME64_1: u64 = 0x9E37_79B1_85EB_CA87;
const PRIME64_2: u64 = 0xC2B2_AE3D_27D4_EB4F;
const PRIME64_3: u64 = 0x1656_67B1_9E37_79F9;
const PRIME64_4: u64 = 0x85EB_CA77_C2B2_AE63;
const PRIME64_5: u64 = 0x27D4_EB2F_1656_67C5;
const PRIME_MX1: u64 = 0x1656_6791_9E37_79F9;
const PRIME_MX2: u64 = 0x9FB2_1C65_1E98_DF25;

/// XXH3's default 192-byte secret (the specification's `kSecret`).
const SECRET: [u8; 192] = [
    0xb8, 0xfe, 0x6c, 0x39, 0x23, 0xa4, 0x4b, 0xbe, 0x7c, 0x01, 0x81, 0x2c, 0xf7, 0x21, 0xad, 0x1c,
    0xde, 0xd4, 0x6d, 0xe9, 0x83, 0x90, 0x97, 0xdb, 0x72, 0x40, 0xa4, 0xa4, 0xb7, 0xb3, 0x67, 0x1f,
    0xcb, 0x79, 0xe6, 0x4e, 0xcc, 0xc0, 0xe5, 0x78, 0x82, 0x5a, 0xd0, 0x7d, 0xcc, 0xff, 0x72, 0x21,
    0xb8, 0x08, 0x46, 0x74, 0xf7, 0x43, 0x24, 0x8e, 0xe0, 0x35, 0x90, 0xe6, 0x81, 0x3a, 0x26, 0x4c,
    0x3c, 0x28, 0x52, 0xbb, 0x91, 0xc3, 0x00, 0xcb, 0x88, 0xd0, 0x65, 0x8b, 0x1b, 0x53, 0x2e, 0xa3,
    0x71, 0x64, 0x48, 0x97, 0xa2, 0x0d, 0xf9, 0x4e, 0x38, 0x19, 0xef, 0x46, 0xa9, 0xde, 0xac, 0xd8,
    0xa8, 0xfa, 0x76, 0x3f, 0xe3, 0x9c, 0x34, 0x3f, 0xf9, 0xdc, 0xbb, 0xc7, 0xc7, 0x0b, 0x4f, 0x1d,
    0x8a, 0x51, 0xe0, 0x4b, 0xcd, 0xb4, 0x59, 0x31, 0xc8, 0x9f, 0x7e, 0xc9, 0xd9, 0x78, 0x73, 0x64,
    0xea, 0xc5, 0xac, 0x83, 0x34, 0xd3, 0xeb, 0xc3, 0xc5, 0x81, 0xa0, 0xff, 0xfa, 0x13, 0x63, 0xeb,
    0x17, 0x0d, 0xdd, 0x51, 0xb7, 0xf0, 0xda, 0x49, 0xd3, 0x16, 0x55, 0x26, 0x29, 0xd4, 0x68, 0x9e,
    0x2b, 0x16, 0xbe, 0x58, 0x7d, 0x47, 0xa1, 0xfc, 0x8f, 0xf8, 0xb8, 0xd1, 0x7a, 0xd0, 0x31, 0xce,
    0x45, 0xcb, 0x3a, 0x8f, 0x95, 0x16, 0x04, 0x28, 0xaf, 0xd7, 0xfb, 0xca, 0xbb, 0x4b, 0x40, 0x7e,
];

/// Stripe length of the long-input loop.
const STRIPE_LEN: usize = 64;
/// Secret bytes consumed per stripe.
const SECRET_CONSUME_RATE: usize = 8;
/// Smallest secret XXH3 allows; the 129–240-byte path's last mix is placed against it.
const SECRET_SIZE_MIN: usize = 136;

/// The GID rmw_zenoh gives the entity whose liveliness key expression is `token_key`.
pub fn entity_gid(token_key: &str) -> [u8; GID_LEN] {
    xxh3_128(token_key.as_bytes()).to_le_bytes()
}

/// XXH3-128 with seed 0 and the default secret, as `(high << 64) | low`.
pub fn xxh3_128(input: &[u8]) -> u128 {
    let (low, high) = match input.len() {
        0 => (
            xxh64_avalanche(read64(&SECRET, 64) ^ read64(&SECRET, 72)),
            xxh64_avalanche(read64(&SECRET, 80) ^ read64(&SECRET, 88)),
        ),
        1..=3 => len_1_to_3(input),
        4..=8 => len_4_to_8(input),
        9..=16 => len_9_to_16(input),
        17..=128 => len_17_to_128(input),
        129..=240 => len_129_to_240(input),
        _ => long(input),
    };
    u128::from(high) << 64 | u128::from(low)
}

fn read64(bytes: &[u8], at: usize) -> u64 {
    let mut word = [0u8; 8];
    word.copy_from_slice(&bytes[at..at + 8]);
    u64::from_le_bytes(word)
}

fn read32(bytes: &[u8], at: usize) -> u64 {
    let mut word = [0u8; 4];
    word.copy_from_slice(&bytes[at..at + 4]);
    u64::from(u32::from_le_bytes(word))
}

fn multiply_64_to_128(a: u64, b: u64) -> (u64, u64) {
    let product = u128::from(a) * u128::from(b);
    (product as u64, (product >> 64) as u64)
}

fn multiply_fold_64(a: u64, b: u64) -> u64 {
    let (low, high) = multiply_64_to_128(a, b);
    low ^ high
}

fn xxh64_avalanche(mut h: u64) -> u64 {
    h ^= h >> 33;
    h = h.wrapping_mul(PRIME64_2);
    h ^= h >> 29;
    h = h.wrapping_mul(PRIME64_3);
    h ^ (h >> 32)
}

fn xxh3_avalanche(mut h: u64) -> u64 {
    h ^= h >> 37;
    h = h.wrapping_mul(PRIME_MX1);
    h ^ (h >> 32)
}

fn len_1_to_3(input: &[u8]) -> (u64, u64) {
    let len = input.len();
    let (c1, c2, c3) = (
        u32::from(input[0]),
        u32::from(input[len >> 1]),
        u32::from(input[len - 1]),
    );
    let combined_low = (c1 << 16) | (c2 << 24) | c3 | ((len as u32) << 8);
    let combined_high = combined_low.swap_bytes().rotate_left(13);
    let flip_low = read32(&SECRET, 0) ^ read32(&SECRET, 4);
    let flip_high = read32(&SECRET, 8) ^ read32(&SECRET, 12);
    (
        xxh64_avalanche(u64::from(combined_low) ^ flip_low),
        xxh64_avalanche(u64::from(combined_high) ^ flip_high),
    )
}

fn len_4_to_8(input: &[u8]) -> (u64, u64) {
    let len = input.len();
    let word = read32(input, 0) + (read32(input, len - 4) << 32);
    let flip = read64(&SECRET, 16) ^ read64(&SECRET, 24);
    let (mut low, mut high) =
        multiply_64_to_128(word ^ flip, PRIME64_1.wrapping_add((len as u64) << 2));
    high = high.wrapping_add(low << 1);
    low ^= high >> 3;
    low ^= low >> 35;
    low = low.wrapping_mul(PRIME_MX2);
    low ^= low >> 28;
    (low, xxh3_avalanche(high))
}

fn len_9_to_16(input: &[u8]) -> (u64, u64) {
    let len = input.len();
    let flip_low = read64(&SECRET, 32) ^ read64(&SECRET, 40);
    let flip_high = read64(&SECRET, 48) ^ read64(&SECRET, 56);
    let first = read64(input, 0);
    let last = read64(input, len - 8);
    let (mut low, mut high) = multiply_64_to_128(first ^ last ^ flip_low, PRIME64_1);
    low = low.wrapping_add(((len - 1) as u64) << 54);
    let last = last ^ flip_high;
    high = high
        .wrapping_add(last)
        .wrapping_add((last & 0xFFFF_FFFF).wrapping_mul(PRIME32_2 - 1));
    low ^= high.swap_bytes();
    let (out_low, out_high) = multiply_64_to_128(low, PRIME64_2);
    let out_high = out_high.wrapping_add(high.wrapping_mul(PRIME64_2));
    (xxh3_avalanche(out_low), xxh3_avalanche(out_high))
}

fn mix_16(input: &[u8], at: usize, secret_at: usize) -> u64 {
    multiply_fold_64(
        read64(input, at) ^ read64(&SECRET, secret_at),
        read64(input, at + 8) ^ read64(&SECRET, secret_at + 8),
    )
}

/// Mixes two 16-byte lanes of `input` (at `first` and `second`) into the accumulator pair.
fn mix_32(
    acc: (u64, u64),
    input: &[u8],
    first: usize,
    second: usize,
    secret_at: usize,
) -> (u64, u64) {
    let mut low = acc.0.wrapping_add(mix_16(input, first, secret_at));
    low ^= read64(input, second).wrapping_add(read64(input, second + 8));
    let mut high = acc.1.wrapping_add(mix_16(input, second, secret_at + 16));
    high ^= read64(input, first).wrapping_add(read64(input, first + 8));
    (low, high)
}

fn finish_mid(acc: (u64, u64), len: usize) -> (u64, u64) {
    let low = acc.0.wrapping_add(acc.1);
    let high = acc
        .0
        .wrapping_mul(PRIME64_1)
        .wrapping_add(acc.1.wrapping_mul(PRIME64_4))
        .wrapping_add((len as u64).wrapping_mul(PRIME64_2));
    (xxh3_avalanche(low), xxh3_avalanche(high).wrapping_neg())
}

fn len_17_to_128(input: &[u8]) -> (u64, u64) {
    let len = input.len();
    let mut acc = ((len as u64).wrapping_mul(PRIME64_1), 0);
    if len > 32 {
        if len > 64 {
            if len > 96 {
                acc = mix_32(acc, input, 48, len - 64, 96);
            }
            acc = mix_32(acc, input, 32, len - 48, 64);
        }
        acc = mix_32(acc, input, 16, len - 32, 32);
    }
    acc = mix_32(acc, input, 0, len - 16, 0);
    finish_mid(acc, len)
}

fn len_129_to_240(input: &[u8]) -> (u64, u64) {
    const START_OFFSET: usize = 3;
    const LAST_OFFSET: usize = 17;
    let len = input.len();
    let rounds = len / 32;
    let mut acc = ((len as u64).wrapping_mul(PRIME64_1), 0);
    for i in 0..4 {
        acc = mix_32(acc, input, 32 * i, 32 * i + 16, 32 * i);
    }
    acc = (xxh3_avalanche(acc.0), xxh3_avalanche(acc.1));
    for i in 4..rounds {
        acc = mix_32(acc, input, 32 * i, 32 * i + 16, START_OFFSET + 32 * (i - 4));
    }
    acc = mix_32(
        acc,
        input,
        len - 16,
        len - 32,
        SECRET_SIZE_MIN - LAST_OFFSET - 16,
    );
    finish_mid(acc, len)
}

fn accumulate_stripe(acc: &mut [u64; 8], input: &[u8], at: usize, secret_at: usize) {
    for lane in 0..8 {
        let value = read64(input, at + 8 * lane);
        let keyed = value ^ read64(&SECRET, secret_at + 8 * lane);
        acc[lane ^ 1] = acc[lane ^ 1].wrapping_add(value);
        acc[lane] = acc[lane].wrapping_add((keyed & 0xFFFF_FFFF).wrapping_mul(keyed >> 32));
    }
}

fn scramble(acc: &mut [u64; 8]) {
    let secret_at = SECRET.len() - STRIPE_LEN;
    for (lane, a) in acc.iter_mut().enumerate() {
        let mut v = *a;
        v ^= v >> 47;
        v ^= read64(&SECRET, secret_at + 8 * lane);
        *a = v.wrapping_mul(PRIME32_1);
    }
}

fn merge(acc: &[u64; 8], secret_at: usize, start: u64) -> u64 {
    let mut result = start;
    for pair in 0..4 {
        result = result.wrapping_add(multiply_fold_64(
            acc[2 * pair] ^ read64(&SECRET, secret_at + 16 * pair),
            acc[2 * pair + 1] ^ read64(&SECRET, secret_at + 16 * pair + 8),
        ));
    }
    xxh3_avalanche(result)
}

fn long(input: &[u8]) -> (u64, u64) {
    const LAST_STRIPE_SECRET_OFFSET: usize = 7;
    const MERGE_SECRET_OFFSET: usize = 11;
    let len = input.len();
    let mut acc = [
        PRIME32_3, PRIME64_1, PRIME64_2, PRIME64_3, PRIME64_4, PRIME32_2, PRIME64_5, PRIME32_1,
    ];
    let stripes_per_block = (SECRET.len() - STRIPE_LEN) / SECRET_CONSUME_RATE;
    let block_len = STRIPE_LEN * stripes_per_block;
    let blocks = (len - 1) / block_len;
    for block in 0..blocks {
        for stripe in 0..stripes_per_block {
            accumulate_stripe(
                &mut acc,
                input,
                block * block_len + stripe * STRIPE_LEN,
                stripe * SECRET_CONSUME_RATE,
            );
        }
        scramble(&mut acc);
    }
    let last_stripes = ((len - 1) - block_len * blocks) / STRIPE_LEN;
    for stripe in 0..last_stripes {
        accumulate_stripe(
            &mut acc,
            input,
            blocks * block_len + stripe * STRIPE_LEN,
            stripe * SECRET_CONSUME_RATE,
        );
    }
    accumulate_stripe(
        &mut acc,
        input,
        len - STRIPE_LEN,
        SECRET.len() - STRIPE_LEN - LAST_STRIPE_SECRET_OFFSET,
    );
    let low = merge(
        &acc,
        MERGE_SECRET_OFFSET,
        (len as u64).wrapping_mul(PRIME64_1),
    );
    let high = merge(
        &acc,
        SECRET.len() - STRIPE_LEN - MERGE_SECRET_OFFSET,
        !(len as u64).wrapping_mul(PRIME64_2),
    );
    (low, high)
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

//! How a case is made from the seed corpus: a seed, then one to four mutations drawn as
//! [`Mutation`] values with `arbitrary` from random bytes.
//!
//! The mutations are the ones that get past a decoder's first check and into its body: cut the
//! input short, flip a bit, overwrite a byte, overwrite a 16/32/64-bit word (a length, a count, a
//! float) with a value chosen to hurt (0, 1, the input's own length ± 1, all ones, the sign bit,
//! NaN, infinities), nudge a word by a small delta, delete, duplicate or insert a range, insert or
//! overwrite a token from the target's dictionary (magic bytes, keys, numbers), replace the next
//! decimal number of a text with an extreme one, and splice in part of another seed.
//!
//! A case is a pure function of the seeds, the campaign's seed and its index ([`make_case`]), so
//! any case of a campaign can be made again from those three numbers.

use arbitrary::{Arbitrary, Unstructured};
use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Longest case made (a case that would grow past it is cut back to it).
pub const MAX_CASE_BYTES: usize = 4 << 20;

/// Random bytes drawn per case for its mutations.
const ENTROPY_BYTES: usize = 96;

/// Decimal numbers that hurt parsers and validators, used by [`Mutation::Number`].
pub const EXTREME_NUMBERS: &[&str] = &[
    "0",
    "-0",
    "1",
    "-1",
    "0.0",
    "1e-320",
    "1e308",
    "1e309",
    "-1e309",
    "nan",
    "inf",
    "-inf",
    "4294967295",
    "4294967296",
    "9223372036854775807",
    "18446744073709551615",
    "18446744073709551616",
    "99999999999999999999999999",
    "65536",
    "1024",
    "1025",
    "0x10",
    "",
];

/// Word widths a [`Mutation::Word`] or [`Mutation::Nudge`] writes.
#[derive(Debug, Clone, Copy, Arbitrary)]
pub enum Width {
    /// Two bytes.
    U16,
    /// Four bytes (also an `f32`).
    U32,
    /// Eight bytes (also an `f64`).
    U64,
}

impl Width {
    fn bytes(self) -> usize {
        match self {
            Width::U16 => 2,
            Width::U32 => 4,
            Width::U64 => 8,
        }
    }
}

/// A value a [`Mutation::Word`] writes.
#[derive(Debug, Clone, Copy, Arbitrary)]
pub enum Special {
    /// 0.
    Zero,
    /// 1.
    One,
    /// All ones (`u*::MAX`, `-1`).
    AllOnes,
    /// The largest signed value.
    SignedMax,
    /// The sign bit alone (the smallest signed value).
    SignBit,
    /// The case's own length.
    Len,
    /// The case's length plus one.
    LenPlusOne,
    /// The case's length minus one.
    LenMinusOne,
    /// A power of two.
    Power(u8),
    /// A float: NaN.
    Nan,
    /// A float: +infinity.
    Infinity,
    /// A float: -infinity.
    NegInfinity,
    /// A float: -0.0.
    NegZero,
    /// A float: the largest finite value.
    FloatMax,
    /// Random bits.
    Bits(u64),
}

/// One change to a case. Positions are taken modulo the case's length.
#[derive(Debug, Clone, Arbitrary)]
pub enum Mutation {
    /// Keeps the first `at` bytes.
    Truncate {
        /// Where to cut.
        at: u32,
    },
    /// Flips one bit.
    FlipBit {
        /// The byte.
        at: u32,
        /// The bit (mod 8).
        bit: u8,
    },
    /// Sets one byte.
    SetByte {
        /// The byte.
        at: u32,
        /// Its new value.
        value: u8,
    },
    /// Overwrites a little- or big-endian word with a [`Special`] value.
    Word {
        /// First byte of the word.
        at: u32,
        /// Its width.
        width: Width,
        /// The value.
        value: Special,
        /// Big-endian instead of little-endian.
        big_endian: bool,
    },
    /// Adds a small signed delta to a little-endian word (a length or count off by a few).
    Nudge {
        /// First byte of the word.
        at: u32,
        /// Its width.
        width: Width,
        /// The delta.
        delta: i8,
    },
    /// Deletes a range.
    Delete {
        /// First byte.
        at: u32,
        /// Bytes deleted.
        len: u16,
    },
    /// Copies a range to another place (inserted).
    Duplicate {
        /// First byte copied.
        from: u32,
        /// Bytes copied.
        len: u16,
        /// Where the copy goes.
        to: u32,
    },
    /// Inserts a few random bytes.
    Insert {
        /// Where.
        at: u32,
        /// The bytes (at most 16 are used).
        bytes: Vec<u8>,
    },
    /// Inserts or overwrites a token of the target's dictionary.
    Token {
        /// Where.
        at: u32,
        /// Which token (mod the dictionary's size).
        which: u16,
        /// Overwrite instead of insert.
        overwrite: bool,
    },
    /// Replaces the first decimal number at or after `at` with one of [`EXTREME_NUMBERS`].
    Number {
        /// Where the search starts.
        at: u32,
        /// Which number (mod the list's size).
        which: u8,
    },
    /// Puts a range of another seed at `at`, replacing the rest of the case.
    Splice {
        /// Which seed (mod the corpus size).
        seed: u16,
        /// First byte taken from it.
        from: u32,
        /// Where it goes in the case.
        at: u32,
    },
}

/// The first `n` mutations drawn from `u` (one to four; fewer when the entropy runs out).
fn draw(u: &mut Unstructured<'_>) -> Vec<Mutation> {
    let n = u.int_in_range(1..=4u8).unwrap_or(1);
    (0..n).filter_map(|_| Mutation::arbitrary(u).ok()).collect()
}

fn pos(at: u32, len: usize) -> usize {
    if len == 0 { 0 } else { at as usize % len }
}

fn special(value: Special, width: Width, len: usize) -> u64 {
    let bits = width.bytes() as u32 * 8;
    let mask = if bits == 64 {
        u64::MAX
    } else {
        (1u64 << bits) - 1
    };
    let float = |x: f64| match width {
        Width::U64 => x.to_bits(),
        Width::U32 => u64::from((x as f32).to_bits()),
        Width::U16 => 0x7c00,
    };
    let v = match value {
        Special::Zero => 0,
        Special::One => 1,
        Special::AllOnes => u64::MAX,
        Special::SignedMax => mask >> 1,
        Special::SignBit => 1u64 << (bits - 1),
        Special::Len => len as u64,
        Special::LenPlusOne => len as u64 + 1,
        Special::LenMinusOne => (len as u64).wrapping_sub(1),
        Special::Power(p) => 1u64 << (u32::from(p) % bits),
        Special::Nan => float(f64::NAN),
        Special::Infinity => float(f64::INFINITY),
        Special::NegInfinity => float(f64::NEG_INFINITY),
        Special::NegZero => float(-0.0),
        Special::FloatMax => match width {
            Width::U64 => f64::MAX.to_bits(),
            Width::U32 => u64::from(f32::MAX.to_bits()),
            Width::U16 => 0x7bff,
        },
        Special::Bits(b) => b,
    };
    v & mask
}

fn write_word(case: &mut [u8], at: usize, width: Width, value: u64, big_endian: bool) {
    let n = width.bytes().min(case.len() - at);
    let bytes = if big_endian {
        value.to_be_bytes()[8 - width.bytes()..].to_vec()
    } else {
        value.to_le_bytes()[..width.bytes()].to_vec()
    };
    case[at..at + n].copy_from_slice(&bytes[..n]);
}

fn read_word(case: &[u8], at: usize, width: Width) -> u64 {
    let mut le = [0u8; 8];
    let n = width.bytes().min(case.len() - at);
    le[..n].copy_from_slice(&case[at..at + n]);
    u64::from_le_bytes(le)
}

/// Applies one mutation; `seeds` serves splices and `tokens` the dictionary.
pub fn apply(case: &mut Vec<u8>, mutation: &Mutation, seeds: &[Vec<u8>], tokens: &[&[u8]]) {
    let len = case.len();
    match *mutation {
        Mutation::Truncate { at } => case.truncate(pos(at, len + 1)),
        Mutation::FlipBit { at, bit } if len > 0 => case[pos(at, len)] ^= 1 << (bit % 8),
        Mutation::SetByte { at, value } if len > 0 => case[pos(at, len)] = value,
        Mutation::Word {
            at,
            width,
            value,
            big_endian,
        } if len > 0 => {
            let at = pos(at, len);
            write_word(case, at, width, special(value, width, len), big_endian);
        }
        Mutation::Nudge { at, width, delta } if len > 0 => {
            let at = pos(at, len);
            let v = read_word(case, at, width).wrapping_add_signed(i64::from(delta));
            write_word(case, at, width, v, false);
        }
        Mutation::Delete { at, len: n } if len > 0 => {
            let at = pos(at, len);
            let end = (at + usize::from(n)).min(len);
            case.drain(at..end);
        }
        Mutation::Duplicate { from, len: n, to } if len > 0 => {
            let from = pos(from, len);
            let end = (from + usize::from(n)).min(len);
            let copy = case[from..end].to_vec();
            let to = pos(to, len + 1);
            case.splice(to..to, copy);
        }
        Mutation::Insert { at, ref bytes } => {
            let at = pos(at, len + 1);
            let bytes = &bytes[..bytes.len().min(16)];
            case.splice(at..at, bytes.iter().copied());
        }
        Mutation::Token {
            at,
            which,
            overwrite,
        } if !tokens.is_empty() => {
            let token = tokens[usize::from(which) % tokens.len()];
            let at = pos(at, len + 1);
            if overwrite {
                let end = (at + token.len()).min(len);
                case.splice(at..end, token.iter().copied());
            } else {
                case.splice(at..at, token.iter().copied());
            }
        }
        Mutation::Number { at, which } => {
            let start = pos(at, len + 1);
            if let Some(first) = case[start..].iter().position(u8::is_ascii_digit) {
                let first = start + first;
                let end = case[first..]
                    .iter()
                    .position(|b| !(b.is_ascii_digit() || *b == b'.'))
                    .map_or(len, |n| first + n);
                let number = EXTREME_NUMBERS[usize::from(which) % EXTREME_NUMBERS.len()];
                case.splice(first..end, number.bytes());
            }
        }
        Mutation::Splice { seed, from, at } if !seeds.is_empty() => {
            let other = &seeds[usize::from(seed) % seeds.len()];
            let from = pos(from, other.len() + 1);
            let at = pos(at, len + 1);
            case.truncate(at);
            case.extend_from_slice(&other[from..]);
        }
        _ => {}
    }
    case.truncate(MAX_CASE_BYTES);
}

/// What a target's cases must look like to get past its decoder's first check, most of the time.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Shape {
    /// Any bytes.
    Bytes,
    /// Seven cases in eight keep their seed's length (cut or padded with zeros after the
    /// mutations): fixed-size messages refuse every other length at once.
    FixedLength,
    /// Seven cases in eight are made valid UTF-8 after the mutations (each bad sequence becomes
    /// U+FFFD): text formats refuse other bytes at once.
    Text,
}

/// The random number generator of case `index` of the campaign seeded with `campaign`.
fn case_rng(campaign: u64, index: u64) -> ChaCha8Rng {
    let mut rng = ChaCha8Rng::seed_from_u64(campaign);
    rng.set_stream(index);
    rng
}

/// Case `index` of the campaign seeded with `campaign`: which seed it starts from, the
/// mutations, and the bytes. Every 64th case is a seed unchanged, so the seeds stay exercised.
pub fn make_case(
    seeds: &[Vec<u8>],
    tokens: &[&[u8]],
    shape: Shape,
    campaign: u64,
    index: u64,
) -> (usize, Vec<Mutation>, Vec<u8>) {
    let mut rng = case_rng(campaign, index);
    let seed = (rng.next_u64() % seeds.len().max(1) as u64) as usize;
    let mut case = seeds.get(seed).cloned().unwrap_or_default();
    if index.is_multiple_of(64) {
        return (seed, Vec::new(), case);
    }
    let mut entropy = [0u8; ENTROPY_BYTES];
    rng.fill_bytes(&mut entropy);
    let mutations = draw(&mut Unstructured::new(&entropy));
    for mutation in &mutations {
        apply(&mut case, mutation, seeds, tokens);
    }
    if !rng.next_u32().is_multiple_of(8) {
        match shape {
            Shape::Bytes => {}
            Shape::FixedLength => case.resize(seeds[seed].len(), 0),
            Shape::Text => {
                if let std::borrow::Cow::Owned(text) = String::from_utf8_lossy(&case) {
                    case = text.into_bytes();
                }
            }
        }
    }
    (seed, mutations, case)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_case_is_made_again_from_the_campaign_seed_and_its_index() {
        let seeds = vec![b"name = \"a\"\nrobots = 3\n".to_vec(), vec![0u8; 40]];
        for index in 0..200 {
            let a = make_case(&seeds, &[b"[x]"], Shape::Bytes, 7, index);
            let b = make_case(&seeds, &[b"[x]"], Shape::Bytes, 7, index);
            assert_eq!(a.2, b.2);
        }
        let changed = (1..200)
            .filter(|&i| {
                let (seed, _, case) = make_case(&seeds, &[], Shape::Bytes, 7, i);
                case != seeds[seed]
            })
            .count();
        assert!(changed > 150, "only {changed} of 199 cases were mutated");
    }

    #[test]
    fn words_take_the_values_that_hurt() {
        let mut case = vec![0u8; 8];
        let word = |value| Mutation::Word {
            at: 2,
            width: Width::U32,
            value,
            big_endian: false,
        };
        apply(&mut case, &word(Special::LenPlusOne), &[], &[]);
        assert_eq!(case, [0, 0, 9, 0, 0, 0, 0, 0]);
        apply(&mut case, &word(Special::Nan), &[], &[]);
        assert_eq!(&case[2..6], &f32::NAN.to_bits().to_le_bytes());
        let mut text = b"robots = 12\n".to_vec();
        apply(&mut text, &Mutation::Number { at: 0, which: 7 }, &[], &[]);
        assert_eq!(text, b"robots = 1e309\n");
    }
}

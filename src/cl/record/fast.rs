//! The fast path: one whole `GOTO/` of short decimals, read in place in the input buffer without
//! allocating. Anything it does not take word for word goes to the general parser, which gives
//! the same record (property-tested against `str::parse`).

use super::Record;

/// `GOTO/x,y,z[,i,j,k]` with plain numbers, parsed without allocating: nearly every statement
/// of a large file. Anything else (or anything odd) goes to the general parser.
#[inline]
pub(crate) fn fast_goto(stmt: &[u8]) -> Option<Record> {
    let len = stmt.len();
    if len < 6 || !stmt[..4].eq_ignore_ascii_case(b"GOTO") {
        return None;
    }
    let slash = 4 + stmt[4..].iter().position(|c| !c.is_ascii_whitespace())?;
    if stmt[slash] != b'/' {
        return None;
    }
    let rest = &stmt[slash + 1..];
    // One pass over the arguments, each a sign, at most 15 digits and a point, spaces around.
    // Then the digits as an integer and 10^decimals are both exact doubles, and one IEEE division
    // rounds their quotient correctly (Clinger's fast path): the same double as the general
    // parser. Anything else (exponents, long mantissas, junk) goes to the general parser, which
    // also names what is wrong and where.
    let mut parts = [(0u64, 0usize, false); 6];
    let mut n = 0;
    let mut i = 0;
    loop {
        while i < rest.len() && rest[i].is_ascii_whitespace() {
            i += 1;
        }
        let neg = match rest.get(i) {
            Some(b'-') => {
                i += 1;
                true
            }
            Some(b'+') => {
                i += 1;
                false
            }
            _ => false,
        };
        let (mut m, mut digits, mut decimals) = (0u64, 0usize, 0usize);
        while let Some(&c) = rest.get(i)
            && c.is_ascii_digit()
        {
            m = m * 10 + (c - b'0') as u64;
            digits += 1;
            i += 1;
            if digits > 15 {
                return None; // beyond an exact double: the general parser rounds it
            }
        }
        if rest.get(i) == Some(&b'.') {
            i += 1;
            // Up to eight fraction digits at a time, off the one-digit dependency chain, while
            // eight bytes are left to load (the last few of a line go one by one below).
            while let Some(c) = rest.get(i..i + 8) {
                let w = u64::from_le_bytes([c[0], c[1], c[2], c[3], c[4], c[5], c[6], c[7]]);
                let k = leading_digits(w);
                if k == 0 {
                    break;
                }
                if digits + k > 15 {
                    return None;
                }
                m = m * POW10_U64[k] + digits_value(w, k);
                (digits, decimals, i) = (digits + k, decimals + k, i + k);
                if k < 8 {
                    break;
                }
            }
            while let Some(&c) = rest.get(i)
                && c.is_ascii_digit()
            {
                m = m * 10 + (c - b'0') as u64;
                (digits, decimals, i) = (digits + 1, decimals + 1, i + 1);
                if digits > 15 {
                    return None;
                }
            }
        }
        if digits == 0 || n == 6 {
            return None;
        }
        parts[n] = (m, decimals, neg);
        n += 1;
        while i < rest.len() && rest[i].is_ascii_whitespace() {
            i += 1;
        }
        match rest.get(i) {
            None => break,
            Some(b',') => i += 1,
            Some(_) => return None,
        }
    }
    // The divisions last: independent of each other, they overlap.
    let v = parts.map(|(m, decimals, neg)| {
        let x = m as f64 / POW10_EXACT[decimals];
        if neg { -x } else { x }
    });
    match n {
        3 => Some(Record::Goto {
            p: [v[0], v[1], v[2]],
            axis: None,
        }),
        // A zero axis goes to the general parser, which reports it with its column.
        6 if v[3] * v[3] + v[4] * v[4] + v[5] * v[5] >= 1e-24 => Some(Record::Goto {
            p: [v[0], v[1], v[2]],
            axis: Some([v[3], v[4], v[5]]),
        }),
        _ => None,
    }
}

const ZEROS: u64 = 0x3030_3030_3030_3030;

/// How many of the eight bytes of `w` (the first in the lowest byte) are ASCII digits before the
/// first that is not. A digit is 0x30..=0x39: high nibble 3, and adding 6 keeps it 3 (a carry out
/// of a byte ≥ 0xFA only reaches bytes after that non-digit).
#[inline]
pub(in crate::cl) fn leading_digits(w: u64) -> usize {
    const HIGH: u64 = 0xF0F0_F0F0_F0F0_F0F0;
    let bad = ((w & HIGH) ^ ZEROS) | ((w.wrapping_add(0x0606_0606_0606_0606) & HIGH) ^ ZEROS);
    (bad.trailing_zeros() / 8) as usize
}

/// The value of the first `k` (1..=8) bytes of `w`, ASCII digits: shifted to the top with '0's
/// below, which as leading zeros change nothing. The SWAR reduction of fast_float's
/// `parse_eight_digits`.
#[inline]
pub(in crate::cl) fn digits_value(w: u64, k: usize) -> u64 {
    let w = if k >= 8 {
        w
    } else {
        (w << (8 * (8 - k))) | (ZEROS >> (8 * k))
    };
    let mut v = w - ZEROS;
    v = v.wrapping_mul(10).wrapping_add(v >> 8);
    const MASK: u64 = 0x0000_00FF_0000_00FF;
    let v1 = (v & MASK).wrapping_mul(100 + (1_000_000 << 32));
    let v2 = ((v >> 16) & MASK).wrapping_mul(1 + (10_000 << 32));
    (v1.wrapping_add(v2) >> 32) as u32 as u64
}

/// 10^k for k ≤ 8.
const POW10_U64: [u64; 9] = [1, 10, 100, 1000, 10_000, 100_000, 1_000_000, 10_000_000, 100_000_000];

/// 10^k for k ≤ 15: each an exact double.
const POW10_EXACT: [f64; 16] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15,
];

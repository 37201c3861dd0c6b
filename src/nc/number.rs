//! Fixed-decimal number output without `format!`: round `v · 10^d` to an integer, write its
//! digits two at a time around the point (≈10 ns against ≈116 ns for `format!("{:.3}")`).
//!
//! The rounding rule is half away from zero (`f64::round`), not `{:.3}`'s half-to-even on the
//! binary value: 0.0005 → 0.001, −0.0005 → −0.001. Every replay (self-verification, `verify`)
//! rounds with the same rule.

/// `v` rounded to `dec` decimals, as an integer count of 10^-dec.
#[inline]
pub fn round_to(v: f64, dec: u32) -> i64 {
    let x = v * POW10[dec.min(6) as usize];
    let t = x.abs();
    if t.is_nan() {
        return 0;
    }
    if t >= 4.5e15 {
        // Beyond 2^52 every double is an integer already.
        return if t < 9.0e18 { x as i64 } else { 0 };
    }
    // `f64::round` by hand: a libm call on baseline x86-64, and this runs for every word.
    // `t - i` is exact below 2^52, so the half is judged on the value itself.
    let i = t as i64;
    let r = if t - i as f64 >= 0.5 { i + 1 } else { i };
    if x < 0.0 { -r } else { r }
}

/// `v` as written with `dec` decimals, read back.
#[inline]
pub fn rounded(v: f64, dec: u32) -> f64 {
    value(round_to(v, dec), dec)
}

/// What a word of `r` units of 10^-dec stands for.
#[inline]
pub fn value(r: i64, dec: u32) -> f64 {
    r as f64 / POW10[dec.min(6) as usize]
}

/// 10^d for the decimals a word can have.
pub const POW10: [f64; 7] = [1.0, 10.0, 100.0, 1000.0, 10000.0, 100000.0, 1000000.0];

/// Writes the integer `r` (in units of 10^-dec, `dec` ≤ 6 as everywhere here) as a decimal with
/// exactly `dec` places.
#[inline]
pub fn write_fixed(out: &mut String, r: i64, dec: u32) {
    let mut t = Ascii::new();
    t.fixed(r, dec);
    t.append_to(out);
}

/// One axis word: `letter`, a `+` before a value ≥ 0 when `plus` (conversational), the value as
/// [`write_fixed`] writes it, and a space: one append for the whole word. Always inlined: the
/// motion block's loop is the formatter's hot path, and with a second caller (a hole's X/Y) the
/// compiler stopped inlining it there, at ≈ 100 instructions a CL point.
#[inline(always)]
pub fn write_word(out: &mut String, letter: u8, plus: bool, r: i64, dec: u32) {
    assert!(letter.is_ascii(), "an NC word's address is ASCII");
    let mut t = Ascii::new();
    t.fixed(r, dec);
    if plus && r >= 0 {
        t.prepend(b'+');
    }
    t.prepend(letter);
    t.append(b' ');
    t.append_to(out);
}

/// Digit pairs "00" … "99": two digits per division (the divisions by constants are multiplies,
/// but each waits for the one before).
const PAIRS: &[u8; 200] = b"\
0001020304050607080910111213141516171819\
2021222324252627282930313233343536373839\
4041424344454647484950515253545556575859\
6061626364656667686970717273747576777879\
8081828384858687888990919293949596979899";

/// A word under construction, right to left, in a stack buffer that is only ever ASCII. It goes
/// into the line with one fixed-length copy, not a `memcpy` call and per-byte capacity checks:
/// writing words is the largest single cost of a block (≈90 instructions a word this way, ≈125
/// with itoa and per-character pushes).
struct Ascii {
    /// `buf[start..end]` is the word; `end + TAIL ≤ buf.len()`, the copy's fixed length.
    buf: [u8; 64],
    start: usize,
    end: usize,
}

/// Bytes copied per append: the longest word (letter, sign, 20 digits, point, space) and more.
const TAIL: usize = 32;
/// Where a word's number ends, with room for a suffix after it.
const MID: usize = 28;

impl Ascii {
    #[inline(always)]
    fn new() -> Ascii {
        Ascii {
            buf: [b' '; 64],
            start: MID,
            end: MID,
        }
    }

    #[inline(always)]
    fn prepend(&mut self, b: u8) {
        self.start -= 1;
        self.buf[self.start] = b;
    }

    /// The two digits of `n` (< 100).
    #[inline(always)]
    fn pair(&mut self, n: u64) {
        let p = n as usize * 2;
        self.start -= 2;
        self.buf[self.start..self.start + 2].copy_from_slice(&PAIRS[p..p + 2]);
    }

    #[inline(always)]
    fn append(&mut self, b: u8) {
        self.buf[self.end] = b;
        self.end += 1;
    }

    /// `n` as exactly `digits` digits, zero-padded (`n < 10^digits`).
    #[inline(always)]
    fn digits(&mut self, mut n: u64, mut digits: u32) {
        while digits >= 2 {
            self.pair(n % 100);
            n /= 100;
            digits -= 2;
        }
        if digits == 1 {
            self.prepend(b'0' + n as u8);
        }
    }

    /// `n` with as many digits as it has (at least one).
    #[inline(always)]
    fn whole(&mut self, mut n: u64) {
        while n >= 100 {
            self.pair(n % 100);
            n /= 100;
        }
        if n >= 10 {
            self.pair(n);
        } else {
            self.prepend(b'0' + n as u8);
        }
    }

    #[inline(always)]
    fn fixed(&mut self, r: i64, dec: u32) {
        let a = r.unsigned_abs();
        // Constant divisors, so that each is a multiply.
        let (int, frac) = match dec {
            0 => (a, 0),
            1 => (a / 10, a % 10),
            2 => (a / 100, a % 100),
            3 => (a / 1000, a % 1000),
            4 => (a / 10_000, a % 10_000),
            5 => (a / 100_000, a % 100_000),
            _ => (a / 1_000_000, a % 1_000_000),
        };
        if dec > 0 {
            self.digits(frac, dec.min(6));
            self.prepend(b'.');
        }
        self.whole(int);
        if r < 0 {
            self.prepend(b'-');
        }
    }

    #[inline(always)]
    fn append_to(&self, out: &mut String) {
        let n = self.end - self.start;
        let src: &[u8; TAIL] = self.buf[self.start..self.start + TAIL].try_into().unwrap();
        debug_assert!(src.is_ascii());
        // SAFETY: every byte of `buf` is ASCII (spaces, digits, '.', '+', '-' and an ASCII
        // letter), so the string stays UTF-8 whatever of it is kept; `reserve` makes room for
        // `TAIL` bytes past the length, all of which the copy initialises before `set_len`
        // keeps `n ≤ TAIL` of them.
        unsafe {
            let v = out.as_mut_vec();
            v.reserve(TAIL);
            let len = v.len();
            std::ptr::copy_nonoverlapping(src.as_ptr(), v.as_mut_ptr().add(len), TAIL);
            v.set_len(len + n);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn f(v: f64, d: u32) -> String {
        let mut s = String::new();
        write_fixed(&mut s, round_to(v, d), d);
        s
    }

    proptest::proptest! {
        #[test]
        fn fixed_words_are_the_integer_with_a_point(r in proptest::num::i64::ANY, dec in 0u32..=6) {
            let p = 10u64.pow(dec);
            let a = r.unsigned_abs();
            let want = match dec {
                0 => format!("{}{a}", if r < 0 { "-" } else { "" }),
                d => format!("{}{}.{:0w$}", if r < 0 { "-" } else { "" }, a / p, a % p, w = d as usize),
            };
            let mut got = String::from("X");
            write_fixed(&mut got, r, dec);
            proptest::prop_assert_eq!(&got[1..], want.as_str());
            // A whole word, after whatever the line holds (its capacity often exactly full).
            for plus in [false, true] {
                let mut line = String::from("N5 ");
                line.shrink_to_fit();
                write_word(&mut line, b'B', plus, r, dec);
                let sign = if plus && r >= 0 { "+" } else { "" };
                proptest::prop_assert_eq!(line, format!("N5 B{sign}{want} "));
            }
        }
    }

    #[test]
    fn fixed_decimals_round_half_away_from_zero() {
        assert_eq!(f(1.2345, 3), "1.235");
        assert_eq!(f(-1.2345, 3), "-1.235");
        assert_eq!(f(0.0004, 3), "0.000");
        assert_eq!(f(-0.0004, 3), "0.000");
        assert_eq!(f(-0.0006, 3), "-0.001");
        assert_eq!(f(0.5, 0), "1");
        assert_eq!(f(123456.7, 4), "123456.7000");
        assert_eq!(f(-0.05, 4), "-0.0500");
        assert_eq!(f(f64::NAN, 3), "0.000");
        // The same rule as `f64::round` everywhere, halves and near-halves included.
        for v in [
            0.49999999999999994,
            0.5,
            1.5,
            2.5,
            -2.5,
            1234.5,
            4.4999999999999996e15,
            1e17,
            -7.5e15,
        ] {
            assert_eq!(round_to(v, 0), v.round() as i64, "{v}");
        }
        let mut x = 0.123456789f64;
        for _ in 0..10_000 {
            x = (x * 7919.0 + 0.2718).fract() * 2e6 - 1e6;
            for d in 0..7 {
                assert_eq!(round_to(x, d), (x * POW10[d as usize]).round() as i64, "{x} {d}");
            }
        }
    }
}

/// Rewrites the numbers of a written line's address words as a dialect without trailing zeros
/// (`X1.5`, `X1.`) or leading zeros (`X.5`, `X-.5`) wants them. Comments (from `open` on) and
/// words without a decimal point (`N10`, `M3`, `G1`) stay as they are; so do G and M codes with
/// one (`G43.4`).
pub fn restyle(line: &str, open: &str, trailing: bool, leading: bool) -> String {
    let (code, comment) = match line.find(open).filter(|_| !open.is_empty()) {
        Some(i) => line.split_at(i),
        None => (line, ""),
    };
    let mut out = String::with_capacity(line.len());
    for (k, token) in code.split(' ').enumerate() {
        if k > 0 {
            out.push(' ');
        }
        out.push_str(&restyle_word(token, trailing, leading));
    }
    out.push_str(comment);
    out
}

fn restyle_word(token: &str, trailing: bool, leading: bool) -> std::borrow::Cow<'_, str> {
    let mut chars = token.chars();
    let Some(address) = chars.next().filter(|c| c.is_ascii_uppercase() && !matches!(c, 'G' | 'M' | 'N' | 'O' | 'T' | 'H' | 'D')) else {
        return token.into();
    };
    let rest = chars.as_str();
    let (sign, digits) = match rest.strip_prefix(['+', '-']) {
        Some(d) => (&rest[..1], d),
        None => ("", rest),
    };
    let Some((int, frac)) = digits.split_once('.') else { return token.into() };
    if !int.bytes().all(|b| b.is_ascii_digit()) || !frac.bytes().all(|b| b.is_ascii_digit()) || int.is_empty() {
        return token.into();
    }
    let frac = if trailing { frac } else { frac.trim_end_matches('0') };
    let int = if !leading && int == "0" { "" } else { int };
    format!("{address}{sign}{int}.{frac}").into()
}

//! Exact, fast parsing of the plain decimal cells CSV point clouds are made
//! of (`-49.23719`, `17`, `0.5`), to exactly what `str::parse::<f32>` gives.
//!
//! Hand-written because it is the whole cost of reading a CSV scan, and a
//! general parser (std's or `fast-float2`) spends most of its time on cases
//! point clouds never have. Anything this module does not handle (exponents,
//! `inf`, more than 19 digits, halfway cases) is declined with `None` and the
//! caller hands the cell to the standard library.
//!
//! Two readers give the same answers: a byte loop, and one that classifies
//! and sums eight digits at a time inside a `u64` (SWAR). The second runs a
//! fixed handful of steps per number instead of a branch per byte, and no
//! branch of it depends on how many digits a number has; it needs 26 readable bytes
//! from the number's start (the rest of the row and the rows after it), so a
//! cell near the end of the buffer takes the byte loop.
//!
//! For example, `fast_f32_prefix(b"-49.25,7\n…")` gives `(-49.25, 6)`: the
//! value and how many bytes the number took, so the caller goes on at the
//! comma. The tests below check both readers against `str::parse` and each
//! other on every prefix of random cells.

/// Powers of ten that are exact in `f64`.
const POW10: [f64; 23] = [
    1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10, 1e11, 1e12, 1e13, 1e14, 1e15, 1e16,
    1e17, 1e18, 1e19, 1e20, 1e21, 1e22,
];

/// Powers of ten exact in `f32` (5^10 < 2^24).
const POW10_F32: [f32; 11] = [1e0, 1e1, 1e2, 1e3, 1e4, 1e5, 1e6, 1e7, 1e8, 1e9, 1e10];

/// Powers of ten as integers, for joining digit groups.
const POW10_U64: [u64; 9] = [
    1,
    10,
    100,
    1_000,
    10_000,
    100_000,
    1_000_000,
    10_000_000,
    100_000_000,
];

/// Bytes the SWAR reader may look at from a number's start: a sign, 8
/// integer bytes, a dot and 16 fraction bytes.
const SWAR_READ: usize = 1 + 8 + 1 + 16;

/// Parses a plain decimal cell (`[+-]digits[.digits]`, at most 19 digits) to
/// exactly what `str::parse::<f32>` gives, or `None` for anything else
/// (which the caller hands to the standard library).
///
/// Why it is exact: the digits form an integer `m`. When `m < 2⁵³` and
/// `d ≤ 22`, `m` and `10^d` are exact in `f64`, so `m / 10^d` is the
/// correctly rounded `f64` of the decimal (Clinger's fast path); rounding
/// that to `f32` gives the correctly rounded `f32` unless the `f64` lies
/// exactly halfway between two `f32`s (then the decimal may lie on either
/// side). In that case, when `m < 2²⁴` and `d ≤ 10`, the same argument in
/// `f32` settles it with one `f32` division; otherwise it returns `None`. Values here are zero or far inside the `f32` normal range
/// (1e-22 ≤ |v| < 1e19), where halfway points are the `f64`s whose low 29
/// mantissa bits are `1 << 28`.
#[inline]
pub(crate) fn fast_f32(cell: &[u8]) -> Option<f32> {
    match fast_f32_prefix(cell) {
        Some((v, len)) if len == cell.len() => Some(v),
        _ => None,
    }
}

/// [`fast_f32`] of the longest prefix of `bytes` made of a sign, digits and
/// one dot: the value and the prefix length.
#[inline(always)]
pub(crate) fn fast_f32_prefix(bytes: &[u8]) -> Option<(f32, usize)> {
    if bytes.len() >= SWAR_READ {
        swar_prefix(bytes)
    } else {
        scalar_prefix(bytes)
    }
}

/// The sign of a number: whether it is negative, and how many bytes it
/// takes.
#[inline(always)]
fn sign(bytes: &[u8]) -> (bool, usize) {
    match bytes.first() {
        Some(b'-') => (true, 1),
        Some(b'+') => (false, 1),
        _ => (false, 0),
    }
}

/// The value of `m / 10^decimals` (with its sign) as `str::parse::<f32>`
/// would give it, or `None` (see [`fast_f32`]).
///
/// The `f64` division comes first for every cell: choosing between it and
/// the `f32` one by the size of `m` is a branch a random mix of 7- and
/// 8-digit cells mispredicts half the time. The `f32` division only settles
/// the halfway cases it can (both give the correctly rounded `f32` when
/// they apply, so the result does not depend on the order).
#[inline(always)]
fn to_f32(neg: bool, m: u64, decimals: usize) -> Option<f32> {
    if m >= 1 << 53 || decimals >= POW10.len() {
        return None;
    }
    let r = m as f64 / POW10[decimals];
    let f = if r.to_bits() & 0x1FFF_FFFF != 0x1000_0000 {
        r as f32
    } else if m < 1 << 24 && decimals < POW10_F32.len() {
        m as f32 / POW10_F32[decimals]
    } else {
        return None;
    };
    Some(if neg { -f } else { f })
}

/// The byte-loop reader of [`fast_f32_prefix`].
#[inline(always)]
fn scalar_prefix(bytes: &[u8]) -> Option<(f32, usize)> {
    let (neg, start) = sign(bytes);
    let mut m = 0u64;
    let mut nd = 0u32;
    let mut decimals = 0usize;
    let mut dot = false;
    let mut p = start;
    while p < bytes.len() {
        let b = bytes[p];
        let d = b.wrapping_sub(b'0');
        if d < 10 {
            // Past 19 digits `m` could overflow: leave such cells to std.
            if nd >= 19 {
                return None;
            }
            m = m * 10 + u64::from(d);
            nd += 1;
            decimals += usize::from(dot);
        } else if b == b'.' && !dot {
            dot = true;
        } else {
            break;
        }
        p += 1;
    }
    if nd == 0 {
        return None;
    }
    Some((to_f32(neg, m, decimals)?, p))
}

/// Eight bytes of `bytes` from `at`, first byte lowest.
#[inline(always)]
fn load8(bytes: &[u8], at: usize) -> u64 {
    let mut w = [0u8; 8];
    w.copy_from_slice(&bytes[at..at + 8]);
    u64::from_le_bytes(w)
}

/// How many of the eight bytes of `w` (first byte lowest) are ASCII digits
/// before the first byte that is not (8 when all are).
///
/// Per byte, `t = b ^ b'0'` is the digit's value for a digit and ≥ 10 for
/// anything else; `(t & 0x7F) + 0x76` sets the byte's top bit exactly when
/// its low seven bits are ≥ 10, and cannot carry into the next byte.
#[inline(always)]
fn leading_digits(w: u64) -> usize {
    const LOW7: u64 = 0x7F7F_7F7F_7F7F_7F7F;
    const TOP: u64 = 0x8080_8080_8080_8080;
    let t = w ^ 0x3030_3030_3030_3030;
    let not_digit = (((t & LOW7) + 0x7676_7676_7676_7676) | t) & TOP;
    (not_digit.trailing_zeros() / 8) as usize
}

/// The value of the first `n` (0..=8) bytes of `w` (first byte lowest),
/// which are digits: the digits are moved to the top of the word (zeros in
/// front) and summed pairwise in three multiplications.
#[inline(always)]
fn digits_value(w: u64, n: usize) -> u64 {
    if n == 0 {
        return 0;
    }
    let v = (w & 0x0F0F_0F0F_0F0F_0F0F) << (8 * (8 - n));
    let v = (v.wrapping_mul(10) + (v >> 8)) & 0x00FF_00FF_00FF_00FF;
    let v = (v.wrapping_mul(100) + (v >> 16)) & 0x0000_FFFF_0000_FFFF;
    v.wrapping_mul(10_000).wrapping_add(v >> 32) & 0xFFFF_FFFF
}

/// The SWAR reader of [`fast_f32_prefix`]; `bytes` holds at least
/// [`SWAR_READ`] bytes. Gives exactly what [`scalar_prefix`] gives.
#[inline(always)]
fn swar_prefix(bytes: &[u8]) -> Option<(f32, usize)> {
    let (neg, start) = sign(bytes);
    let w = load8(bytes, start);
    let a = leading_digits(w);
    if a == 8 {
        // Eight or more integer digits: rare in a point cloud.
        return scalar_prefix(bytes);
    }
    let mut m;
    let mut p = start + a;
    let mut decimals = 0usize;
    if bytes[p] == b'.' {
        p += 1;
        let wf = load8(bytes, p);
        let b = leading_digits(wf);
        m = if a + b <= 8 {
            // The common cell: the integer digits (a ≤ 7) with the fraction
            // digits after them make one word, summed once.
            digits_value((w & ((1 << (8 * a)) - 1)) | (wf << (8 * a)), a + b)
        } else {
            digits_value(w, a) * POW10_U64[b] + digits_value(wf, b)
        };
        p += b;
        decimals = b;
        if b == 8 {
            let w = load8(bytes, p);
            let c = leading_digits(w);
            if c == 8 || a + 8 + c > 19 {
                return scalar_prefix(bytes);
            }
            m = m * POW10_U64[c] + digits_value(w, c);
            p += c;
            decimals += c;
        }
        if a + decimals == 0 {
            return None;
        }
    } else if a == 0 {
        return None;
    } else {
        m = digits_value(w, a);
    }
    Some((to_f32(neg, m, decimals)?, p))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn xorshift(s: &mut u64) -> u64 {
        *s ^= *s << 13;
        *s ^= *s >> 7;
        *s ^= *s << 17;
        *s
    }

    #[test]
    fn swar_helpers_count_and_sum_digits() {
        for text in [
            "", "7", "12", "0012345", "98765432", "1234567x", "5.5", "-1",
        ] {
            let mut b = [b'x'; 8];
            b[..text.len()].copy_from_slice(text.as_bytes());
            let w = u64::from_le_bytes(b);
            let n = text.bytes().take_while(u8::is_ascii_digit).count();
            assert_eq!(leading_digits(w), n, "{text:?}");
            let want: u64 = text[..n].parse().unwrap_or(0);
            assert_eq!(digits_value(w, n), want, "{text:?}");
        }
        // Every byte value right after a digit stops the count there.
        for b in 0..=255u8 {
            let w = u64::from_le_bytes([b'4', b, b'1', b'1', b'1', b'1', b'1', b'1']);
            let want = if b.is_ascii_digit() { 8 } else { 1 };
            assert_eq!(leading_digits(w), want, "byte {b:#x}");
        }
    }

    #[test]
    fn swar_and_byte_loop_readers_agree_on_every_prefix() {
        let mut s = 0x2545_F491_4F6C_DD1Du64;
        let alphabet = b"0123456789012345678901234567890123456789..--+,\n\re x";
        for _ in 0..400_000 {
            let len = (xorshift(&mut s) % 30) as usize;
            let mut b: Vec<u8> = (0..len)
                .map(|_| alphabet[(xorshift(&mut s) % alphabet.len() as u64) as usize])
                .collect();
            // Padding so that the SWAR reader can run on every prefix.
            b.extend_from_slice(&[b','; SWAR_READ]);
            let want = scalar_prefix(&b).map(|(v, n)| (v.to_bits(), n));
            let got = swar_prefix(&b).map(|(v, n)| (v.to_bits(), n));
            assert_eq!(got, want, "{:?}", String::from_utf8_lossy(&b[..len]));
        }
    }
}

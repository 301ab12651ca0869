//! Fixed-point decimal formatting and parsing of `f32` without core's float machinery.
//!
//! `core::fmt`'s float formatting (Grisu/Dragon) and `str::parse::<f32>` each pull several
//! kilobytes into the firmware. Protocol values (temperatures, powers, radii) need only a
//! fixed number of decimals, which integer arithmetic on the float's bits does exactly.
//!
//! In the same spirit, two helpers the firmware's text and time share: [`ascii_str`] (the
//! protocol's printable-ASCII lines as text, without core's UTF-8 validator) and
//! [`div_rem_small`] (a `u64` divided by a small number with 32-bit divides, without the
//! software `u64` division).

use core::fmt;
use core::num::{NonZeroU16, NonZeroU32};

const TEN: NonZeroU16 = NonZeroU16::new(10).unwrap();

/// Most decimals [`Fixed`] prints; more are clamped. An `f32` carries about 7 significant
/// digits, so a 10th decimal would only ever show binary noise, and 9 keeps the scaled value
/// (≤ 1e9 · 1e9) inside a `u64`.
pub const MAX_DECIMALS: u8 = 9;

/// Largest magnitude [`Fixed`] prints; beyond it the output saturates to ±this value.
/// Nothing the link measures comes near it (temperatures < 1e3, counts < 1e7), so a saturated
/// number is clearly "absurd" to a reader yet keeps the line short and machine-parsable.
pub const SATURATION: f32 = 1e9;

/// Longest text [`parse_decimal`] accepts, in characters: enough for `-123456.78901` style
/// values minus one digit, and short enough that the digits fit a `u64` exactly.
pub const MAX_DECIMAL_LEN: usize = 12;

/// An `f32` printed with a fixed number of decimals: `Fixed(value, decimals)`.
///
/// Rounds the exact binary value half away from zero (`Fixed(0.125, 2)` prints `0.13`);
/// prints no sign for values that round to zero; `nan`, `inf`, `-inf` for non-finite values;
/// magnitudes beyond [`SATURATION`] print as ±[`SATURATION`]; decimals are capped at
/// [`MAX_DECIMALS`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fixed(pub f32, pub u8);

impl Fixed {
    /// `x` to two decimals, rounded up (within 0.01 of it): a least value printed so that the
    /// printed number is itself taken (`RANGE`'s min, a budget's least).
    pub fn up2(x: f32) -> Fixed {
        Fixed(x + 0.00499, 2)
    }

    /// `x` to two decimals, rounded down: a most value printed so that the printed number is
    /// itself taken (`RANGE`'s max).
    pub fn down2(x: f32) -> Fixed {
        Fixed(x - 0.00499, 2)
    }
}

impl fmt::Display for Fixed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let Fixed(value, decimals) = *self;
        if value.is_nan() {
            return f.write_str("nan");
        }
        if value.is_infinite() {
            return f.write_str(if value > 0.0 { "inf" } else { "-inf" });
        }
        let decimals = decimals.min(MAX_DECIMALS);
        let negative = value.is_sign_negative();
        let magnitude = if value.abs() > SATURATION {
            SATURATION
        } else {
            value.abs()
        };
        let scaled = scaled_rounded(magnitude, decimals);
        let mut buf = [0u8; 24];
        let len = write_digits(&mut buf, scaled, decimals, negative && scaled != 0);
        // Only ASCII digits, '-' and '.' were written.
        f.write_str(ascii_str(&buf[..len]).ok_or(fmt::Error)?)
    }
}

/// `round(magnitude · 10^decimals)` half away from zero, exactly, for finite
/// 0 ≤ magnitude ≤ [`SATURATION`] and decimals ≤ [`MAX_DECIMALS`].
fn scaled_rounded(magnitude: f32, decimals: u8) -> u64 {
    let bits = magnitude.to_bits();
    let raw_exp = ((bits >> 23) & 0xff) as i32;
    let frac = (bits & 0x007f_ffff) as u64;
    // magnitude = mant · 2^exp exactly.
    let (mant, exp) = if raw_exp == 0 {
        (frac, -149)
    } else {
        (frac | 0x0080_0000, raw_exp - 150)
    };
    // mant < 2^24 and 10^9 < 2^30: the product fits easily; with exp ≥ 0 the value is ≤ 1e9 so
    // the shifted product stays ≤ 1e18 < 2^64.
    let n = mant * 10u64.pow(decimals as u32);
    if exp >= 0 {
        n << exp
    } else {
        let shift = (-exp) as u32;
        if shift >= 64 {
            return 0; // n < 2^54, so n / 2^64 < 1/2 rounds to 0
        }
        let q = n >> shift;
        let rem = n & ((1u64 << shift) - 1);
        // rem ≥ half of 2^shift rounds up (half away from zero on the magnitude).
        if rem >= 1u64 << (shift - 1) {
            q + 1
        } else {
            q
        }
    }
}

/// `bytes` as text if every one is printable ASCII or a tab, as the protocol's lines are (a NUL
/// or another control byte in a line is no command's); else `None`.
pub fn ascii_str(bytes: &[u8]) -> Option<&str> {
    if !bytes
        .iter()
        .all(|&b| b == b'\t' || (b' '..=b'~').contains(&b))
    {
        return None;
    }
    // SAFETY: a sequence of ASCII bytes is valid UTF-8. Not `core::str::from_utf8`: its
    // validator is 368 B of flash, which the hardware budget has no room for.
    Some(unsafe { core::str::from_utf8_unchecked(bytes) })
}

/// `v / d` and `v % d` for a divisor under 2^16, by long division in 16-bit digits with the
/// Cortex-M4's 32-bit divide: a `u64` division is a software routine of about 1 KiB of flash
/// there, which nothing else in the firmware then needs.
pub fn div_rem_small(v: u64, d: NonZeroU16) -> (u64, u32) {
    let d = NonZeroU32::from(d);
    let hi = (v >> 32) as u32;
    let (q_hi, r) = (hi / d, hi % d);
    // Each partial dividend is under d · 2^16 < 2^32, and each partial quotient under 2^16.
    let mid = (r << 16) | ((v as u32) >> 16);
    let (q_mid, r) = (mid / d, mid % d);
    let low = (r << 16) | (v as u32 & 0xffff);
    let (q_low, r) = (low / d, low % d);
    (
        (u64::from(q_hi) << 32) | u64::from((q_mid << 16) | q_low),
        r,
    )
}

/// Writes `[-]int.frac` of `scaled / 10^decimals` into `buf`, returns the length.
fn write_digits(buf: &mut [u8; 24], scaled: u64, decimals: u8, negative: bool) -> usize {
    // Digits least significant first into a scratch buffer, then reverse into `buf`.
    let mut rev = [0u8; 24];
    let mut n = 0;
    let mut v = scaled;
    let min_digits = decimals as usize + 1; // at least "0" before the point
    while v > 0 || n < min_digits {
        let (q, r) = div_rem_small(v, TEN);
        rev[n] = b'0' + r as u8;
        v = q;
        n += 1;
    }
    let mut len = 0;
    if negative {
        buf[len] = b'-';
        len += 1;
    }
    for i in (0..n).rev() {
        buf[len] = rev[i];
        len += 1;
        if i == decimals as usize && decimals > 0 {
            buf[len] = b'.';
            len += 1;
        }
    }
    len
}

/// Parses a plain decimal number: optional `+`/`-`, digits, optional single `.` with digits,
/// at least one digit, at most [`MAX_DECIMAL_LEN`] characters. Rejects everything else
/// (empty, `inf`, `nan`, exponents, spaces, several dots) with `None`.
///
/// Accurate to about one `f32` ulp: the digits are accumulated exactly as an integer, converted
/// once, then divided by an exact power of ten.
pub fn parse_decimal(s: &str) -> Option<f32> {
    let bytes = s.as_bytes();
    if bytes.is_empty() || bytes.len() > MAX_DECIMAL_LEN {
        return None;
    }
    let (negative, body) = match bytes[0] {
        b'-' => (true, &bytes[1..]),
        b'+' => (false, &bytes[1..]),
        _ => (false, bytes),
    };
    let mut digits: u64 = 0;
    let mut n_digits = 0u32;
    let mut frac_digits = 0u32;
    let mut seen_dot = false;
    for &b in body {
        match b {
            b'0'..=b'9' => {
                // ≤ 12 digits < 10^12: no overflow.
                digits = digits * 10 + (b - b'0') as u64;
                n_digits += 1;
                if seen_dot {
                    frac_digits += 1;
                }
            }
            b'.' if !seen_dot => seen_dot = true,
            _ => return None,
        }
    }
    if n_digits == 0 {
        return None;
    }
    let mut value = digits as f32;
    // 10^10 = 2^10 · 5^10 with 5^10 < 2^24 is exact in f32; split larger divisors.
    let mut remaining = frac_digits;
    while remaining > 0 {
        let step = remaining.min(10);
        value /= 10u64.pow(step) as f32;
        remaining -= step;
    }
    Some(if negative { -value } else { value })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::string::{String, ToString};

    fn show(v: f32, d: u8) -> String {
        Fixed(v, d).to_string()
    }

    #[test]
    fn formats_basic_values() {
        assert_eq!(show(0.0, 0), "0");
        assert_eq!(show(0.0, 2), "0.00");
        assert_eq!(show(1.5, 0), "2");
        assert_eq!(show(-1.5, 0), "-2");
        assert_eq!(show(2.5, 0), "3");
        assert_eq!(show(0.125, 2), "0.13"); // exact half rounds away from zero
        assert_eq!(show(-0.125, 2), "-0.13");
        assert_eq!(show(38.0, 1), "38.0");
        assert_eq!(show(-12.345, 2), "-12.35"); // -12.345f32 is -12.3450002...
        assert_eq!(show(2.675, 2), "2.67"); // 2.675f32 is 2.67499995...
        assert_eq!(show(123_456.79, 2), "123456.79");
        assert_eq!(show(0.05, 1), "0.1");
        assert_eq!(show(1e-3, 9), "0.001000000");
    }

    #[test]
    fn no_negative_zero() {
        assert_eq!(show(-0.0, 1), "0.0");
        assert_eq!(show(-0.004, 2), "0.00");
        assert_eq!(show(-0.005, 2), "0.00"); // -0.005f32 is -0.00499999989
        assert_eq!(show(-0.0051, 2), "-0.01");
        assert_eq!(show(-f32::from_bits(1), 3), "0.000");
    }

    #[test]
    fn non_finite_and_saturation() {
        assert_eq!(show(f32::NAN, 2), "nan");
        assert_eq!(show(f32::INFINITY, 2), "inf");
        assert_eq!(show(f32::NEG_INFINITY, 0), "-inf");
        assert_eq!(show(1e9, 0), "1000000000");
        assert_eq!(show(3e12, 1), "1000000000.0");
        assert_eq!(show(-f32::MAX, 2), "-1000000000.00");
    }

    #[test]
    fn decimals_are_capped() {
        assert_eq!(show(0.5, 200), "0.500000000");
        assert_eq!(show(-1e9, 255), "-1000000000.000000000");
    }

    #[test]
    fn parses_accepted_forms() {
        assert_eq!(parse_decimal("38"), Some(38.0));
        assert_eq!(parse_decimal("+38"), Some(38.0));
        assert_eq!(parse_decimal("-4.5"), Some(-4.5));
        assert_eq!(parse_decimal(".5"), Some(0.5));
        assert_eq!(parse_decimal("5."), Some(5.0));
        assert_eq!(parse_decimal("0.1"), Some(0.1));
        assert_eq!(parse_decimal("999999999999"), Some(999_999_999_999.0));
        assert_eq!(parse_decimal(".12345678901"), Some(0.123_456_79));
        assert_eq!(parse_decimal("-0"), Some(-0.0));
    }

    #[test]
    fn rejects_everything_else() {
        for bad in [
            "",
            "-",
            "+",
            ".",
            "-.",
            "inf",
            "nan",
            "NaN",
            "-inf",
            "1e3",
            "1E3",
            "1.2.3",
            "1..2",
            " 1",
            "1 ",
            "--1",
            "+-1",
            "1-",
            "0x10",
            "1,5",
            "１",
            "1234567890123",
            "½",
        ] {
            assert_eq!(parse_decimal(bad), None, "{bad:?}");
        }
    }

    proptest! {
        #[test]
        fn ascii_str_is_the_text_of_printable_ascii_and_nothing_else(
            bytes in proptest::collection::vec(any::<u8>(), 0..80)
        ) {
            let printable = bytes.iter().all(|&b| b == b'\t' || (0x20..0x7f).contains(&b));
            let want = printable.then(|| core::str::from_utf8(&bytes).unwrap());
            prop_assert_eq!(ascii_str(&bytes), want);
        }

        #[test]
        fn small_divisions_match_the_u64_ones(v in any::<u64>(), d in 1u16..) {
            let n = NonZeroU16::new(d).unwrap();
            prop_assert_eq!(div_rem_small(v, n), (v / u64::from(d), (v % u64::from(d)) as u32));
        }

        #[test]
        fn format_parse_round_trip(v in -1e6f32..1e6, d in 0u8..=4) {
            let text = show(v, d);
            let back = parse_decimal(&text);
            prop_assert!(back.is_some(), "{text}");
            let back = back.unwrap_or(f32::NAN);
            // Formatting rounds to half a unit of the last decimal; parsing adds ~1 ulp of v.
            let tol = 0.5 * 10f64.powi(-(d as i32)) + 2.0 * (v.abs() as f64) * f32::EPSILON as f64;
            prop_assert!(((back as f64) - (v as f64)).abs() <= tol, "{v} -> {text} -> {back}");
        }

        #[test]
        fn formatting_matches_std_rounding_of_exact_value(v in -1e6f32..1e6, d in 0u8..=6) {
            // std formats the exact binary value with round-half-even; ties are impossible to
            // hit randomly except at exact binary fractions, so compare away from ties.
            let exact = v as f64 * 10f64.powi(d as i32);
            prop_assume!((exact.abs().fract() - 0.5).abs() > 1e-6);
            let ours = show(v, d);
            let theirs = format!("{:.*}", d as usize, v);
            let theirs = theirs.strip_prefix('-').filter(|t| t.bytes().all(|b| b == b'0' || b == b'.'))
                .map(|t| t.to_string()).unwrap_or(theirs);
            prop_assert_eq!(ours, theirs);
        }

        #[test]
        fn parse_never_panics(s in "\\PC{0,16}") {
            let _ = parse_decimal(&s);
        }

        #[test]
        fn parse_matches_std_on_valid_input(s in "[+-]?[0-9]{0,6}(\\.[0-9]{0,5})?") {
            let ours = parse_decimal(&s);
            let has_digit = s.bytes().any(|b| b.is_ascii_digit());
            prop_assert_eq!(ours.is_some(), has_digit && s.len() <= MAX_DECIMAL_LEN);
            if let (Some(ours), Ok(theirs)) = (ours, s.parse::<f64>()) {
                prop_assert!(((ours as f64) - theirs).abs() <= theirs.abs() * 1.5 * f32::EPSILON as f64);
            }
        }
    }
}

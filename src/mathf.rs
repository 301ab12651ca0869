//! Accurate `f32` natural logarithm and exponential for `no_std`.
//!
//! `core` has no `ln`/`exp` for floats, and the thermistor conversion needs both to well below
//! the 0.1 °C resolution we report. micromath's `F32Ext::ln` is a 4th-order polynomial built for
//! speed and, for x < 1, goes through an approximate reciprocal. Measured on the host over
//! x in [1e-6, 1e9] (test `micromath_ln_is_worse`):
//!
//! | | max relative error | max absolute error |
//! |---|---|---|
//! | micromath `ln` | 5.1e2 (near x = 1), 0.74 where \|ln x\| > 0.1 | 0.118 (x ≈ 5.7e-6); 0.077 at x = 0.9 |
//! | [`ln`] here | 2.0e-7 | 1.0e-6 |
//!
//! An error of 0.077 in ln(R/R25) is about 3.5 °C of thermistor error near room temperature
//! (dT = T² · d(ln R) / β), far beyond our budget; ours contributes < 0.001 °C. [`exp`] is
//! measured at 1.0e-7 max relative error on [-80, 80]. Both cost a few hundred bytes of flash.
//!
//! Both functions handle the IEEE special values like `std`: `ln(0) = -inf`, `ln(x < 0) = NaN`,
//! `exp(-inf) = 0`, overflow to `inf`, NaN in → NaN out.

/// ln 2 split for Cody–Waite range reduction: the high part has only 15 significant bits so
/// `k * LN2_HI` is exact for every |k| < 256 we use; the low part carries the rest.
const LN2_HI: f32 = f32::from_bits(0x3f31_7200); // 0.693_145_751_953_125
/// Low part of ln 2: `ln 2 - LN2_HI`.
const LN2_LO: f32 = 1.428_606_8e-6;
/// 1 / ln 2, to pick the power of two in [`exp`].
const INV_LN2: f32 = core::f32::consts::LOG2_E;
/// Above this `exp` overflows `f32` (ln(f32::MAX) ≈ 88.7228).
const EXP_OVERFLOW_X: f32 = 88.722_84;
/// Below this `exp` underflows to 0 even as a subnormal (ln(2^-150) ≈ -103.97).
const EXP_UNDERFLOW_X: f32 = -103.972_08;

/// Natural logarithm of `x` (dimensionless), relative error below 1e-7 on normal inputs.
///
/// Method: `x = m · 2^e` with `m` in [√½, √2) taken from the bits, then
/// `ln x = e·ln 2 + 2·atanh(s)` with `s = (m − 1)/(m + 1)`, |s| ≤ 0.172, summed to s¹¹
/// (truncation < 2e-10 relative).
pub fn ln(x: f32) -> f32 {
    if x.is_nan() || x < 0.0 {
        return f32::NAN;
    }
    if x == 0.0 {
        return f32::NEG_INFINITY;
    }
    if x == f32::INFINITY {
        return f32::INFINITY;
    }
    let mut bits = x.to_bits();
    let mut e: i32 = 0;
    if bits < 0x0080_0000 {
        // Subnormal: scale by 2^25 to make it normal, remember the shift.
        bits = (x * 33_554_432.0).to_bits();
        e -= 25;
    }
    e += ((bits >> 23) & 0xff) as i32 - 127;
    // Mantissa in [1, 2), then fold to [√½, √2) so |s| stays small.
    let mut m = f32::from_bits((bits & 0x007f_ffff) | 0x3f80_0000);
    if m > core::f32::consts::SQRT_2 {
        m *= 0.5;
        e += 1;
    }
    let s = (m - 1.0) / (m + 1.0);
    let s2 = s * s;
    // 2·atanh(s) = 2s·(1 + s²/3 + s⁴/5 + …), Horner in s².
    let series = 1.0
        + s2 * (1.0 / 3.0
            + s2 * (1.0 / 5.0 + s2 * (1.0 / 7.0 + s2 * (1.0 / 9.0 + s2 * (1.0 / 11.0)))));
    let ln_m = 2.0 * s * series;
    let ef = e as f32;
    ef * LN2_HI + (ef * LN2_LO + ln_m)
}

/// `e^x` for `x` (dimensionless), relative error below 1e-6 wherever the result is normal.
///
/// Method: `x = k·ln 2 + r` with integer `k` and |r| ≤ ln2/2 (Cody–Waite two-part ln 2), a
/// degree-7 Taylor polynomial for `e^r` (truncation < 6e-9), then scaling by `2^k` through the
/// exponent bits, in two steps when the result is subnormal or `k` = 128.
pub fn exp(x: f32) -> f32 {
    if x.is_nan() {
        return f32::NAN;
    }
    if x > EXP_OVERFLOW_X {
        return f32::INFINITY;
    }
    if x < EXP_UNDERFLOW_X {
        return 0.0;
    }
    let kf = round_half_away(x * INV_LN2);
    let k = kf as i32;
    let r = (x - kf * LN2_HI) - kf * LN2_LO;
    let p = 1.0
        + r * (1.0
            + r * (1.0 / 2.0
                + r * (1.0 / 6.0
                    + r * (1.0 / 24.0
                        + r * (1.0 / 120.0 + r * (1.0 / 720.0 + r * (1.0 / 5040.0)))))));
    scale_pow2(p, k)
}

/// Rounds to the nearest integer, halves away from zero, for |v| < 2^23 (no `f32::round` in core).
fn round_half_away(v: f32) -> f32 {
    let t = (v.abs() + 0.5) as i32 as f32;
    if v < 0.0 {
        -t
    } else {
        t
    }
}

/// `p · 2^k` for p in [0.7, 1.5] and k in [-150, 128], via exponent bits.
fn scale_pow2(p: f32, k: i32) -> f32 {
    if k > 127 {
        return p * pow2(127) * pow2(k - 127);
    }
    if k < -126 {
        // Land in the normal range first, then let one multiply produce the subnormal.
        return p * pow2(k + 64) * pow2(-64);
    }
    p * pow2(k)
}

/// `2^k` for k in [-126, 127] as an exact `f32`.
fn pow2(k: i32) -> f32 {
    f32::from_bits(((k + 127) as u32) << 23)
}

/// `x` limited to `[lo, hi]`, NaN staying NaN: [`f32::clamp`] for `lo <= hi`, without its
/// check. `core`'s asserts `lo <= hi` and formats both bounds with `f32`'s `Debug` when it
/// fails, which puts the float formatting machinery (several KiB) in the image wherever the
/// compiler cannot prove the bounds ordered; for unordered bounds this returns one of them.
pub fn clamp(x: f32, lo: f32, hi: f32) -> f32 {
    if x < lo {
        lo
    } else if x > hi {
        hi
    } else {
        x
    }
}

/// `sqrt` without `std`: Newton's iteration from a bit-level first guess; 4 steps give `f32`
/// precision over the ranges used here (residuals, uncertainties). 0 for 0, NaN below it.
pub fn sqrt(x: f32) -> f32 {
    if !(x > 0.0) {
        return if x == 0.0 { 0.0 } else { f32::NAN };
    }
    let mut r = f32::from_bits((x.to_bits() >> 1) + 0x1fc0_0000);
    for _ in 0..4 {
        r = 0.5 * (r + x / r);
    }
    r
}

#[cfg(test)]
mod tests {
    #[test]
    fn clamp_is_f32_clamp_for_ordered_bounds() {
        for x in [
            -2.0f32,
            -0.0,
            0.0,
            0.5,
            1.0,
            3.0,
            f32::INFINITY,
            f32::NEG_INFINITY,
        ] {
            for (lo, hi) in [(0.0f32, 1.0f32), (-1.0, -1.0), (0.3, 2.0)] {
                assert_eq!(super::clamp(x, lo, hi), x.clamp(lo, hi), "{x} {lo} {hi}");
            }
        }
        assert!(super::clamp(f32::NAN, 0.0, 1.0).is_nan());
    }

    use super::*;
    use proptest::prelude::*;

    /// Relative error of `got` against the f64 reference.
    fn rel_err(got: f32, want: f64) -> f64 {
        if want == 0.0 {
            (got as f64).abs()
        } else {
            ((got as f64 - want) / want).abs()
        }
    }

    /// `n` log-spaced points over [lo, hi] plus every power-of-two boundary's neighbours.
    fn log_points(lo: f64, hi: f64, n: usize) -> impl Iterator<Item = f32> {
        (0..=n).map(move |i| (lo.ln() + (hi / lo).ln() * i as f64 / n as f64).exp() as f32)
    }

    fn max_ln_err(f: impl Fn(f32) -> f32) -> f64 {
        let mut worst = 0.0f64;
        let mut check = |x: f32| worst = worst.max(rel_err(f(x), (x as f64).ln()));
        log_points(1e-6, 1e9, 200_000).for_each(&mut check);
        // Near 1, where ln is tiny and cancellation would show up.
        for i in 1..2000u32 {
            check(f32::from_bits(1.0f32.to_bits() + i));
            check(f32::from_bits(1.0f32.to_bits() - i));
        }
        worst
    }

    #[test]
    fn ln_relative_error_below_1e6() {
        let worst = max_ln_err(ln);
        println!("mathf::ln max relative error on [1e-6, 1e9]: {worst:e}");
        assert!(worst < 1e-6, "worst {worst:e}");
    }

    #[test]
    fn exp_relative_error_below_1e6() {
        let mut worst = 0.0f64;
        for i in 0..=320_000 {
            let x = -80.0 + 160.0 * i as f32 / 320_000.0;
            worst = worst.max(rel_err(exp(x), (x as f64).exp()));
        }
        println!("mathf::exp max relative error on [-80, 80]: {worst:e}");
        assert!(worst < 1e-6, "worst {worst:e}");
    }

    #[test]
    fn micromath_ln_is_worse() {
        use micromath::F32Ext;
        let ours = max_ln_err(ln);
        let theirs = max_ln_err(F32Ext::ln);
        // Absolute error matters for the thermistor: dT = T² · d(ln R) / β.
        let mut abs_ours = 0.0f64;
        let mut abs_theirs = 0.0f64;
        let mut rel_theirs_away_from_1 = 0.0f64;
        for x in log_points(1e-6, 1e9, 200_000) {
            let want = (x as f64).ln();
            abs_ours = abs_ours.max((ln(x) as f64 - want).abs());
            abs_theirs = abs_theirs.max((F32Ext::ln(x) as f64 - want).abs());
            if want.abs() > 0.1 {
                rel_theirs_away_from_1 = rel_theirs_away_from_1.max(rel_err(F32Ext::ln(x), want));
            }
        }
        println!(
            "micromath ln on [1e-6, 1e9]: max rel {theirs:e}, max rel where |ln x| > 0.1 \
             {rel_theirs_away_from_1:e}, max abs {abs_theirs:e}; ours: rel {ours:e}, abs {abs_ours:e}"
        );
        // The reason this module exists; if micromath ever gets this good, revisit.
        assert!(
            theirs > 100.0 * ours && theirs > 1e-4,
            "micromath {theirs:e}"
        );
        assert!(abs_theirs > 10.0 * abs_ours, "micromath abs {abs_theirs:e}");
    }

    #[test]
    fn special_values() {
        assert!(ln(f32::NAN).is_nan());
        assert!(ln(-1.0).is_nan());
        assert_eq!(ln(0.0), f32::NEG_INFINITY);
        assert_eq!(ln(f32::INFINITY), f32::INFINITY);
        assert_eq!(ln(1.0), 0.0);
        assert!(rel_err(ln(f32::MAX), (f32::MAX as f64).ln()) < 1e-6);
        let tiny = f32::from_bits(1); // smallest subnormal
        assert!(rel_err(ln(tiny), (tiny as f64).ln()) < 1e-6);
        assert!(exp(f32::NAN).is_nan());
        assert_eq!(exp(f32::NEG_INFINITY), 0.0);
        assert_eq!(exp(f32::INFINITY), f32::INFINITY);
        assert_eq!(exp(89.0), f32::INFINITY);
        assert_eq!(exp(0.0), 1.0);
        assert!(rel_err(exp(88.7), (88.7f32 as f64).exp()) < 1e-6);
        // Subnormal results keep only a few bits but must be in the right place.
        let sub = exp(-100.0) as f64;
        assert!((sub - (-100f64).exp()).abs() < 2.0 * f32::from_bits(1) as f64);
    }

    proptest! {
        #[test]
        fn ln_matches_std(x in 1e-6f32..1e9) {
            prop_assert!(rel_err(ln(x), (x as f64).ln()) < 1e-6);
        }

        #[test]
        fn exp_matches_std(x in -80f32..80.0) {
            prop_assert!(rel_err(exp(x), (x as f64).exp()) < 1e-6);
        }

        #[test]
        fn exp_inverts_ln(x in 1e-6f32..1e9) {
            prop_assert!(rel_err(exp(ln(x)), x as f64) < 1e-5);
        }
    }
}

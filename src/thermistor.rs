//! NTC thermistor conversion (of oversampled, summed readings) and open/short detection.
//!
//! Circuit: the NTC sits on the low side of a divider with a pull-up resistor to the ADC
//! reference, so the ADC reads `fraction = R_ntc / (R_ntc + R_pullup)` of full scale. A broken
//! (open) thermistor reads full scale, i.e. "very cold"; a shorted one reads 0, "very hot".
//! Readings outside [`ThermistorConfig::min_fraction`, `max_fraction`] are classified as
//! faults instead of temperatures, and [`RangeCheck`] turns a run of them into a latched fault.

use crate::mathf::{exp, ln};

/// 0 °C in kelvin.
pub const KELVIN_OFFSET: f32 = 273.15;

/// Reference temperature of the Beta model, 25 °C in kelvin.
pub const T25_K: f32 = 298.15;

/// Largest count of a single 12-bit ADC conversion.
pub const ADC_12BIT_MAX: u32 = 4095;

/// The ADC fraction is clamped to [ε, 1 − ε] before conversion, as Klipper does (0.00001), so a
/// reading of exactly 0 or full scale still gives a finite (absurd) temperature rather than a
/// division by zero or ln(0).
pub const FRACTION_EPSILON: f32 = 1e-5;

/// Lowest fraction of full scale accepted as a temperature; below it the sensor reads as
/// [`Reading::Short`]. For the default 10 kΩ B3950 NTC with a 10 kΩ pull-up, 150 °C is at
/// fraction 0.0196 (≈ 200 Ω) and 0.005 is ≈ 50 Ω, about 224 °C: far above anything the link
/// can reach, yet 20 counts (12-bit) above the 0 a dead short reads.
pub const DEFAULT_MIN_FRACTION: f32 = 0.005;

/// Highest fraction of full scale accepted as a temperature; above it the sensor reads as
/// [`Reading::Open`]. 0 °C is at fraction 0.771 (≈ 33.6 kΩ) and 0.98 is ≈ 490 kΩ, about
/// −43 °C: colder than any water or air the link works in, yet 82 counts (12-bit) below the
/// full scale an open wire reads.
pub const DEFAULT_MAX_FRACTION: f32 = 0.98;

/// Resistance–temperature model of the NTC.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Curve {
    /// `1/T = 1/T25 + ln(R/R25)/β` (T in kelvin).
    Beta {
        /// Resistance at 25 °C in ohms.
        r25_ohm: f32,
        /// β constant in kelvin.
        beta_k: f32,
    },
    /// `1/T = c1 + c2·ln R + c3·(ln R)³` (T in kelvin, R in ohms).
    SteinhartHart {
        /// Constant term in 1/K.
        c1: f32,
        /// Linear coefficient in 1/K.
        c2: f32,
        /// Cubic coefficient in 1/K.
        c3: f32,
    },
}

impl Curve {
    /// Temperature in °C of the NTC at `resistance_ohm`.
    pub fn temp_c(&self, resistance_ohm: f32) -> f32 {
        let inv_t = match *self {
            Curve::Beta { r25_ohm, beta_k } => 1.0 / T25_K + ln(resistance_ohm / r25_ohm) / beta_k,
            Curve::SteinhartHart { c1, c2, c3 } => {
                let l = ln(resistance_ohm);
                c1 + l * (c2 + c3 * l * l)
            }
        };
        1.0 / inv_t - KELVIN_OFFSET
    }

    /// Resistance in ohms of the NTC at `temp_c` (inverse of [`Curve::temp_c`]).
    pub fn resistance_ohm(&self, temp_c: f32) -> f32 {
        let inv_t = 1.0 / (temp_c + KELVIN_OFFSET);
        match *self {
            Curve::Beta { r25_ohm, beta_k } => r25_ohm * exp(beta_k * (inv_t - 1.0 / T25_K)),
            Curve::SteinhartHart { c1, c2, c3 } => {
                // Solve c3·L³ + c2·L + c1 − 1/T = 0 by Newton from the linear solution; the
                // cubic term is a small correction so a few steps converge to f32 precision.
                let mut l = (inv_t - c1) / c2;
                for _ in 0..6 {
                    let g = c1 + l * (c2 + c3 * l * l) - inv_t;
                    l -= g / (c2 + 3.0 * c3 * l * l);
                }
                exp(l)
            }
        }
    }
}

/// A thermistor channel: curve, divider and ADC scaling, and fault limits.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThermistorConfig {
    /// The NTC's resistance–temperature model.
    pub curve: Curve,
    /// Pull-up resistor from the ADC reference to the NTC, in ohms.
    pub pullup_ohm: f32,
    /// Count of a full-scale reading, after any oversampling (e.g. 16 · 4095 for 16 summed
    /// 12-bit samples).
    pub adc_full_scale: u32,
    /// Fractions of full scale below this read as [`Reading::Short`].
    pub min_fraction: f32,
    /// Fractions of full scale above this read as [`Reading::Open`].
    pub max_fraction: f32,
}

/// What a thermistor reading means.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Reading {
    /// A plausible temperature in °C.
    Ok(f32),
    /// Above `max_fraction`: wire broken or connector off (reads "too cold").
    Open,
    /// Below `min_fraction`: thermistor or its wiring shorted (reads "too hot").
    Short,
}

impl ThermistorConfig {
    /// A 10 kΩ B3950 NTC (the common 3950 K, 10 kΩ-at-25 °C part) with a 10 kΩ pull-up on a
    /// single 12-bit conversion (full scale [`ADC_12BIT_MAX`]); a 10 kΩ pull-up equals R25 so
    /// the divider is most sensitive around room temperature.
    pub const DEFAULT: ThermistorConfig = ThermistorConfig {
        curve: Curve::Beta {
            r25_ohm: 10_000.0,
            beta_k: 3950.0,
        },
        pullup_ohm: 10_000.0,
        adc_full_scale: ADC_12BIT_MAX,
        min_fraction: DEFAULT_MIN_FRACTION,
        max_fraction: DEFAULT_MAX_FRACTION,
    };

    /// The same channel read with a different full scale (e.g. for oversampled, summed readings).
    pub const fn with_full_scale(self, adc_full_scale: u32) -> Self {
        ThermistorConfig {
            adc_full_scale,
            ..self
        }
    }

    /// Fraction of full scale of `counts`, unclamped; counts above full scale count as full
    /// scale, and a zero full scale (a configuration error) reads as 0, i.e. as a short.
    fn fraction(&self, counts: u32) -> f32 {
        if self.adc_full_scale == 0 {
            return 0.0;
        }
        counts.min(self.adc_full_scale) as f32 / self.adc_full_scale as f32
    }

    /// NTC resistance in ohms for `counts`, with the fraction clamped to
    /// [[`FRACTION_EPSILON`], 1 − [`FRACTION_EPSILON`]] so the result is always finite.
    pub fn resistance_ohm(&self, counts: u32) -> f32 {
        let f = self
            .fraction(counts)
            .clamp(FRACTION_EPSILON, 1.0 - FRACTION_EPSILON);
        self.pullup_ohm * f / (1.0 - f)
    }

    /// Temperature in °C for a reading of `counts`, without fault classification (an open
    /// sensor gives a very low, a short a very high temperature).
    pub fn temp_c(&self, counts: u32) -> f32 {
        self.curve.temp_c(self.resistance_ohm(counts))
    }

    /// The reading in counts the ADC would give at `temp_c` (rounded to the nearest count); used
    /// by the simulator. Temperatures below absolute zero or NaN read full scale (like an open
    /// sensor), +∞ reads 0.
    pub fn counts_for_temp(&self, temp_c: f32) -> u32 {
        if temp_c.is_nan() || temp_c <= -KELVIN_OFFSET {
            return self.adc_full_scale;
        }
        let r = self.curve.resistance_ohm(temp_c);
        // fraction = R / (R + R_pullup), written to stay finite at R = 0 and R = ∞.
        let f = 1.0 / (1.0 + self.pullup_ohm / r);
        if f.is_nan() {
            return self.adc_full_scale;
        }
        let counts = f * self.adc_full_scale as f32 + 0.5;
        // `as` saturates, and f ≤ 1 keeps this within full scale.
        (counts as u32).min(self.adc_full_scale)
    }

    /// Classifies `counts` as a temperature or an open/short fault using the fraction limits.
    /// A temperature that comes out non-finite (only possible with a broken curve) reads as
    /// [`Reading::Open`] so that it fails safe.
    pub fn classify(&self, counts: u32) -> Reading {
        let f = self.fraction(counts);
        if f > self.max_fraction {
            return Reading::Open;
        }
        if f < self.min_fraction {
            return Reading::Short;
        }
        let temp_c = self.temp_c(counts);
        if temp_c.is_finite() {
            Reading::Ok(temp_c)
        } else {
            Reading::Open
        }
    }
}

/// Debounces open/short readings with a leaky counter: +1 for an out-of-range sample, −1 for
/// a good one (never below 0, never above the trip count), a fault reported once the count
/// reaches the trip count. One noisy conversion does not stop a morph, and an intermittent
/// fault (a loose crimp reading open every other sample) adds up where a consecutive count
/// would restart for ever.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RangeCheck {
    consecutive: u8,
    count: u8,
}

impl Default for RangeCheck {
    fn default() -> Self {
        Self::new(Self::DEFAULT_CONSECUTIVE)
    }
}

impl RangeCheck {
    /// The trip count, as Klipper's ADC range check uses (4 samples): at our 10 Hz control rate
    /// a real fault is caught within 0.4 s, well inside the heaters' seconds-long time
    /// constants; an intermittent one that is bad at least every other sample within 0.8 s.
    pub const DEFAULT_CONSECUTIVE: u8 = 4;

    /// A check that faults once its leaky count reaches `consecutive` (0 is treated as 1).
    pub const fn new(consecutive: u8) -> Self {
        RangeCheck {
            consecutive: if consecutive == 0 { 1 } else { consecutive },
            count: 0,
        }
    }

    /// Whether the check stands tripped: its leaky count has reached the trip count (the
    /// sensor counts as failed until good samples bring it down).
    pub fn tripped(&self) -> bool {
        self.count >= self.consecutive
    }

    /// Feeds one classified sample. Returns `Some(Open)`/`Some(Short)` (this sample's class)
    /// on every out-of-range sample once the leaky count has reached the trip count (so a
    /// persisting fault keeps being reported); a good sample takes one off the count.
    pub fn update(&mut self, reading: Reading) -> Option<Reading> {
        match reading {
            Reading::Ok(_) => {
                self.count = self.count.saturating_sub(1);
                None
            }
            Reading::Open | Reading::Short => {
                self.count = (self.count + 1).min(self.consecutive);
                (self.count >= self.consecutive).then_some(reading)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const OVERSAMPLED_16: u32 = 16 * ADC_12BIT_MAX;

    /// Exact (f64) NTC temperature in °C from resistance, for either curve.
    fn exact_temp_c(curve: &Curve, r: f64) -> f64 {
        let inv_t = match *curve {
            Curve::Beta { r25_ohm, beta_k } => {
                1.0 / 298.15 + (r / r25_ohm as f64).ln() / beta_k as f64
            }
            Curve::SteinhartHart { c1, c2, c3 } => {
                let l = r.ln();
                c1 as f64 + c2 as f64 * l + c3 as f64 * l * l * l
            }
        };
        1.0 / inv_t - 273.15
    }

    /// Exact resistance from temperature (bisection on the exact forward model).
    fn exact_r(curve: &Curve, temp_c: f64) -> f64 {
        let (mut lo, mut hi) = (1.0f64.ln(), 1e9f64.ln());
        for _ in 0..200 {
            let mid = 0.5 * (lo + hi);
            // Temperature falls as resistance rises.
            if exact_temp_c(curve, mid.exp()) > temp_c {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        (0.5 * (lo + hi)).exp()
    }

    fn exact_counts(cfg: &ThermistorConfig, temp_c: f64) -> u32 {
        let r = exact_r(&cfg.curve, temp_c);
        (r / (r + cfg.pullup_ohm as f64) * cfg.adc_full_scale as f64).round() as u32
    }

    fn exact_temp_for_counts(cfg: &ThermistorConfig, counts: u32) -> f64 {
        let f = (counts as f64 / cfg.adc_full_scale as f64).clamp(1e-5, 1.0 - 1e-5);
        exact_temp_c(&cfg.curve, cfg.pullup_ohm as f64 * f / (1.0 - f))
    }

    /// Steinhart–Hart coefficients through three (°C, Ω) points, solved in f64.
    fn fit_steinhart_hart(points: [(f64, f64); 3]) -> Curve {
        let [(t1, r1), (t2, r2), (t3, r3)] = points;
        let (l1, l2, l3) = (r1.ln(), r2.ln(), r3.ln());
        let (y1, y2, y3) = (
            1.0 / (t1 + 273.15),
            1.0 / (t2 + 273.15),
            1.0 / (t3 + 273.15),
        );
        let g2 = (y2 - y1) / (l2 - l1);
        let g3 = (y3 - y1) / (l3 - l1);
        let c3 = (g3 - g2) / (l3 - l2) / (l1 + l2 + l3);
        let c2 = g2 - c3 * (l1 * l1 + l1 * l2 + l2 * l2);
        let c1 = y1 - (c2 + l1 * l1 * c3) * l1;
        Curve::SteinhartHart {
            c1: c1 as f32,
            c2: c2 as f32,
            c3: c3 as f32,
        }
    }

    /// Steinhart–Hart for the default B3950 part, fitted through its Beta curve at 0, 75 and
    /// 150 °C (the ends and middle of the working range).
    fn b3950_sh() -> Curve {
        let beta = ThermistorConfig::DEFAULT.curve;
        fit_steinhart_hart([0.0, 75.0, 150.0].map(|t| (t, exact_r(&beta, t))))
    }

    /// A generic 10 kΩ NTC with a non-zero cubic term, to exercise it (the Beta-fitted curve
    /// has c3 ≈ 0 because Beta is Steinhart–Hart without the cubic term).
    const SH_CUBIC: Curve = Curve::SteinhartHart {
        c1: 1.009_249_5e-3,
        c2: 2.378_405_4e-4,
        c3: 2.019_202_7e-7,
    };

    fn configs() -> [(&'static str, ThermistorConfig); 6] {
        let beta = ThermistorConfig::DEFAULT;
        let sh = ThermistorConfig {
            curve: b3950_sh(),
            ..beta
        };
        let cubic = ThermistorConfig {
            curve: SH_CUBIC,
            ..beta
        };
        [
            ("beta 12-bit", beta),
            ("beta 16x", beta.with_full_scale(OVERSAMPLED_16)),
            ("sh 12-bit", sh),
            ("sh 16x", sh.with_full_scale(OVERSAMPLED_16)),
            ("sh-cubic 12-bit", cubic),
            ("sh-cubic 16x", cubic.with_full_scale(OVERSAMPLED_16)),
        ]
    }

    #[test]
    fn fitted_sh_reproduces_beta() {
        let beta = ThermistorConfig::DEFAULT.curve;
        let sh = b3950_sh();
        if let Curve::SteinhartHart { c1, c2, c3 } = sh {
            assert!((c2 - 1.0 / 3950.0).abs() < 1e-9, "c2 {c2:e}");
            assert!(c3.abs() < 1e-10, "c3 {c3:e}");
            assert!(c1 > 0.0);
        }
        for t in [0.0, 25.0, 75.0, 150.0] {
            let r = exact_r(&beta, t);
            assert!((exact_temp_c(&sh, r) - t).abs() < 1e-3, "{t}");
        }
        assert!((exact_r(&beta, 25.0) - 10_000.0).abs() < 1e-3);
    }

    #[test]
    fn error_budget_0_to_150_c() {
        for (name, cfg) in configs() {
            let mut worst = 0.0f64;
            for i in 0..=1500 {
                let t = i as f64 * 0.1;
                let counts = exact_counts(&cfg, t);
                let err = (cfg.temp_c(counts) as f64 - exact_temp_for_counts(&cfg, counts)).abs();
                worst = worst.max(err);
            }
            println!("{name}: max |temp_c - exact| over 0..150 C = {worst:.5} C");
            assert!(worst < 0.2, "{name}: {worst}");
        }
    }

    #[test]
    fn counts_for_temp_matches_exact_inverse() {
        for (name, cfg) in configs() {
            let mut worst = 0i64;
            for i in -400..=2000 {
                let t = i as f32 * 0.1;
                let diff = cfg.counts_for_temp(t) as i64 - exact_counts(&cfg, t as f64) as i64;
                worst = worst.max(diff.abs());
            }
            assert!(worst <= 1, "{name}: off by {worst} counts");
        }
    }

    #[test]
    fn temp_round_trip_within_one_count() {
        for (name, cfg) in configs() {
            for i in 0..=150 {
                let t = i as f32;
                let c = cfg.counts_for_temp(t);
                let step = (cfg.temp_c(c - 1) - cfg.temp_c(c + 1)).abs() / 2.0;
                let back = cfg.temp_c(c);
                assert!((back - t).abs() <= 0.5 * step + 0.01, "{name} {t}: {back}");
            }
        }
    }

    #[test]
    fn default_limits_bracket_working_range_and_catch_faults() {
        let cfg = ThermistorConfig::DEFAULT;
        let fs = cfg.adc_full_scale as f32;
        let short_limit_c = cfg.curve.temp_c(cfg.pullup_ohm * 0.005 / 0.995);
        let open_limit_c = cfg.curve.temp_c(cfg.pullup_ohm * 0.98 / 0.02);
        assert!((200.0..250.0).contains(&short_limit_c), "{short_limit_c}");
        assert!((-50.0..-30.0).contains(&open_limit_c), "{open_limit_c}");
        for t in [0.0, 25.0, 100.0, 150.0] {
            let c = cfg.counts_for_temp(t);
            assert!(
                matches!(cfg.classify(c), Reading::Ok(v) if (v - t).abs() < 0.6),
                "{t}"
            );
        }
        assert_eq!(cfg.classify(ADC_12BIT_MAX), Reading::Open);
        assert_eq!(cfg.classify(u32::MAX), Reading::Open);
        assert_eq!(cfg.classify(0), Reading::Short);
        // A few counts of noise on a dead short or open wire still classify as faults.
        assert_eq!(cfg.classify(5), Reading::Short);
        assert_eq!(cfg.classify(ADC_12BIT_MAX - 20), Reading::Open);
        assert!((cfg.min_fraction * fs) > 19.0 && ((1.0 - cfg.max_fraction) * fs) > 80.0);
        let os = cfg.with_full_scale(OVERSAMPLED_16);
        assert_eq!(os.classify(OVERSAMPLED_16), Reading::Open);
        assert_eq!(os.classify(16 * 3), Reading::Short);
    }

    #[test]
    fn clamped_extremes_are_finite() {
        let cfg = ThermistorConfig::DEFAULT;
        assert!(cfg.temp_c(0).is_finite() && cfg.temp_c(0) > 500.0);
        assert!(cfg.temp_c(ADC_12BIT_MAX).is_finite() && cfg.temp_c(ADC_12BIT_MAX) < -100.0);
        let broken = cfg.with_full_scale(0);
        assert_eq!(broken.classify(100), Reading::Short);
        assert!(broken.temp_c(100).is_finite());
    }

    #[test]
    fn counts_for_temp_extremes() {
        let cfg = ThermistorConfig::DEFAULT;
        assert_eq!(cfg.counts_for_temp(f32::NAN), ADC_12BIT_MAX);
        assert_eq!(cfg.counts_for_temp(-300.0), ADC_12BIT_MAX);
        assert_eq!(cfg.counts_for_temp(f32::NEG_INFINITY), ADC_12BIT_MAX);
        assert_eq!(cfg.counts_for_temp(f32::INFINITY), 0);
        assert_eq!(cfg.counts_for_temp(5000.0), 0);
        assert!(cfg.counts_for_temp(-150.0) >= ADC_12BIT_MAX - 1);
        assert!((2047..=2048).contains(&cfg.counts_for_temp(25.0))); // R = R_pullup: half scale
    }

    /// Sums oversampled ADC conversions into one reading (saturating), as the boards do.
    fn oversample(samples: &[u16]) -> u32 {
        samples
            .iter()
            .fold(0u32, |sum, &s| sum.saturating_add(s as u32))
    }

    /// The thermistor budget of the temperature conversion's maths, °C, over [`BUDGET_RANGE_C`].
    const BUDGET_C: f64 = 0.2;
    /// Where the budget holds, °C.
    const BUDGET_RANGE_C: (f64, f64) = (0.0, 150.0);

    /// Largest error, °C, over 0–150 °C of the default Beta curve computed in `f32` with the
    /// given `ln` and `exp`: (counts → °C: the NTC's exact resistance through `ln`; °C → counts:
    /// the resistance from `exp`, read back exactly).
    fn conversion_error_c(ln: impl Fn(f32) -> f32, exp: impl Fn(f32) -> f32) -> (f64, f64) {
        let Curve::Beta { r25_ohm, beta_k } = ThermistorConfig::DEFAULT.curve else {
            unreachable!()
        };
        let (r25, beta, t25) = (r25_ohm as f64, beta_k as f64, T25_K as f64);
        let k0 = KELVIN_OFFSET as f64;
        let (mut to_c, mut from_c) = (0.0f64, 0.0f64);
        let steps = 30_000;
        for i in 0..=steps {
            let t_c =
                BUDGET_RANGE_C.0 + (BUDGET_RANGE_C.1 - BUDGET_RANGE_C.0) * i as f64 / steps as f64;
            let r = r25 * (beta * (1.0 / (t_c + k0) - 1.0 / t25)).exp();
            // counts → °C, as `Curve::temp_c` computes it.
            let inv_t = 1.0 / T25_K + ln(r as f32 / r25_ohm) / beta_k;
            let got_c = (1.0 / inv_t - KELVIN_OFFSET) as f64;
            to_c = to_c.max((got_c - t_c).abs());
            // °C → counts, as `Curve::resistance_ohm` computes it, read back exactly.
            let inv_t = 1.0 / (t_c as f32 + KELVIN_OFFSET);
            let r_got = (r25_ohm * exp(beta_k * (inv_t - 1.0 / T25_K))) as f64;
            let back_c = 1.0 / (1.0 / t25 + (r_got / r25).ln() / beta) - k0;
            from_c = from_c.max((back_c - t_c).abs());
        }
        (to_c, from_c)
    }

    /// The numbers of docs/firmware.md ("Maths: why not micromath"): the hand-written
    /// `mathf` and libm keep the conversion far inside the ±0.2 °C budget; micromath's
    /// `ln`/`exp` exceed it, which is why the firmware does not use them.
    #[test]
    fn micromath_exceeds_the_thermistor_budget_and_mathf_does_not() {
        use micromath::F32Ext;
        let ours = conversion_error_c(crate::mathf::ln, crate::mathf::exp);
        let libm = conversion_error_c(libm::logf, libm::expf);
        let micro = conversion_error_c(F32Ext::ln, F32Ext::exp);
        println!(
            "max error over 0-150 C (counts->C, C->counts): mathf {ours:?}, libm {libm:?}, \
             micromath {micro:?}"
        );
        assert!(ours.0 < 0.01 && ours.1 < 0.01, "mathf {ours:?}");
        assert!(libm.0 < 0.01 && libm.1 < 0.01, "libm {libm:?}");
        assert!(micro.0 > BUDGET_C, "micromath ln {micro:?}");
    }

    #[test]
    fn oversample_sums() {
        assert_eq!(oversample(&[]), 0);
        assert_eq!(oversample(&[4095; 16]), OVERSAMPLED_16);
        assert_eq!(oversample(&[1, 2, 3]), 6);
        assert_eq!(oversample(&[u16::MAX; 70_000]), u32::MAX);
        let cfg = ThermistorConfig::DEFAULT;
        let single = cfg.counts_for_temp(60.0) as u16;
        let summed = oversample(&[single; 16]);
        let os = cfg.with_full_scale(OVERSAMPLED_16);
        assert!((os.temp_c(summed) - cfg.temp_c(single as u32)).abs() < 1e-3);
    }

    #[test]
    fn range_check_counts_intermittent_faults() {
        let mut rc = RangeCheck::default();
        for _ in 0..3 {
            assert_eq!(rc.update(Reading::Open), None);
        }
        assert_eq!(rc.update(Reading::Open), Some(Reading::Open));
        assert_eq!(rc.update(Reading::Open), Some(Reading::Open)); // still reported
        assert_eq!(rc.update(Reading::Ok(20.0)), None);
        // One good sample takes one off: the next bad one trips again.
        assert_eq!(rc.update(Reading::Short), Some(Reading::Short));
        let mut rc = RangeCheck::default();
        // A single noisy sample now and then never adds up.
        for _ in 0..20 {
            assert_eq!(rc.update(Reading::Open), None);
            assert_eq!(rc.update(Reading::Ok(20.0)), None);
        }
        // Bad two samples out of three: adds up (a consecutive count would restart for ever).
        let mut tripped = false;
        for _ in 0..10 {
            tripped |= rc.update(Reading::Open).is_some();
            tripped |= rc.update(Reading::Short).is_some();
            assert_eq!(rc.update(Reading::Ok(20.0)), None);
        }
        assert!(tripped);
        let mut one = RangeCheck::new(0);
        assert_eq!(one.update(Reading::Short), Some(Reading::Short));
    }

    proptest! {
        #[test]
        fn range_check_matches_leaky_count(
            seq in prop::collection::vec(0u8..3, 0..300),
            n in 1u8..8,
        ) {
            let mut rc = RangeCheck::new(n);
            let mut count = 0usize;
            for kind in seq {
                let reading = match kind {
                    0 => Reading::Ok(25.0),
                    1 => Reading::Open,
                    _ => Reading::Short,
                };
                count = if kind == 0 { count.saturating_sub(1) } else { (count + 1).min(n as usize) };
                let want = (kind != 0 && count >= n as usize).then_some(reading);
                prop_assert_eq!(rc.update(reading), want);
            }
        }

        #[test]
        fn classify_and_temp_never_panic_and_are_monotonic(c in 0u32..=OVERSAMPLED_16) {
            let cfg = ThermistorConfig::DEFAULT.with_full_scale(OVERSAMPLED_16);
            let t = cfg.temp_c(c);
            prop_assert!(t.is_finite());
            if c < OVERSAMPLED_16 {
                // More counts = more resistance = colder (ties allowed in the clamped ends).
                prop_assert!(cfg.temp_c(c + 1) <= t);
            }
            let _ = cfg.classify(c);
        }

        #[test]
        fn counts_for_temp_never_panics(t in proptest::num::f32::ANY) {
            let cfg = ThermistorConfig::DEFAULT;
            prop_assert!(cfg.counts_for_temp(t) <= cfg.adc_full_scale);
        }
    }
}

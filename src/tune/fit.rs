//! Fits of a heater step's thermistor record: a steady rise and a time constant, by two
//! methods, so that one that fails has a second (Marlin #25496: an asymptotic fit with no
//! fallback).
//!
//! The record is the thermistor's rise above its baseline, one sample every `dt_s`, from the
//! moment the heater's power stepped on. Both methods model it as first order,
//! `y(t) = Y (1 − e^(−t/τ))`: the bead's lag and the heater's own capacity make the first
//! seconds slower, so the asymptotic method reads only the record's last two thirds.
//! Neither result is used before [`super`] has checked its sign and bounds.

use crate::mathf::{exp, ln};

/// Which method produced a fit.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Method {
    /// Three equally spaced points of the record's tail (the classic asymptote from
    /// successive differences).
    Asymptotic,
    /// Least squares of the whole record over a grid of time constants, the rise solved in
    /// closed form at each.
    LeastSquares,
}

impl Method {
    /// Wire name.
    pub fn as_str(self) -> &'static str {
        match self {
            Method::Asymptotic => "asymptotic",
            Method::LeastSquares => "least-squares",
        }
    }
}

/// One fitted step response.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StepFit {
    /// Steady rise, K.
    pub rise_k: f32,
    /// Time constant, s.
    pub tau_s: f32,
    /// How it was found.
    pub method: Method,
}

/// Least samples a fit needs: three windows of at least three samples.
pub const MIN_SAMPLES: usize = 9;
/// Grid of the least-squares method: time constants log-spaced over its range, points.
pub const GRID_POINTS: usize = 48;

/// Mean of `y[from..to]`.
fn mean(y: &[f32], from: usize, to: usize) -> f32 {
    let s: f32 = y[from..to].iter().sum();
    s / (to - from) as f32
}

/// The asymptotic method: the record's mean over three windows ending a third, two thirds and
/// all of the way through; their successive differences shrink by `r = e^(−h/τ)`, which gives
/// `τ` and the asymptote `y₁ + (y₂ − y₁)/(1 − r)`. `None` unless the record rises and slows
/// (`0 < r < 1`).
pub fn asymptotic(y: &[f32], dt_s: f32) -> Option<StepFit> {
    let n = y.len();
    if n < MIN_SAMPLES {
        return None;
    }
    let third = n / 3;
    let w = (third / 3).max(1);
    let at = |end: usize| mean(y, end - w, end);
    let (y1, y2, y3) = (at(third), at(2 * third), at(3 * third));
    let (d1, d2) = (y2 - y1, y3 - y2);
    if !(d1 > 0.0) {
        return None;
    }
    let r = d2 / d1;
    if !(r > 0.0 && r < 1.0) {
        return None;
    }
    let h_s = third as f32 * dt_s;
    let tau_s = -h_s / ln(r);
    let rise_k = y1 + d1 / (1.0 - r);
    (tau_s.is_finite() && rise_k.is_finite()).then_some(StepFit {
        rise_k,
        tau_s,
        method: Method::Asymptotic,
    })
}

/// The least-squares method over time constants log-spaced in `tau_range_s`: for each, the
/// rise that fits best is `Σ y f / Σ f²` with `f = 1 − e^(−t/τ)`; the pair with the least
/// squared residual wins. `None` for a record too short or one that does not rise.
pub fn least_squares(y: &[f32], dt_s: f32, tau_range_s: (f32, f32)) -> Option<StepFit> {
    if y.len() < MIN_SAMPLES || !(tau_range_s.0 > 0.0 && tau_range_s.1 > tau_range_s.0) {
        return None;
    }
    let span = ln(tau_range_s.1 / tau_range_s.0);
    let mut best: Option<(f32, StepFit)> = None;
    for k in 0..GRID_POINTS {
        let tau_s = tau_range_s.0 * exp(span * k as f32 / (GRID_POINTS - 1) as f32);
        let (mut syf, mut sff) = (0.0f32, 0.0f32);
        for (i, &v) in y.iter().enumerate() {
            let f = 1.0 - exp(-((i + 1) as f32 * dt_s) / tau_s);
            syf += v * f;
            sff += f * f;
        }
        if !(sff > 0.0) {
            continue;
        }
        let rise_k = syf / sff;
        let mut sse = 0.0f32;
        for (i, &v) in y.iter().enumerate() {
            let f = 1.0 - exp(-((i + 1) as f32 * dt_s) / tau_s);
            let e = v - rise_k * f;
            sse += e * e;
        }
        if sse.is_finite() && best.is_none_or(|(b, _)| sse < b) {
            best = Some((
                sse,
                StepFit {
                    rise_k,
                    tau_s,
                    method: Method::LeastSquares,
                },
            ));
        }
    }
    best.map(|(_, f)| f).filter(|f| f.rise_k > 0.0)
}

/// Root-mean-square residual of `fit` against the record's last two thirds, K (the part a
/// first-order curve should follow: the bead's lag shapes the first third).
pub fn residual_rms_k(y: &[f32], dt_s: f32, fit: &StepFit) -> f32 {
    let from = y.len() / 3;
    if y.len() <= from || !(fit.tau_s > 0.0) {
        return f32::NAN;
    }
    let mut sse = 0.0f32;
    for (i, &v) in y.iter().enumerate().skip(from) {
        let f = 1.0 - exp(-((i + 1) as f32 * dt_s) / fit.tau_s);
        let e = v - fit.rise_k * f;
        sse += e * e;
    }
    crate::mathf::sqrt(sse / (y.len() - from) as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn record(rise: f32, tau: f32, n: usize) -> [f32; 120] {
        let mut y = [0.0f32; 120];
        for i in 0..n {
            y[i] = rise * (1.0 - exp(-((i + 1) as f32) / tau));
        }
        y
    }

    #[test]
    fn both_methods_recover_a_first_order_step() {
        let y = record(25.0, 20.0, 90);
        let a = asymptotic(&y[..90], 1.0).unwrap();
        assert!(
            (a.rise_k - 25.0).abs() < 0.2 && (a.tau_s - 20.0).abs() < 0.5,
            "{a:?}"
        );
        let l = least_squares(&y[..90], 1.0, (2.0, 200.0)).unwrap();
        assert!(
            (l.rise_k - 25.0).abs() < 1.0 && (l.tau_s - 20.0).abs() < 2.0,
            "{l:?}"
        );
    }

    #[test]
    fn a_flat_or_falling_record_fails_the_asymptote_but_not_silently() {
        let flat = [1.0f32; 60];
        assert_eq!(asymptotic(&flat, 1.0), None);
        let mut falling = [0.0f32; 60];
        for (i, v) in falling.iter_mut().enumerate() {
            *v = -(i as f32);
        }
        assert_eq!(asymptotic(&falling, 1.0), None);
        assert_eq!(least_squares(&falling, 1.0, (2.0, 200.0)), None);
        // A record still rising at a constant rate has no asymptote (r = 1) ...
        let mut ramp = [0.0f32; 60];
        for (i, v) in ramp.iter_mut().enumerate() {
            *v = i as f32 * 0.5;
        }
        assert_eq!(asymptotic(&ramp, 1.0), None);
        // ... and the fallback still answers (the bounds check then judges it).
        assert!(least_squares(&ramp, 1.0, (2.0, 200.0)).is_some());
    }

    #[test]
    fn short_records_are_refused() {
        assert_eq!(asymptotic(&[1.0; 5], 1.0), None);
        assert_eq!(least_squares(&[1.0; 5], 1.0, (2.0, 200.0)), None);
    }
}

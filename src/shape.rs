//! The link's shape read from the TCA's resistance at rest (docs/shape.md).
//!
//! At rest the TCA sits at the ambient temperature, so what is left of its resistance's change
//! since a rest at a known shape is its strain: the shape the link locked in. The coil sits off
//! the rod's axis, so its strain, and with it `ΔR/R`, is linear in the change of curvature:
//! `g = (R/R_A − 1) − α·(T − T_A) = G·(κ − κ_A)`, with `α` the TCA's temperature coefficient
//! (the calibration's), `T` the TCA thermistor's reading at rest and `G` this link's gauge
//! (1/m⁻¹, either sign: the plated thread's contacts may open or close as it shortens). `G` is
//! learnt from two rests at known shapes (the link as built and a MEASURED one, or two MEASURED
//! ones); from then on every rest gives `κ = κ_A + g/G` with an uncertainty from the rests' own
//! spread, the thermometers' and the gauge's.
//!
//! [`RestShape`] holds the anchor (the last rest at a known shape), the gauge and the rest
//! being read; the controller feeds it every tick at rest and acts on what [`RestShape::note`]
//! returns.

use crate::mathf::sqrt;

/// Fastest drift of the TCA thermistor over a reading for the TCA to count as at rest, K/s:
/// the bead's remaining excess is about its drift times its settling time (some 60 s), and at
/// 1.5e-3/K a kelvin is 0.15 % of resistance, the strain of 2.5 /m on a 6e-4 gauge; 0.002 K/s
/// leaves about 0.1 K of excess, which the bead's own reading then takes out (its offset
/// against the anchor's cancels). The thermistor must also be within
/// [`crate::electrical::SELF_REST_MAX_K`] of ambient (the beads' tolerance).
pub const SHAPE_REST_MAX_K_S: f32 = 0.002;
/// The TCA's settling time the drift's remaining excess is counted with, s.
pub const REST_SETTLE_S: f32 = 60.0;
/// Rest ticks a reading averages, 300 (30 s at 10 Hz): the probe pulses' 0.2 % noise averages
/// to about 0.012 %, 0.2 /m of curvature on a 6e-4 gauge.
pub const SHAPE_REST_TICKS: u16 = 300;
/// Seconds after `done` a link may take to rest before it is reported as not resting
/// (`event: shape none reason=no-rest`): about twice the 10 minutes a still-air TCA takes to
/// settle within [`SHAPE_REST_MAX_K_S`].
pub const SHAPE_REST_MAX_S: f32 = 1200.0;
/// Least change of curvature between two known shapes a gauge is learnt from, 1/m: the
/// table's range spans 9 /m, and a gauge from a smaller step carries the shapes' own
/// uncertainty several times over.
pub const GAUGE_MIN_SPAN_PER_M: f32 = 2.0;
/// A gauge whose magnitude is under this many of its own uncertainty reads no shape, 1: the
/// coil's resistance then says too little of its strain (a gauge factor near zero, a plant or
/// link whose TCA has none).
pub const GAUGE_MIN_SIGMAS: f32 = 4.0;
/// A rest reading whose curvature is over this many of its uncertainty from the shape the
/// controller estimated is reported, not learnt, 1 (the estimate's own uncertainty is the
/// calibration's, in [`ESTIMATE_SIGMA_SHARE`]).
pub const AGREE_SIGMAS: f32 = 3.0;
/// The uncertainty of a morph's `done` estimate, as a share of its curvature: after TUNE the
/// model misses by 3–7 % at p95 (docs/calibration.md), 2.5 % a sigma.
pub const ESTIMATE_SIGMA_SHARE: f32 = 0.025;
/// Uncertainty of the TCA thermistor's reading at rest against the anchor's, K: the bead's
/// noise averaged over a rest and its tracking of the coil in the last tenths of a kelvin.
pub const REST_TEMP_SIGMA_K: f32 = 0.03;
/// Share of the bead's remaining excess over ambient that the coil may differ from it by, 1.
pub const EXCESS_SHARE: f32 = 0.5;
/// A MEASURED's own uncertainty, mm: a caliper's reading of a bent rod's radius.
pub const MEASURED_SIGMA_MM: f32 = 0.2;
/// Uncertainty of the as-built shape the model gives, as a share of its curvature.
pub const AS_BUILT_SIGMA_SHARE: f32 = 0.03;

/// One rest at one shape: the TCA's mean resistance and its thermistor's mean reading.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rest {
    /// Mean resistance, Ω.
    pub r_ohm: f32,
    /// Variance of the mean resistance, Ω² (from the ticks' own spread).
    pub r_var_ohm2: f32,
    /// Mean TCA thermistor reading, °C.
    pub t_c: f32,
    /// What the TCA may still be over its reading's mean, K: its drift times
    /// [`REST_SETTLE_S`].
    pub excess_k: f32,
    /// The link's curvature, 1/m: known (as built or MEASURED) or the controller's estimate.
    pub shape_per_m: f32,
    /// Its variance, (1/m)².
    pub shape_var: f32,
}

/// A shape read at rest.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Reading {
    /// The radius, mm.
    pub radius_mm: f32,
    /// Its uncertainty (one sigma), mm.
    pub sigma_mm: f32,
    /// It agrees with the controller's estimate within [`AGREE_SIGMAS`]: it may act as a
    /// MEASURED, counted by [`Reading::weight`].
    pub learnable: bool,
}

impl Reading {
    /// What the reading counts as against a caliper's MEASURED (0–1]: the ratio of their
    /// variances ([`MEASURED_SIGMA_MM`] over this one's sigma, squared), so a calibration
    /// folds each by what it knows.
    pub fn weight(&self) -> f32 {
        let r = MEASURED_SIGMA_MM / self.sigma_mm;
        crate::mathf::clamp(r * r, 1e-3, 1.0)
    }
}

/// Why a rest gave no shape.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum NoShape {
    /// No current sense: the TCA's resistance is not read.
    NoSense,
    /// No gauge yet: a second known shape (a MEASURED) is needed.
    NoGauge,
    /// A gauge, but no rest at a known shape since boot: after a reset the link may be bent,
    /// not as built, so a MEASURED of a morph anchors it.
    NoAnchor,
    /// The gauge learnt is too weak against its uncertainty ([`GAUGE_MIN_SIGMAS`]): this TCA's
    /// resistance does not follow its strain.
    WeakGauge,
    /// The link did not rest within [`SHAPE_REST_MAX_S`] of `done`.
    NoRest,
}

impl NoShape {
    /// The wire word (`event: shape none reason=<word>`).
    pub fn as_str(self) -> &'static str {
        match self {
            NoShape::NoSense => "no-current-sense",
            NoShape::NoGauge => "no-gauge",
            NoShape::WeakGauge => "weak-gauge",
            NoShape::NoAnchor => "no-anchor",
            NoShape::NoRest => "no-rest",
        }
    }
}

/// What a rest at a new shape gave ([`crate::shape`]): a radius and its sigma, mm, or why
/// none (kept to 12 bytes, the size of the other events, so the queue does not grow).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShapeEvent {
    /// The radius read, mm (NaN with `none`).
    pub radius_mm: f32,
    /// Its uncertainty, mm.
    pub sigma_mm: f32,
    /// Why no shape was read, if none was.
    pub none: Option<NoShape>,
    /// The reading was folded into the calibration as a MEASURED.
    pub learnt: bool,
}

/// What a finished rest gave.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Outcome {
    /// A shape read.
    Shape(Reading),
    /// No shape, and why.
    None(NoShape),
}

/// Sums over the rest ticks being read.
#[derive(Clone, Copy, Debug, Default)]
struct Sums {
    n: u16,
    r: f32,
    r2: f32,
    t: f32,
    /// Sum of the TCA reading over the first half of the ticks, °C.
    t_first: f32,
    /// The first tick's resistance, Ω: sums are of the difference, so `f32` keeps the 1e-5
    /// a mean needs.
    r0: f32,
}

/// The rest-shape sensor's state.
#[derive(Clone, Copy, Debug, Default)]
pub struct RestShape {
    anchor: Option<Rest>,
    sums: Sums,
    /// The finished rest at the present shape, once read.
    last: Option<Rest>,
    /// Seconds at the present shape without a finished rest (the bound of [`NoShape::NoRest`]).
    waited_s: f32,
    /// The present shape's outcome has been given.
    told: bool,
    /// A gauge learnt and not yet taken ([`RestShape::take_new_gauge`]): `G` (ΔR/R per 1/m)
    /// and its variance. The calibration keeps the gauge (`Calibration::gauge`); this sensor
    /// is handed it.
    gauge_new: Option<(f32, f32)>,
    /// The present shape's reading, once read: what STATUS shows and a caliper's MEASURED of
    /// the same morph must not contradict.
    reading: Option<Reading>,
}

impl RestShape {
    /// The link's shape changed (a morph began): the rest being read is dropped.
    pub fn moved(&mut self) {
        self.sums = Sums::default();
        self.last = None;
        self.reading = None;
        self.waited_s = 0.0;
        self.told = false;
    }

    /// The TCA was driven or a fault stopped the link: a rest must start again.
    pub fn interrupted(&mut self) {
        self.sums = Sums::default();
    }

    /// One tick of `dt_s` at rest: the TCA's resistance `r_ohm` (`Err`: the board senses no
    /// current; `Ok(None)`: not read this tick), its
    /// thermistor `t_tca_c` and the ambient `t_amb_c`, the link at `shape_per_m ± sigma`
    /// (1/m; `known`: as built or MEASURED, not a morph's estimate), temperature coefficient
    /// `tcr_per_k`, the gauge learnt so far and its variance. Returns an outcome once per shape.
    pub fn note(
        &mut self,
        dt_s: f32,
        r_ohm: Result<Option<f32>, ()>,
        (t_tca_c, t_amb_c): (f32, f32),
        shape: (f32, f32, bool),
        tcr_per_k: f32,
        gauge: Option<(f32, f32)>,
    ) -> Option<Outcome> {
        if self.told {
            return None;
        }
        self.waited_s += dt_s;
        let out = match r_ohm {
            Err(()) => Some(Outcome::None(NoShape::NoSense)),
            Ok(r) => match self.sum(r, t_tca_c, t_amb_c, shape, dt_s) {
                Some(rest) => {
                    self.last = Some(rest);
                    let read = self.read(&rest, tcr_per_k, gauge);
                    if let Outcome::Shape(r) = read {
                        self.reading = Some(r);
                    }
                    if shape.2 {
                        self.learn(rest, tcr_per_k, gauge);
                    }
                    Some(read)
                }
                None if self.waited_s > SHAPE_REST_MAX_S => Some(Outcome::None(NoShape::NoRest)),
                None => None,
            },
        };
        self.told = out.is_some();
        out
    }

    /// Adds one tick to the rest being read: the rest once [`SHAPE_REST_TICKS`] in a row were
    /// near ambient and read, and the TCA's reading drifted less than [`SHAPE_REST_MAX_K_S`]
    /// between their first and second halves; otherwise the sums start again.
    fn sum(
        &mut self,
        r_ohm: Option<f32>,
        t_c: f32,
        t_amb_c: f32,
        shape: (f32, f32, bool),
        dt_s: f32,
    ) -> Option<Rest> {
        let s = &mut self.sums;
        let near = (t_c - t_amb_c).abs() <= crate::electrical::SELF_REST_MAX_K;
        let (Some(r), true, true) = (r_ohm, near, shape.0.is_finite()) else {
            *s = Sums::default();
            return None;
        };
        if s.n == 0 {
            s.r0 = r;
        }
        const HALF: u16 = SHAPE_REST_TICKS / 2;
        if s.n < HALF {
            s.t_first += t_c;
        }
        s.n += 1;
        s.r += r - s.r0;
        s.r2 += (r - s.r0) * (r - s.r0);
        s.t += t_c;
        if s.n < SHAPE_REST_TICKS {
            return None;
        }
        let sums = core::mem::take(s);
        let n = sums.n as f32;
        let half = HALF as f32;
        // The halves' means are half the ticks apart.
        let drift = (sums.t - 2.0 * sums.t_first) / half / (half * dt_s);
        if !(drift.abs() <= SHAPE_REST_MAX_K_S) {
            // Still cooling (or warming): read the next window.
            return None;
        }
        let mean = sums.r / n;
        Some(Rest {
            r_ohm: sums.r0 + mean,
            r_var_ohm2: (sums.r2 / n - mean * mean).max(0.0) / (n - 1.0),
            t_c: sums.t / n,
            excess_k: drift.abs() * REST_SETTLE_S,
            shape_per_m: shape.0,
            shape_var: shape.1 * shape.1,
        })
    }

    /// The shape of `rest` on the anchor in hand and `gauge`.
    fn read(&self, rest: &Rest, tcr_per_k: f32, gauge: Option<(f32, f32)>) -> Outcome {
        let Some((g, g_var)) = self.gauge_new.or(gauge) else {
            return Outcome::None(NoShape::NoGauge);
        };
        let Some(a) = self.anchor else {
            return Outcome::None(NoShape::NoAnchor);
        };
        if !(g * g >= GAUGE_MIN_SIGMAS * GAUGE_MIN_SIGMAS * g_var) {
            return Outcome::None(NoShape::WeakGauge);
        }
        let (dg, dg_var) = strain(&a, rest, tcr_per_k);
        let d = dg / g;
        let kappa = a.shape_per_m + d;
        // Variances in (1/m)²: the strain's, the gauge's over the distance, the anchor's.
        let var = (dg_var + d * d * g_var) / (g * g) + a.shape_var;
        let radius_mm = 1e3 / kappa;
        let apart = kappa - rest.shape_per_m;
        Outcome::Shape(Reading {
            radius_mm,
            sigma_mm: radius_mm * sqrt(var) / kappa,
            learnable: apart * apart <= AGREE_SIGMAS * AGREE_SIGMAS * (var + rest.shape_var),
        })
    }

    /// A rest at a known shape: the first is the anchor; each next one far enough from it
    /// teaches the gauge (weighted by its uncertainty, with `gauge` before it) and becomes the
    /// anchor.
    fn learn(&mut self, rest: Rest, tcr_per_k: f32, gauge: Option<(f32, f32)>) {
        let Some(a) = self.anchor else {
            self.anchor = Some(rest);
            return;
        };
        let span = rest.shape_per_m - a.shape_per_m;
        if !(span.abs() >= GAUGE_MIN_SPAN_PER_M) {
            // Too close to teach the gauge: the newer shape is the better anchor.
            self.anchor = Some(rest);
            return;
        }
        let (dg, dg_var) = strain(&a, &rest, tcr_per_k);
        let g = dg / span;
        let g_var = (dg_var + g * g * (a.shape_var + rest.shape_var)) / (span * span);
        if !(g.is_finite() && g_var > 0.0 && g_var.is_finite()) {
            return;
        }
        // Each pair's gauge weighted by its inverse variance.
        self.gauge_new = Some(match self.gauge_new.or(gauge) {
            None => (g, g_var),
            Some((g0, v0)) => (
                (g0 * g_var + g * v0) / (v0 + g_var),
                v0 * g_var / (v0 + g_var),
            ),
        });
        self.anchor = Some(rest);
    }

    /// The shape the present rest was read at turned out to be `shape_per_m` (a MEASURED):
    /// if that rest is finished it is learnt from now; if not, the caller's shape for the
    /// ticks to come says it.
    pub fn measured(&mut self, shape_per_m: f32, tcr_per_k: f32, gauge: Option<(f32, f32)>) {
        if let Some(mut rest) = self.last.take() {
            rest.shape_per_m = shape_per_m;
            let sigma = known_sigma_per_m(shape_per_m);
            rest.shape_var = sigma * sigma;
            self.learn(rest, tcr_per_k, gauge);
            self.last = Some(rest);
        }
    }

    /// The gauge (ΔR/R per 1/m) and its variance, once after each time it is learnt.
    pub fn take_new_gauge(&mut self) -> Option<(f32, f32)> {
        self.gauge_new.take()
    }

    /// The present shape's reading, if its rest has given one (none from the next morph's
    /// soften on).
    pub fn reading(&self) -> Option<Reading> {
        self.reading
    }

    /// The last rest at a known shape.
    pub fn anchor(&self) -> Option<Rest> {
        self.anchor
    }
}

/// The uncertainty of a known (MEASURED) shape of curvature `shape_per_m`, 1/m.
pub fn known_sigma_per_m(shape_per_m: f32) -> f32 {
    MEASURED_SIGMA_MM * 1e-3 * shape_per_m * shape_per_m
}

/// The uncertainty of the as-built shape the model gives, 1/m.
pub fn as_built_sigma_per_m(shape_per_m: f32) -> f32 {
    AS_BUILT_SIGMA_SHARE * shape_per_m
}

/// The estimate's uncertainty after a morph's `done` at `shape_per_m`, 1/m.
pub fn estimate_sigma_per_m(shape_per_m: f32) -> f32 {
    ESTIMATE_SIGMA_SHARE * shape_per_m
}

/// The strain term between rests `a` and `b` (`g`, ΔR/R with the temperature's share taken
/// out) and its variance.
fn strain(a: &Rest, b: &Rest, tcr_per_k: f32) -> (f32, f32) {
    let g = (b.r_ohm / a.r_ohm - 1.0) - tcr_per_k * (b.t_c - a.t_c);
    let temp = |r: &Rest| REST_TEMP_SIGMA_K + EXCESS_SHARE * r.excess_k.abs();
    let (ta, tb) = (tcr_per_k * temp(a), tcr_per_k * temp(b));
    let (ra, rb) = (
        a.r_var_ohm2 / (a.r_ohm * a.r_ohm),
        b.r_var_ohm2 / (b.r_ohm * b.r_ohm),
    );
    (g, ta * ta + tb * tb + ra + rb)
}

#[cfg(test)]
mod tests {
    use super::*;

    const TCR: f32 = 1.5e-3;
    const DT: f32 = 0.1;

    /// A TCA of gauge `g` (ΔR/R per 1/m) from 18.9 /m, at `t_c`, with ±0.2 % noise.
    fn ohm(g: f32, kappa: f32, t_c: f32, k: u32) -> f32 {
        let noise = 0.002 * ((k.wrapping_mul(2_654_435_761) >> 16) as f32 / 65536.0 - 0.5);
        6.5 * (1.0 + TCR * (t_c - 22.0) + g * (kappa - 18.9)) * (1.0 + noise)
    }

    /// A sensor and the gauge its calibration keeps.
    #[derive(Default)]
    struct Link {
        s: RestShape,
        gauge: Option<(f32, f32)>,
    }

    /// Rests `l` at `kappa` (told as `shape`) until it gives an outcome; a gauge it learns
    /// is kept, as the calibration keeps it.
    fn rest(l: &mut Link, g: f32, kappa: f32, shape: (f32, f32, bool)) -> Outcome {
        for k in 0..20_000 {
            let t = 22.0 + 0.2 * (kappa - 18.9) / 10.0;
            let r = ohm(g, kappa, t, k);
            if let Some(o) = l.s.note(DT, Ok(Some(r)), (t, 22.0), shape, TCR, l.gauge) {
                l.gauge = l.s.take_new_gauge().or(l.gauge);
                return o;
            }
        }
        panic!("no outcome");
    }

    fn read(o: Outcome) -> Reading {
        match o {
            Outcome::Shape(r) => r,
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_gauge_from_two_known_shapes_reads_a_third_within_its_sigma() {
        for g in [6e-4, -4e-4, 2e-3] {
            let mut s = Link::default();
            let built = (18.9, as_built_sigma_per_m(18.9), true);
            assert_eq!(
                rest(&mut s, g, 18.9, built),
                Outcome::None(NoShape::NoGauge)
            );
            s.s.moved();
            assert_eq!(
                rest(&mut s, g, 29.0, (29.0, known_sigma_per_m(29.0), true)),
                Outcome::None(NoShape::NoGauge)
            );
            let (learnt, var) = s.gauge.unwrap();
            assert!((learnt - g).abs() <= 3.0 * sqrt(var), "{learnt} {var} {g}");
            // A morph's estimate at 25.0 /m (40 mm), the link truly at 24.0 /m (41.7 mm).
            s.s.moved();
            let r = read(rest(
                &mut s,
                g,
                24.0,
                (25.0, estimate_sigma_per_m(25.0), false),
            ));
            let truth_mm = 1e3 / 24.0;
            assert!((r.radius_mm - truth_mm).abs() <= 3.0 * r.sigma_mm, "{r:?}");
            assert!(r.sigma_mm < 0.05 * truth_mm, "{r:?}");
            assert!(
                r.learnable && r.weight() > 0.0 && r.weight() <= 1.0,
                "{r:?}"
            );
            // The reading is not a known shape: the gauge stays as it was.
            assert_eq!(s.s.take_new_gauge(), None);
            // After a reset the sensor starts empty, the gauge kept: the link may be bent, so
            // its first rest, told as built, is not taken as the anchor; a MEASURED one is, and
            // the next rest reads.
            let mut after = Link {
                gauge: s.gauge,
                ..Link::default()
            };
            let unknown = (18.9, as_built_sigma_per_m(18.9), false);
            assert_eq!(
                rest(&mut after, g, 24.0, unknown),
                Outcome::None(NoShape::NoAnchor)
            );
            after.s.moved();
            rest(&mut after, g, 24.0, (24.0, known_sigma_per_m(24.0), true));
            after.s.moved();
            let r = read(rest(
                &mut after,
                g,
                30.0,
                (30.5, estimate_sigma_per_m(30.5), false),
            ));
            assert!(
                (r.radius_mm - 1e3 / 30.0).abs() <= 3.0 * r.sigma_mm,
                "{r:?}"
            );
        }
    }

    #[test]
    fn a_tca_without_a_strain_term_gives_no_shape_not_a_wrong_one() {
        let mut s = Link::default();
        rest(&mut s, 0.0, 18.9, (18.9, as_built_sigma_per_m(18.9), true));
        s.s.moved();
        rest(&mut s, 0.0, 29.0, (29.0, known_sigma_per_m(29.0), true));
        s.s.moved();
        let o = rest(&mut s, 0.0, 24.0, (25.0, estimate_sigma_per_m(25.0), false));
        assert_eq!(o, Outcome::None(NoShape::WeakGauge));
    }

    #[test]
    fn no_sense_and_no_rest_are_said_once_and_a_reading_far_from_the_estimate_is_not_learnt() {
        let mut s = RestShape::default();
        let shape = (25.0, estimate_sigma_per_m(25.0), false);
        assert_eq!(
            s.note(DT, Err(()), (22.0, 22.0), shape, TCR, None),
            Some(Outcome::None(NoShape::NoSense))
        );
        assert_eq!(s.note(DT, Err(()), (22.0, 22.0), shape, TCR, None), None);
        // A TCA that keeps drifting 0.009 K/s (within the beads' kelvin of ambient) never rests.
        s.moved();
        let mut got = None;
        for k in 0..((SHAPE_REST_MAX_S / DT) as u32 + 2 * SHAPE_REST_TICKS as u32) {
            let t = 21.5 + 0.009 * (k % 1000) as f32 * DT;
            if let Some(o) = s.note(DT, Ok(Some(6.5)), (t, 22.0), shape, TCR, None) {
                got = Some((k, o));
                break;
            }
        }
        let (k, o) = got.unwrap();
        assert_eq!(o, Outcome::None(NoShape::NoRest));
        assert!(k as f32 * DT >= SHAPE_REST_MAX_S, "{k}");
        // With a gauge, a reading five sigmas from the estimate is reported, not learnt.
        let g = 6e-4;
        let mut s = Link::default();
        rest(&mut s, g, 18.9, (18.9, as_built_sigma_per_m(18.9), true));
        s.s.moved();
        rest(&mut s, g, 29.0, (29.0, known_sigma_per_m(29.0), true));
        s.s.moved();
        let r = read(rest(&mut s, g, 21.0, (28.0, 0.1, false)));
        assert!(!r.learnable, "{r:?}");
    }
}

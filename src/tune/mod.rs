//! `TUNE`: the thermal autotune. A bounded test heats each heater in turn and fits, from this
//! link's own thermistors, the steady rise per watt each one shows of its heater, their time
//! constants and the PLA-to-TCA coupling ([`crate::calibration::Calibration`]'s thermal fields).
//!
//! Steps (each a [`TuneStep`]): `settle` (heaters off, the baseline), `tca` ([`TUNE_TCA_W`] for
//! [`TUNE_TCA_S`]), `cool` (heaters off, [`TUNE_COOL_S`]), `pla` ([`TUNE_PLA_W`] for
//! [`TUNE_PLA_S`]). Bounded in power (both well under the heater caps), temperature (a step ends
//! early once its thermistor has risen [`TUNE_MAX_RISE_K`]) and time ([`TUNE_TOTAL_S`], under 3
//! minutes). It runs through `Controller::step` under the supervisor, every check active: the
//! powers are at least the share of the caps the heater-not-heating check judges, so a dead
//! heater trips it as in a morph, and ABORT or any trip ends the tune with both heaters off and
//! the calibration as it was.
//!
//! **Still air.** The PLA's step rising to its cap before [`TUNE_EARLY_CAP_SHARE`] of its
//! length is still air: the same watt rises about five times as far, over minutes. The tune
//! then ends `done` with the model at its still-air convection ([`TUNE_STILL_AIR_W_M2K`]) and
//! the still-air model's own rises and couplings (`event: tune still-air ...`): records capped
//! within seconds of a response minutes long say how fast the heaters warm, not how far, and
//! shares fitted to them made the high-fidelity still-air links worse after calibration than
//! the model's own (`docs/calibration.md`). The time constants stay as they were. A tune
//! whose steps end as under water sets the link file's convection (still water) back.
//!
//! Every fitted value is checked for sign and bounds before use (Marlin #27181: a negative
//! constant ran a heater away): its share of the model's own rise at the convection it is
//! read against ([`crate::calibration::RISE_MIN_SHARE`]..[`crate::calibration::RISE_MAX_SHARE`],
//! a coupling up to twice the top share), inside the ranges of
//! [`crate::calibration::FIELDS`]. The asymptotic
//! fit comes first; where it fails or is out of bounds the least-squares fit is tried
//! ([`fit`]); where both fail the tune fails, says why and keeps the old values. Only the
//! coupling may fail alone: it is then kept and the tune still ends `done`.

pub mod fit;

use crate::calibration::{Calibration, FieldInfo, FIELDS, SHARE_RULE, TAU_RANGE_S};
use crate::heater::HeaterConfig;
use crate::link::{CONVECTION_RANGE_W_M2K, LINK};
use crate::lumped::ResistanceMatrix;
use crate::vocab::{Heater, Measurements, Powers};
use fit::{Method, StepFit};

/// Heaters off before the first step, s: the baseline is the mean over it.
pub const TUNE_SETTLE_S: f32 = 5.0;
/// TCA power of its step, W: 0.6 W rises the TCA about 20 K in water (the table's middle),
/// and is 1.5 times the share of the cap the heater-not-heating check judges, so the check
/// runs.
pub const TUNE_TCA_W: f32 = 0.6;
/// Length of the TCA step, s: about four of its thermistor's time constants.
pub const TUNE_TCA_S: f32 = 45.0;
/// Heaters off between the steps, s: the TCA falls back within a few kelvin.
pub const TUNE_COOL_S: f32 = 30.0;
/// PLA power of its step, W: the least the heater-not-heating check judges (20 % of the 5 W
/// cap), about 30 K of rise in water: under the glass transition in all but the warmest
/// water.
pub const TUNE_PLA_W: f32 = 1.0;
/// What a tune holds of the supply while it runs, W: each step's power, both together (a
/// shared budget keeps them for it from its first tick, `Controller::reserve_w`).
pub const TUNE_STEP_POWERS: Powers = Powers {
    pla_w: TUNE_PLA_W,
    tca_w: TUNE_TCA_W,
};

/// Length of the PLA step, s: about three of its thermistor's time constants.
pub const TUNE_PLA_S: f32 = 90.0;
/// A heated step ends early once its thermistor has risen this far above the baseline, K
/// (PLA, TCA): in still air the same powers rise five times as much; the tune then stays
/// 60 K under the supervisor's limits and its fit fails on the bounds, as it should.
pub const TUNE_MAX_RISE_K: [f32; 2] = [32.0, 40.0];
/// A step capped by [`TUNE_MAX_RISE_K`] before this share of its length fails the tune: in
/// water the thermistors rise about a third of the cap per time constant, so reaching it this
/// early is still air (five times the rise), where the model strategies' thermal model does not
/// hold and a fit of the short record would still pass the bounds.
pub const TUNE_EARLY_CAP_SHARE: f32 = 0.6;
/// `TUNE` starts only from a link at rest: PLA and TCA within this of the ambient, K (a warm
/// link cooling during the test would read as a weaker heater).
pub const TUNE_START_MAX_RISE_K: f32 = 3.0;
/// Most a fit's steady rise may exceed the rise its record ended at, as a factor: 1.6 is a
/// record about one time constant long (63 % of the way). A slow coupling seen over a shorter
/// record is an extrapolation (a 45 s record read as a 120 s time constant triples its rise)
/// that the observer would take as heat the link has; such a fit is rejected. The heaters'
/// own records end at 85 % or more of their rise under water, well inside the bound.
pub const TUNE_MAX_EXTRAPOLATION: f32 = 1.6;
const _: () = assert!(TUNE_MAX_EXTRAPOLATION > 1.0 && TUNE_MAX_EXTRAPOLATION <= 2.0);
/// Rim convection a tune that finds still air sets, W/(m² K): the model's still-air value
/// (`morphlink_model::params::H_AIR_W_M2K`).
pub const TUNE_STILL_AIR_W_M2K: f32 = morphlink_model::params::H_AIR_W_M2K as f32;
const _: () = assert!(
    TUNE_STILL_AIR_W_M2K >= CONVECTION_RANGE_W_M2K.0
        && TUNE_STILL_AIR_W_M2K <= CONVECTION_RANGE_W_M2K.1
);
/// Heaters off after the PLA step before the result counts, s: well past the time the
/// supervisor's residual tests name a heater stuck on (`supervisor::HEATER_VERDICT_S`), so one
/// stuck through the tune trips before its record is taken as the link's; only then `tune done`.
pub const TUNE_VERIFY_S: f32 = crate::supervisor::HEATER_VERDICT_S + 8.0;
/// Most the ambient thermistor may move from its baseline (1 s means) during a tune, K: a
/// still bath stays within a few tenths; a bath that moves by more adds its step to every
/// rise fitted.
pub const TUNE_AMB_MAX_MOVE_K: f32 = 1.0;
/// The least time the PLA's step can take to reach its cap, s: the model's PLA node, which
/// reads the whole rod, needs 33.7 s at [`TUNE_PLA_W`] to rise [`TUNE_MAX_RISE_K`] in the
/// weakest convection allowed (10 W/(m² K)); a bead reads less and later. Half of it leaves
/// room for a hotter heater (+10 %) and a bead on the wrap; a stuck MOSFET at 12 V (14 W)
/// gets there in about 3 s.
pub const TUNE_PLA_FASTEST_CAP_S: f32 = 17.0;
/// The residual a fit may leave whatever the rise, K: the one-second means' noise (at most
/// 0.2 K per reading, ten readings a mean) with a margin.
pub const TUNE_MAX_RESIDUAL_K: f32 = 0.3;
/// The residual a fit may leave per kelvin of the rise its record ended at, 1: 1.4 times what
/// the first-order fit leaves of the model's own PLA step (a five-node response, 0.056 of its
/// rise; `the_models_own_step_leaves_a_residual_under_the_bound`). A PLA thermistor drifting
/// 0.05 K/s through the PLA step leaves about 0.1 on the nominal high-fidelity link; a healthy
/// one 0.03.
pub const TUNE_MAX_RESIDUAL_SHARE: f32 = 0.08;
const _: () = assert!(TUNE_MAX_RESIDUAL_K >= 0.0 && TUNE_MAX_RESIDUAL_SHARE < 0.5);
/// Samples at the end of a record whose mean is the rise it ended at.
pub const TUNE_END_SAMPLES: usize = 3;
const _: () = assert!(TUNE_END_SAMPLES >= 1 && TUNE_END_SAMPLES <= fit::MIN_SAMPLES);
/// Sample period of the fit's record, s (each sample the mean of this second's ticks).
pub const TUNE_SAMPLE_S: f32 = 1.0;
/// Samples a step can hold (the longer step).
pub const TUNE_MAX_SAMPLES: usize = 90;
/// Where the cool step's window for the TCA's temperature coefficient starts, s after the TCA
/// heater went off: by then the TCA, with no heat of its own, and its bead beside it read
/// nearly one temperature, once the bead's own lag is taken off (it reads a falling TCA
/// high by its lag times the rate of fall: [`SENSOR_TAU_S`]), so the resistance's rise over
/// the bead's rise is the coefficient, whatever the thermal model says.
pub const TUNE_TCR_COOL_FROM_S: f32 = 8.0;
/// The thermistor lag the controller assumes, s: the observer's own
/// (`strategy::model::observer::SENSOR_TAU_S`, held equal there).
pub const SENSOR_TAU_S: f32 = 3.0;
/// Least mean rise of the TCA's thermistor over that window for the coefficient to be fitted,
/// K: below it the resistance's noise (about 0.3 K's worth a tick) would dominate.
pub const TUNE_TCR_MIN_RISE_K: f32 = 2.0;
/// Whole test, s.
pub const TUNE_TOTAL_S: f32 = TUNE_SETTLE_S + TUNE_TCA_S + TUNE_COOL_S + TUNE_PLA_S + TUNE_VERIFY_S;
// About 3 minutes under water, and each step's record fits.
const _: () = assert!(TUNE_TOTAL_S <= 200.0);
const _: () = assert!(TUNE_PLA_S / TUNE_SAMPLE_S <= TUNE_MAX_SAMPLES as f32);
const _: () = assert!(TUNE_TCA_S / TUNE_SAMPLE_S <= TUNE_MAX_SAMPLES as f32);
// Both steps lift their beads well clear of the noise, and stay well under the caps.
const _: () = assert!(TUNE_PLA_W >= 0.2 * HeaterConfig::PLA.max_power_w);
const _: () = assert!(TUNE_TCA_W >= 0.2 * HeaterConfig::TCA.max_power_w);
const _: () = assert!(TUNE_PLA_W <= 0.5 * HeaterConfig::PLA.max_power_w);
const _: () = assert!(TUNE_TCA_W <= 0.5 * HeaterConfig::TCA.max_power_w);

/// The test's steps.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TuneStep {
    /// Heaters off; the baseline.
    Settle,
    /// TCA heated.
    Tca,
    /// Heaters off.
    Cool,
    /// PLA heated.
    Pla,
    /// Heaters off until the result counts ([`TUNE_VERIFY_S`]).
    Verify,
}

impl TuneStep {
    /// Wire name.
    pub fn as_str(self) -> &'static str {
        match self {
            TuneStep::Settle => "settle",
            TuneStep::Tca => "tca",
            TuneStep::Cool => "cool",
            TuneStep::Pla => "pla",
            TuneStep::Verify => "verify",
        }
    }

    fn length_s(self) -> f32 {
        match self {
            TuneStep::Settle => TUNE_SETTLE_S,
            TuneStep::Tca => TUNE_TCA_S,
            TuneStep::Cool => TUNE_COOL_S,
            TuneStep::Pla => TUNE_PLA_S,
            TuneStep::Verify => TUNE_VERIFY_S,
        }
    }

    fn powers(self) -> Powers {
        match self {
            TuneStep::Tca => Powers {
                pla_w: 0.0,
                tca_w: TUNE_TCA_W,
            },
            TuneStep::Pla => Powers {
                pla_w: TUNE_PLA_W,
                tca_w: 0.0,
            },
            _ => Powers::default(),
        }
    }
}

/// What was fitted, per quantity.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Fitted {
    /// A heater's own thermistor: rise per watt and time constant.
    Own(Heater),
    /// The TCA thermistor's rise per PLA watt.
    PlaToTca,
    /// The PLA thermistor's rise per TCA watt.
    TcaToPla,
}

impl Fitted {
    /// Wire name.
    pub fn as_str(self) -> &'static str {
        match self {
            Fitted::Own(h) => h.as_str(),
            Fitted::PlaToTca => "pla_to_tca",
            Fitted::TcaToPla => "tca_to_pla",
        }
    }
}

/// Why a fit was not used.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Rejection {
    /// Neither method found a rising, slowing record.
    NoFit,
    /// The fit's value is outside its field's range (the field and the value).
    OutOfBounds(FieldInfo, f32),
    /// The fit's steady rise is more than [`TUNE_MAX_EXTRAPOLATION`] times the rise its
    /// record ended at (fitted, seen; K): the record is too short for its time constant.
    Extrapolated(f32, f32),
    /// The record strays from its own fitted step by more than a first-order response may
    /// (residual, allowed; K): [`TUNE_MAX_RESIDUAL_K`], [`TUNE_MAX_RESIDUAL_SHARE`].
    Residual(f32, f32),
}

/// Why a tune ended without `done`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TuneFailure {
    /// ABORT.
    Aborted,
    /// A safety trip (its alarm says which).
    Tripped,
    /// A fit failed on both methods.
    Fit(Fitted, Rejection),
    /// The TCA's step reached [`TUNE_MAX_RISE_K`] before [`TUNE_EARLY_CAP_SHARE`] of its
    /// length (its rise, K): far faster than in water, and in still air the TCA rises slower
    /// still (a PLA step that does so is still air, [`TuneEvent::StillAir`]).
    TcaTooFast(f32),
    /// The PLA's step reached its cap in this many seconds, sooner than
    /// [`TUNE_PLA_FASTEST_CAP_S`]: faster than its power can heat the rod even in still air (a
    /// MOSFET stuck on, a heater of the wrong resistance).
    PlaTooFast(f32),
    /// The ambient thermistor moved this far from its baseline during the tune, K (more than
    /// [`TUNE_AMB_MAX_MOVE_K`]): a bath that warmed or cooled reads as heater rise.
    AmbientMoved(f32),
}

/// The highest PLA reading the model strategies let soften reach, °C: their PLA target plus
/// their thermistor guard (`strategy::model::PLA_SOFT_TARGET_C + MODEL_GUARD_K`, held equal
/// there at compile time; named here so the tune needs nothing of the strategies).
pub const TUNE_SOFTEN_READING_MAX_C: f32 = 85.0;
/// The estimate at which soften ends, °C (`strategy::SOFT_THRESHOLD_C`, held equal there).
pub const TUNE_SOFT_THRESHOLD_C: f32 = 70.0;

/// The most of the water model's rise per watt a PLA thermistor may read for the model
/// strategies to call the rod soft at `ambient_c` (°C) on water's model: their observer takes
/// the rod's rise as the reading's over that share, and their guard holds the reading at most
/// [`TUNE_SOFTEN_READING_MAX_C`], so over this share the estimate never reaches
/// [`TUNE_SOFT_THRESHOLD_C`]. A step that reads over it is not water: the tune takes it as
/// still air, as one that reached its cap early (docs/calibration.md, "Draw 1").
pub fn pla_share_softens(ambient_c: f32) -> f32 {
    (TUNE_SOFTEN_READING_MAX_C - ambient_c) / (TUNE_SOFT_THRESHOLD_C - ambient_c)
}

/// Progress of a tune, for `event: tune ...` lines.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TuneEvent {
    /// A step began, `t_s` after TUNE.
    Step {
        /// The step.
        step: TuneStep,
        /// Since TUNE, s.
        t_s: f32,
        /// The heated heater's power, W (0 for settle and cool).
        power_w: f32,
    },
    /// The PLA's step rose `rise_k` in `t_s`, far faster than in water (to its cap early, or
    /// over what water's model lets a bead that shows a soft rod read,
    /// [`pla_share_softens`]): still air, whose model is used from now on.
    StillAir {
        /// The PLA thermistor's rise when its step ended (cut at its cap, or at its end), K.
        rise_k: f32,
        /// Into the step when it ended, s.
        t_s: f32,
    },
    /// A value was fitted and passed its checks.
    Fit {
        /// What.
        what: Fitted,
        /// Steady rise per watt, K/W.
        rise_k_per_w: f32,
        /// Time constant, s.
        tau_s: f32,
        /// Method that gave it.
        method: Method,
        /// The record's RMS residual about the fit (its last two thirds), K.
        residual_k: f32,
    },
    /// A fit was rejected and its old value kept (the coupling only; the others fail).
    Kept {
        /// What.
        what: Fitted,
        /// Why.
        why: Rejection,
    },
    /// The tune finished; the fitted values are in use.
    Done(Calibration),
    /// The tune ended without a result; the calibration is as it was.
    Failed(TuneFailure),
}

/// What a tune tick asks of the controller.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum TuneTick {
    /// Heat with these powers.
    Run(Powers),
    /// Finished: use this calibration.
    Done(Calibration),
    /// Failed: keep the old calibration.
    Failed(TuneFailure),
}

/// A running tune.
#[derive(Clone, Copy, Debug)]
pub struct Tune {
    start_ms: u64,
    step: TuneStep,
    step_ms: u64,
    /// Baseline (PLA, TCA) and its sample count (the settle step's mean).
    base_c: [f32; 2],
    base_n: u32,
    /// This second's sum (own, other sensor) and count.
    acc: [f32; 2],
    acc_n: u32,
    acc_ms: u64,
    /// The heated step's record: own sensor's rise, other sensor's rise.
    rec: [[f32; TUNE_MAX_SAMPLES]; 2],
    n: usize,
    /// The TCA's fit and its rise as its step ended (for the tail subtracted from the
    /// coupling record).
    tca_fit: Option<StepFit>,
    tca_end_rise_k: f32,
    tca_off_ms: u64,
    /// The TCA fit's rejection when its record was too short for its time constant: final
    /// unless the PLA step finds still air.
    tca_deferred: Option<Rejection>,
    /// The PLA's step reached its cap early: its rise (K) and when (s into the step).
    capped_early: Option<(f32, f32)>,
    /// The calibration being built (the old one until each value passes).
    cal: Calibration,
    /// The ambient baseline (the settle step's mean; a sum until it ends), °C, and this
    /// second's ambient sum and count.
    base_amb_c: f32,
    amb_acc: f32,
    amb_n: u32,
    amb_ms: u64,
    /// Fitted and waiting out [`TuneStep::Verify`].
    fitted: bool,
    /// Sums of the TCA's resistance rise `R/R₀ − 1` and its thermistor's rise (K) over the
    /// cool step from [`TUNE_TCR_COOL_FROM_S`], and their count (current sense only).
    cool_ratio_sum: f32,
    cool_rise_sum: f32,
    cool_n: u32,
    /// The window's first and last thermistor rise (K) and their times (ms): the lag's share.
    cool_first: (f32, u64),
    cool_last: (f32, u64),
}

fn field(name: &str) -> FieldInfo {
    let mut i = 0;
    while i < FIELDS.len() {
        if FIELDS[i].name.as_bytes() == name.as_bytes() {
            return FIELDS[i];
        }
        i += 1;
    }
    FIELDS[0]
}

/// Checks a value against its field's range (sign included: every range is positive).
fn bounded(info: FieldInfo, v: f32) -> Result<f32, Rejection> {
    if v >= info.min && v <= info.max {
        Ok(v)
    } else {
        Err(Rejection::OutOfBounds(info, v))
    }
}

/// The rise field of `what`, with the range a tune judges it by against the model's rises
/// `r` (K/W): a thermistor's own rise [`RISE_MIN_SHARE`]..[`RISE_MAX_SHARE`] of the model's,
/// a coupling up to twice the top share; never wider than the field's own range.
fn judged(what: Fitted, r: &ResistanceMatrix) -> FieldInfo {
    // The rule CONFIG SET is held to as well (`calibration::SHARE_RULE`, by field index).
    let (k, model) = match what {
        Fitted::Own(Heater::Pla) => (0, r.r_pp),
        Fitted::Own(Heater::Tca) => (1, r.r_tt),
        Fitted::PlaToTca => (2, r.r_tp),
        Fitted::TcaToPla => (3, r.r_tp),
    };
    let (i, (lo, hi)) = SHARE_RULE[k];
    let (model, f) = (model, FIELDS[i]);
    FieldInfo {
        min: (lo * model).max(f.min),
        max: (hi * model).min(f.max),
        ..f
    }
}

/// The model's rises at the link file's convection (still water), K/W.
fn water() -> ResistanceMatrix {
    crate::calibration::WATER_RESISTANCES
}

/// Fits a record of `power_w` into (rise per watt, tau) within the range [`judged`] gives
/// `what` against the model's rises `r` (and, for a heater's own thermistor, its time
/// constant's field): the asymptotic method first, least squares where it fails or is out of
/// bounds.
fn fit_checked(
    y: &[f32],
    power_w: f32,
    what: Fitted,
    r: &ResistanceMatrix,
) -> Result<(f32, f32, Method, f32), Rejection> {
    let tau_field = match what {
        Fitted::Own(Heater::Pla) => Some("pla_tau_s"),
        Fitted::Own(Heater::Tca) => Some("tca_tau_s"),
        _ => None,
    };
    let end_k = if y.len() >= TUNE_END_SAMPLES {
        let tail = &y[y.len() - TUNE_END_SAMPLES..];
        tail.iter().sum::<f32>() / TUNE_END_SAMPLES as f32
    } else {
        0.0
    };
    // A record that did not end risen (too short, flat or falling) has no fit to judge.
    if !(end_k > 0.0) {
        return Err(Rejection::NoFit);
    }
    let check = |f: StepFit| -> Result<(f32, f32, Method, f32), Rejection> {
        if !(f.rise_k <= TUNE_MAX_EXTRAPOLATION * end_k) {
            return Err(Rejection::Extrapolated(f.rise_k, end_k));
        }
        // A record a first-order step does not describe (a drifting bead, a bath that moved)
        // is no measurement of this link's rise.
        let res_k = fit::residual_rms_k(y, TUNE_SAMPLE_S, &f);
        let allowed_k = TUNE_MAX_RESIDUAL_K + TUNE_MAX_RESIDUAL_SHARE * end_k;
        if !(res_k <= allowed_k) {
            return Err(Rejection::Residual(res_k, allowed_k));
        }
        let r = bounded(judged(what, r), f.rise_k / power_w)?;
        let t = match tau_field {
            Some(name) => bounded(field(name), f.tau_s)?,
            None => f.tau_s,
        };
        Ok((r, t, f.method, res_k))
    };
    let first = fit::asymptotic(y, TUNE_SAMPLE_S)
        .ok_or(Rejection::NoFit)
        .and_then(check);
    match first {
        Ok(v) => Ok(v),
        Err(why) => match fit::least_squares(y, TUNE_SAMPLE_S, TAU_RANGE_S) {
            Some(f) => check(f),
            None => Err(why),
        },
    }
}

fn since_s(now_ms: u64, then_ms: u64) -> f32 {
    now_ms.saturating_sub(then_ms) as f32 / 1000.0
}

impl Tune {
    /// A tune starting at `now_ms` from the calibration `cal` (kept where a fit fails).
    pub fn new(now_ms: u64, cal: Calibration, emit: &mut dyn FnMut(TuneEvent)) -> Self {
        let t = Tune {
            start_ms: now_ms,
            step: TuneStep::Settle,
            step_ms: now_ms,
            base_c: [0.0; 2],
            base_n: 0,
            acc: [0.0; 2],
            acc_n: 0,
            acc_ms: now_ms,
            rec: [[0.0; TUNE_MAX_SAMPLES]; 2],
            n: 0,
            tca_fit: None,
            tca_end_rise_k: 0.0,
            tca_off_ms: now_ms,
            tca_deferred: None,
            capped_early: None,
            cal,
            base_amb_c: 0.0,
            amb_acc: 0.0,
            amb_n: 0,
            amb_ms: now_ms,
            fitted: false,
            cool_ratio_sum: 0.0,
            cool_rise_sum: 0.0,
            cool_n: 0,
            cool_first: (0.0, 0),
            cool_last: (0.0, 0),
        };
        emit(TuneEvent::Step {
            step: TuneStep::Settle,
            t_s: 0.0,
            power_w: 0.0,
        });
        t
    }

    /// The step under way.
    pub fn step_now(&self) -> TuneStep {
        self.step
    }

    fn enter(&mut self, step: TuneStep, now_ms: u64, emit: &mut dyn FnMut(TuneEvent)) {
        self.step = step;
        self.step_ms = now_ms;
        self.n = 0;
        self.acc = [0.0; 2];
        self.acc_n = 0;
        self.acc_ms = now_ms;
        let p = step.powers();
        emit(TuneEvent::Step {
            step,
            t_s: since_s(now_ms, self.start_ms),
            power_w: p.pla_w + p.tca_w,
        });
    }

    /// Feeds this tick's ambient reading; after the settle step, each second's mean that lies
    /// more than [`TUNE_AMB_MAX_MOVE_K`] from the baseline is returned (how far, K).
    fn ambient_moved(&mut self, now_ms: u64, amb_c: f32) -> Option<f32> {
        if self.step == TuneStep::Settle {
            self.amb_ms = now_ms;
            return None;
        }
        self.amb_acc += amb_c;
        self.amb_n += 1;
        if since_s(now_ms, self.amb_ms) < TUNE_SAMPLE_S {
            return None;
        }
        let mean_c = self.amb_acc / self.amb_n.max(1) as f32;
        self.amb_acc = 0.0;
        self.amb_n = 0;
        self.amb_ms = now_ms;
        let moved_k = mean_c - self.base_amb_c;
        (!(moved_k.abs() <= TUNE_AMB_MAX_MOVE_K)).then_some(moved_k)
    }

    /// The TCA's own tail after its step, K above its baseline, `now_ms`.
    fn tca_tail_k(&self, now_ms: u64) -> f32 {
        match self.tca_fit {
            Some(f) if f.tau_s > 0.0 => {
                self.tca_end_rise_k * crate::mathf::exp(-since_s(now_ms, self.tca_off_ms) / f.tau_s)
            }
            _ => 0.0,
        }
    }

    /// One control tick with the supervisor's measurements `m` and, where current is sensed,
    /// the TCA's resistance over its value at rest before the tune (`tca_ratio`, 1).
    pub fn tick(
        &mut self,
        now_ms: u64,
        m: &Measurements,
        tca_ratio: Option<f32>,
        emit: &mut dyn FnMut(TuneEvent),
    ) -> TuneTick {
        let (pla, tca) = (m.t_pla_c, m.t_tca_c);
        let cooling =
            self.step == TuneStep::Cool && since_s(now_ms, self.step_ms) >= TUNE_TCR_COOL_FROM_S;
        if let (true, Some(r)) = (cooling, tca_ratio.filter(|r| r.is_finite())) {
            let rise = tca - self.base_c[1];
            if self.cool_n == 0 {
                self.cool_first = (rise, now_ms);
            }
            self.cool_last = (rise, now_ms);
            self.cool_ratio_sum += r - 1.0;
            self.cool_rise_sum += rise;
            self.cool_n += 1;
        }
        match self.step {
            TuneStep::Settle => {
                self.base_c[0] += pla;
                self.base_c[1] += tca;
                self.base_amb_c += m.t_amb_c;
                self.base_n += 1;
            }
            TuneStep::Tca | TuneStep::Pla => {
                let (own, other) = if self.step == TuneStep::Tca {
                    (tca - self.base_c[1], pla - self.base_c[0])
                } else {
                    (
                        pla - self.base_c[0],
                        tca - self.base_c[1] - self.tca_tail_k(now_ms),
                    )
                };
                self.acc[0] += own;
                self.acc[1] += other;
                self.acc_n += 1;
                if since_s(now_ms, self.acc_ms) >= TUNE_SAMPLE_S && self.n < TUNE_MAX_SAMPLES {
                    let k = self.acc_n.max(1) as f32;
                    self.rec[0][self.n] = self.acc[0] / k;
                    self.rec[1][self.n] = self.acc[1] / k;
                    self.n += 1;
                    self.acc = [0.0; 2];
                    self.acc_n = 0;
                    self.acc_ms = now_ms;
                }
            }
            TuneStep::Cool | TuneStep::Verify => {}
        }
        if let Some(moved_k) = self.ambient_moved(now_ms, m.t_amb_c) {
            return self.fail(TuneFailure::AmbientMoved(moved_k), emit);
        }
        let in_step_s = since_s(now_ms, self.step_ms);
        let capped = match self.step {
            TuneStep::Tca => tca - self.base_c[1] >= TUNE_MAX_RISE_K[1],
            TuneStep::Pla => pla - self.base_c[0] >= TUNE_MAX_RISE_K[0],
            _ => false,
        };
        if capped && in_step_s < TUNE_EARLY_CAP_SHARE * self.step.length_s() {
            if self.step == TuneStep::Pla {
                // Faster than still air allows: the heater gives more than its power.
                if in_step_s < TUNE_PLA_FASTEST_CAP_S {
                    return self.fail(TuneFailure::PlaTooFast(in_step_s), emit);
                }
                // Still air: the step ends here and `finish` takes its model.
                self.capped_early = Some((pla - self.base_c[0], in_step_s));
            } else {
                return self.fail(TuneFailure::TcaTooFast(tca - self.base_c[1]), emit);
            }
        }
        if in_step_s + 1e-3 >= self.step.length_s() || capped || self.n >= TUNE_MAX_SAMPLES {
            match self.step {
                TuneStep::Settle => {
                    let k = self.base_n.max(1) as f32;
                    self.base_c = [self.base_c[0] / k, self.base_c[1] / k];
                    self.base_amb_c /= k;
                    self.enter(TuneStep::Tca, now_ms, emit);
                }
                TuneStep::Tca => {
                    let y = &self.rec[0][..self.n];
                    match fit_checked(y, TUNE_TCA_W, Fitted::Own(Heater::Tca), &water()) {
                        Ok((r, tau, method, residual_k)) => {
                            self.cal.tca_rise_k_per_w = r;
                            self.cal.tca_tau_s = tau;
                            self.tca_fit = Some(StepFit {
                                rise_k: r * TUNE_TCA_W,
                                tau_s: tau,
                                method,
                            });
                            self.tca_end_rise_k = tca - self.base_c[1];
                            self.tca_off_ms = now_ms;
                            emit(TuneEvent::Fit {
                                what: Fitted::Own(Heater::Tca),
                                rise_k_per_w: r,
                                tau_s: tau,
                                method,
                                residual_k,
                            });
                        }
                        // Too short for its time constant: still air, if the PLA's step shows it.
                        Err(why @ Rejection::Extrapolated(..)) => self.tca_deferred = Some(why),
                        Err(why) => {
                            return self.fail(TuneFailure::Fit(Fitted::Own(Heater::Tca), why), emit)
                        }
                    }
                    let c = &self.rec[1][..self.n];
                    match fit_checked(c, TUNE_TCA_W, Fitted::TcaToPla, &water()) {
                        Ok((r, tau, method, residual_k)) => {
                            self.cal.tca_to_pla_k_per_w = r;
                            emit(TuneEvent::Fit {
                                what: Fitted::TcaToPla,
                                rise_k_per_w: r,
                                tau_s: tau,
                                method,
                                residual_k,
                            });
                        }
                        Err(why) => emit(TuneEvent::Kept {
                            what: Fitted::TcaToPla,
                            why,
                        }),
                    }
                    self.enter(TuneStep::Cool, now_ms, emit);
                }
                TuneStep::Cool => self.enter(TuneStep::Pla, now_ms, emit),
                TuneStep::Pla => return self.finish(now_ms, emit),
                TuneStep::Verify => {
                    emit(TuneEvent::Done(self.cal));
                    return TuneTick::Done(self.cal);
                }
            }
        }
        TuneTick::Run(self.step.powers())
    }

    fn fail(&self, why: TuneFailure, emit: &mut dyn FnMut(TuneEvent)) -> TuneTick {
        emit(TuneEvent::Failed(why));
        TuneTick::Failed(why)
    }

    fn finish(&mut self, now_ms: u64, emit: &mut dyn FnMut(TuneEvent)) -> TuneTick {
        let y = &self.rec[0][..self.n];
        let pla = fit_checked(y, TUNE_PLA_W, Fitted::Own(Heater::Pla), &water());
        // Faster than water lets it rise: to its cap early, or higher than water's model lets
        // a bead that still shows a soft rod read (docs/calibration.md, "Draw 1").
        let over = |(r, ..): (f32, f32, Method, f32)| {
            let t_s = self.n as f32 * TUNE_SAMPLE_S;
            let share = r / water().r_pp;
            (!(share <= pla_share_softens(self.base_amb_c))).then(|| (y[self.n - 1], t_s))
        };
        if let Some((rise_k, t_s)) = self.capped_early.or_else(|| pla.ok().and_then(over)) {
            return self.finish_still_air(now_ms, rise_k, t_s, emit);
        }
        if let Some(why) = self.tca_deferred {
            return self.fail(TuneFailure::Fit(Fitted::Own(Heater::Tca), why), emit);
        }
        self.cal.convection_w_m2k = LINK.surroundings.h_w_m2k as f32;
        match pla {
            Ok((r, tau, method, residual_k)) => {
                self.cal.pla_rise_k_per_w = r;
                self.cal.pla_tau_s = tau;
                emit(TuneEvent::Fit {
                    what: Fitted::Own(Heater::Pla),
                    rise_k_per_w: r,
                    tau_s: tau,
                    method,
                    residual_k,
                });
            }
            Err(why) => return self.fail(TuneFailure::Fit(Fitted::Own(Heater::Pla), why), emit),
        }
        let c = &self.rec[1][..self.n];
        match fit_checked(c, TUNE_PLA_W, Fitted::PlaToTca, &water()) {
            Ok((r, tau, method, residual_k)) => {
                self.cal.pla_to_tca_k_per_w = r;
                emit(TuneEvent::Fit {
                    what: Fitted::PlaToTca,
                    rise_k_per_w: r,
                    tau_s: tau,
                    method,
                    residual_k,
                });
            }
            Err(why) => emit(TuneEvent::Kept {
                what: Fitted::PlaToTca,
                why,
            }),
        }
        self.fit_tcr();
        self.fitted = true;
        self.enter(TuneStep::Verify, now_ms, emit);
        TuneTick::Run(Powers::default())
    }

    /// The TCA's temperature coefficient: its resistance's rise over its thermistor's rise
    /// while it cools after its step (heater off, so the two read nearly one temperature), the
    /// coefficient in [`Calibration::tca_tcr_ppm_per_k`] where current was sensed, the rise
    /// was large enough and the value is in its range; else the old one stays. The PLA is
    /// rigid through the TCA's step and its cooling, so the link barely bends and the coil's
    /// strain term stays small.
    fn fit_tcr(&mut self) {
        let n = self.cool_n as f32;
        if !(self.cool_rise_sum >= TUNE_TCR_MIN_RISE_K * n) || self.cool_n < 2 {
            return;
        }
        // The bead's lag taken off each reading, summed: τ·Σ ḃ = τ·(b_last − b_first)/Δt.
        let span_s = since_s(self.cool_last.1, self.cool_first.1);
        let lag_k = SENSOR_TAU_S * (self.cool_last.0 - self.cool_first.0) * (n - 1.0) / span_s;
        let ppm = self.cool_ratio_sum / (self.cool_rise_sum + lag_k) * 1e6;
        if let Ok(v) = bounded(field("tca_tcr_ppm_per_k"), ppm) {
            let old = self.cal.tca_tcr_ppm_per_k;
            self.cal.tca_tcr_ppm_per_k = v;
            self.cal.rescale_own(old);
        }
    }

    /// The PLA's step reached its cap early (`rise_k` above its baseline, `t_s` into the
    /// step): still air. The model's still-air convection and its own rises and couplings at
    /// it replace whatever the TCA step fitted.
    fn finish_still_air(
        &mut self,
        now_ms: u64,
        rise_k: f32,
        t_s: f32,
        emit: &mut dyn FnMut(TuneEvent),
    ) -> TuneTick {
        let mut cal = self.cal;
        cal.convection_w_m2k = TUNE_STILL_AIR_W_M2K;
        let r = cal.model_resistances();
        cal.pla_rise_k_per_w = r.r_pp;
        cal.tca_rise_k_per_w = r.r_tt;
        cal.pla_to_tca_k_per_w = r.r_tp;
        cal.tca_to_pla_k_per_w = r.r_tp;
        self.cal = cal;
        emit(TuneEvent::StillAir { rise_k, t_s });
        self.fit_tcr();
        self.fitted = true;
        self.enter(TuneStep::Verify, now_ms, emit);
        TuneTick::Run(Powers::default())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A first-order record of `rise_k` with time constant `tau_s`, `n` samples.
    fn record(rise_k: f32, tau_s: f32, n: usize) -> [f32; TUNE_MAX_SAMPLES] {
        let mut y = [0.0f32; TUNE_MAX_SAMPLES];
        for (i, v) in y.iter_mut().take(n).enumerate() {
            *v = rise_k * (1.0 - crate::mathf::exp(-((i + 1) as f32 * TUNE_SAMPLE_S) / tau_s));
        }
        y
    }

    /// The model's own PLA and TCA steps under water, read through the observer's bead lag and
    /// sampled as a tune samples them: the first-order fit leaves them a residual well inside
    /// the bound, at [`TUNE_MAX_RESIDUAL_SHARE`] / 1.4 or less of their rise.
    #[test]
    fn the_models_own_step_leaves_a_residual_under_the_bound() {
        use morphlink_model::thermal::{node, Network};
        for (at, pla_w, tca_w, len) in [
            (node::PLA, TUNE_PLA_W, 0.0, TUNE_PLA_S),
            (node::TCA, 0.0, TUNE_TCA_W, TUNE_TCA_S),
        ] {
            let mut net = Network::new(&LINK);
            let amb = LINK.surroundings.ambient_c;
            let n = (len / TUNE_SAMPLE_S) as usize;
            let mut y = [0.0f32; TUNE_MAX_SAMPLES];
            let keep = morphlink_model::thermal::lag_remaining(0.1, SENSOR_TAU_S as f64);
            let mut bead_k = 0.0;
            for v in y.iter_mut().take(n) {
                let mut acc = 0.0;
                for _ in 0..10 {
                    net.advance(0.1, tca_w as f64, pla_w as f64, amb);
                    bead_k = (net.temp_c[at] - amb) + (bead_k - (net.temp_c[at] - amb)) * keep;
                    acc += bead_k;
                }
                *v = (acc / 10.0) as f32;
            }
            let y = &y[..n];
            let f = fit::asymptotic(y, TUNE_SAMPLE_S).unwrap();
            let share = fit::residual_rms_k(y, TUNE_SAMPLE_S, &f) / y[n - 1];
            assert!(share <= TUNE_MAX_RESIDUAL_SHARE / 1.4, "node {at}: {share}");
        }
    }

    #[test]
    fn a_record_longer_than_its_time_constant_is_fitted() {
        // 45 s of a 13 s coupling: 97 % of the way.
        let y = record(4.8, 13.0, 45);
        let (r, tau, _, _) = fit_checked(&y[..45], TUNE_TCA_W, Fitted::TcaToPla, &water()).unwrap();
        assert!(
            (r - 8.0).abs() < 0.3 && (tau - 13.0).abs() < 1.5,
            "{r} {tau}"
        );
    }

    #[test]
    fn a_record_far_shorter_than_its_time_constant_is_an_extrapolation() {
        // 45 s of a 120 s coupling ends at 31 % of its rise: both methods would triple it.
        let y = record(12.0, 120.0, 45);
        match fit_checked(&y[..45], TUNE_TCA_W, Fitted::TcaToPla, &water()) {
            Err(Rejection::Extrapolated(fit_k, seen_k)) => {
                assert!(fit_k > TUNE_MAX_EXTRAPOLATION * seen_k, "{fit_k} {seen_k}");
                assert!((seen_k - y[44]).abs() < 0.2, "{seen_k}");
            }
            other => panic!("{other:?}"),
        }
        // A falling or empty record has nothing to extrapolate from.
        assert!(fit_checked(&[0.0; 20], TUNE_TCA_W, Fitted::TcaToPla, &water()).is_err());
        assert!(fit_checked(&[], TUNE_TCA_W, Fitted::TcaToPla, &water()).is_err());
    }
}

//! This link's calibration: what `TUNE` fitted and what `MEASURED` learnt, in one struct of
//! plain `f32` fields the [`crate::controller::Controller`] owns and the strategies read.
//!
//! [`Calibration::default`] is the compiled-in link (`link.toml`'s lumped model, no measured
//! morph), so a link that was never tuned behaves as before. Every field has a row in
//! [`FIELDS`] (name, unit, allowed range) and is read and written by index
//! ([`Calibration::get`], [`Calibration::set`]), so a settings registry can list, range-check and
//! store the group without knowing its meaning. [`Calibration::set`] refuses a value outside its
//! row's range and changes nothing then.
//!
//! Two corrections live here:
//! - **thermal** (from `TUNE`): the steady rise per watt each thermistor shows of its own heater.
//!   The observer of `boost`/`closed` models each thermistor as reading that share of its
//!   node's rise ([`Calibration::sensor_gain`]): a bead beside a heater reads a fraction of the
//!   heater's mean rise, and without this the observer takes the shortfall for a cold heater.
//! - **map** (from `MEASURED` after a `boost`/`closed` morph): the TCA temperature map in the
//!   thermistor's space. Each report pairs the estimate's TCA rise at lock, `x` (what the
//!   thermistors said), with the rise the mechanics need for the radius measured, `y`; the map
//!   `y = a + b·x` is the least-squares line through the reports (offset and slope), pulled
//!   towards `a = 0, b = 1` by priors worth [`MAP_OFFSET_PRIOR_WEIGHT`] and
//!   [`MAP_PRIOR_WEIGHT`] reports ([`Calibration::map`]): one report moves both a little of the
//!   way (fewer points, fewer free parameters), three at different radii fit both. A fit whose
//!   slope leaves [`MAP_SLOPE_RANGE`] or whose correction exceeds [`MAP_MAX_CORRECTION_K`] is
//!   refused and says why ([`ReportRejection`]). After a `paper`/`gated` morph the report
//!   scales the table's power instead ([`Calibration::power_scale`]).

use crate::link::{
    CONVECTION_RANGE_W_M2K, LINK, R_AT_HIGHEST_CONVECTION_K_PER_W, R_AT_LOWEST_CONVECTION_K_PER_W,
    R_PP_K_PER_W, R_TP_K_PER_W, R_TT_K_PER_W,
};
use crate::lumped::{resistance_matrix, ResistanceMatrix};

/// One calibration field's description: its name (the settings key), unit and allowed range.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FieldInfo {
    /// Name, lower-case with its unit (`tca_rise_k_per_w`).
    pub name: &'static str,
    /// Unit as shown to the user (`K/W`, `s`, `1`).
    pub unit: &'static str,
    /// Smallest allowed value.
    pub min: f32,
    /// Largest allowed value.
    pub max: f32,
    /// What the field is, one line.
    pub doc: &'static str,
}

/// [`FIELDS`]' row of [`Calibration::tca_self_bend`], a switch: `CONFIG SET` takes it as one
/// of [`SWITCH_CHOICES`], so that no value between off and on is taken for either.
pub const SELF_BEND_FIELD: usize = 15;
/// The words a switch takes: 0 (off) and 1 (on), the value being the word's index.
pub const SWITCH_CHOICES: [&str; 2] = ["0", "1"];

/// Smallest rise per watt `TUNE` accepts, as a share of the model's: a bead that sees under a
/// third of its heater's rise is off its heater (or the link is in a stirred bath far from the
/// model), and the observer would amplify its noise threefold.
pub const RISE_MIN_SHARE: f32 = 0.3;
/// Largest rise per watt `TUNE` accepts, as a share of the model's: a bead cannot read more
/// than its heater; 1.5 allows 50 % weaker convection than the model's water. Still air (about
/// five times the rise) is outside: the model strategies assume water.
pub const RISE_MAX_SHARE: f32 = 1.5;
/// Time constants `TUNE` accepts, s: the TCA's thermistor responds within about 2 s at the
/// fastest (bead on the fibre), the PLA's within 200 s at the slowest (a loose bead on a rod
/// in still water); outside, the fit is not of this link.
pub const TAU_RANGE_S: (f32, f32) = (2.0, 200.0);
/// Default time constant of the TCA thermistor's step response, s: `TUNE`'s result on the
/// nominal lumped link (`cargo test --release --test tune a_healthy -- --nocapture`, which
/// prints every fitted value).
pub const DEFAULT_TCA_TAU_S: f32 = 12.6;
/// Default time constant of the PLA thermistor's step response, s (as
/// [`DEFAULT_TCA_TAU_S`]).
pub const DEFAULT_PLA_TAU_S: f32 = 21.7;
/// Weight of the map's prior (`a = 0, b = 1`), in reports: one report moves the map most of the
/// way to what it shows (split between offset and slope by the prior's shape); three reports
/// at different radii fit it almost freely.
pub const MAP_PRIOR_WEIGHT: f32 = 0.2;
/// Weight of the offset's prior (`a = 0`), in reports (each report weighs 1 per K² of its
/// residual). The high-fidelity links' error after TUNE is mostly an offset in this space
/// (the PLA's heat at the TCA bead, which the model's coupling does not share): one report
/// at a mid-range rise puts about half of its correction into the offset, three at
/// different radii fit the offset almost freely, and a lighter prior passes more of the
/// measuring error into the map (`cargo xtask calibration`; docs/calibration.md, "What changed,
/// and why").
pub const MAP_OFFSET_PRIOR_WEIGHT: f32 = 0.2;
const _: () = assert!(MAP_OFFSET_PRIOR_WEIGHT > 0.0 && MAP_OFFSET_PRIOR_WEIGHT <= 10.0);
/// TCA rise that scales the slope's prior, K: a mid-range rise (the table spans 12–63 K), so
/// the prior on `b` weighs like a report there.
pub const MAP_PRIOR_RISE_K: f32 = 35.0;
/// Reports the map remembers at full weight; beyond it older reports fade (their sums are
/// scaled down), so a link that changes is followed. Eight reports at 0.3 mm each average the
/// measuring error to about 0.1 mm.
pub const MEASURED_MEMORY: f32 = 8.0;
/// Largest correction of the map's aim at any needed rise in [`MAP_SPAN_K`], K: 25 K is about 7 mm of
/// radius in the middle of the range, four times the largest miss of the paper's model on its
/// own link and above the 3.5 mm the most biased high-fidelity links miss by before
/// calibration. A report that would need more is refused as a measuring mistake.
pub const MAP_MAX_CORRECTION_K: f32 = 25.0;
/// The needed TCA rises the map's correction is judged over, K: every rise the mechanics can
/// ask of the map for a radius in the table (12–63 K) with a margin. The correction is judged
/// on the aim the map gives for each (`x = (y − a) / b`), so no aim a morph can be given lies
/// more than [`MAP_MAX_CORRECTION_K`] from what the mechanics need.
pub const MAP_SPAN_K: (f32, f32) = (0.0, 70.0);
/// Allowed range of the map's slope: a bead reads at least half and at most twice the rise
/// the mechanics need.
pub const MAP_SLOPE_RANGE: (f32, f32) = (0.5, 2.0);
/// Allowed range of the table's power scale: down to half (a heater of twice the nominal
/// resistance is outside any link the table was made for) and up to what keeps the scaled
/// table's largest power within the TCA heater's cap (2 W / 1.5 W): past it the scale would
/// only saturate the heater, and a report asking for more is a measuring mistake.
pub const POWER_SCALE_RANGE: (f32, f32) = (
    0.5,
    crate::heater::HeaterConfig::TCA.max_power_w / crate::table::MAX_POWER_W,
);
const _: () = assert!(POWER_SCALE_RANGE.1 > 1.0 && POWER_SCALE_RANGE.1 <= 2.0);

/// The calibration's layout version: 2 added [`Calibration::convection_w_m2k`], against
/// which the rises are read; 3 [`Calibration::tca_tcr_ppm_per_k`], the TCA's own thermometer;
/// 4 [`Calibration::tca_self_bend`] and [`Calibration::tca_strain_k_m`]. Fields after those
/// are appended before the version (a stored calibration from before one was appended loads
/// it at its default: [`crate::settings::codec`]); [`Calibration::tca_strain_sd_share`] is.
pub const LAYOUT_VERSION: f32 = 4.0;

/// Largest strain factor the own thermometer takes, K·m (see [`Calibration::strain_k_m`]): its
/// correction over the table's whole bend (some 12 /m of curvature from the cast shape) stays
/// under [`MAP_MAX_CORRECTION_K`]'s 25 K; the high-fidelity links' estimates reach 2.4 K·m.
pub const STRAIN_MAX_K_M: f32 = 3.0;
/// Largest uncertainty of the strain factor kept, a share of it (see
/// [`Calibration::tca_strain_sd_share`]): a gauge looser than a quarter of itself reads no shape
/// (`shape::GAUGE_MIN_SIGMAS`) but is kept, so the link says `weak-gauge` (a TCA whose
/// resistance does not follow its strain: the lumped links' gauges are 10–1000 times their
/// sigma's reciprocal), not `no-gauge` after every MEASURED.
pub const STRAIN_SD_SHARE_MAX: f32 = 1.0e4;

/// The TCA's temperature coefficient of resistance an untuned controller takes, ppm/K: the
/// silver-coated thread's 1.5e-3/K, an estimate (docs/plant.md); `TUNE` fits the link's own.
/// In ppm so the settings' three decimals keep it whole.
pub const TCA_TCR_NOMINAL_PPM_PER_K: f32 = 1500.0;
/// The coefficients [`Calibration::tca_tcr_ppm_per_k`] may take, ppm/K: a fifth to three times
/// the nominal (silver's own 3 800 ppm/K is about the top a plated thread can show).
pub const TCA_TCR_RANGE_PPM_PER_K: (f32, f32) = (300.0, 4500.0);

// The link file's convection is a value the range allows.
const _: () = assert!(
    LINK.surroundings.h_w_m2k as f32 >= CONVECTION_RANGE_W_M2K.0
        && LINK.surroundings.h_w_m2k as f32 <= CONVECTION_RANGE_W_M2K.1
);

/// The model's rises at the link file's convection (still water), K/W: the build's
/// `R_TT_K_PER_W`, `R_PP_K_PER_W`, `R_TP_K_PER_W`.
pub const WATER_RESISTANCES: ResistanceMatrix = ResistanceMatrix {
    r_tt: R_TT_K_PER_W,
    r_pp: R_PP_K_PER_W,
    r_tp: R_TP_K_PER_W,
};

/// Decimals a calibration range is kept to: `CONFIG` prints them with three, and a printed end
/// must be a value the range accepts, so each end is rounded inwards.
pub const RANGE_DECIMALS_SCALE: f32 = 1000.0;

/// `(min, max)` rounded inwards to [`RANGE_DECIMALS_SCALE`]: `min` up, `max` down.
const fn inward(min: f32, max: f32) -> (f32, f32) {
    const fn floor(x: f32) -> f32 {
        let t = x as i64 as f32;
        if t > x {
            t - 1.0
        } else {
            t
        }
    }
    // `+ 0.0` turns the −0 of a range that starts at 0 into +0.
    let lo = -floor(-min * RANGE_DECIMALS_SCALE) / RANGE_DECIMALS_SCALE + 0.0;
    let hi = floor(max * RANGE_DECIMALS_SCALE) / RANGE_DECIMALS_SCALE;
    (lo, hi)
}

/// `doc` on the host, `""` in the firmware image: the calibration fields' and the settings'
/// one-line docs are read by the host's tools and tests only, and in the image they would take
/// flash.
pub const fn doc_text(doc: &'static str) -> &'static str {
    if cfg!(target_os = "none") {
        ""
    } else {
        doc
    }
}

/// A field of `name` with the range `(min, max)` rounded [`inward`].
const fn field_info(
    name: &'static str,
    unit: &'static str,
    (min, max): (f32, f32),
    doc: &'static str,
) -> FieldInfo {
    let (min, max) = inward(min, max);
    FieldInfo {
        name,
        unit,
        min,
        max,
        doc: doc_text(doc),
    }
}

/// Number of fields.
pub const FIELD_COUNT: usize = 19;

/// Every field, in index order (the order of [`Calibration::get`] / [`Calibration::set`]).
pub const FIELDS: [FieldInfo; FIELD_COUNT] = [
    field_info(
        "pla_rise_k_per_w",
        "K/W",
        (
            RISE_MIN_SHARE * R_AT_HIGHEST_CONVECTION_K_PER_W[1],
            RISE_MAX_SHARE * R_AT_LOWEST_CONVECTION_K_PER_W[1],
        ),
        "steady PLA thermistor rise per PLA watt (TUNE)",
    ),
    field_info(
        "tca_rise_k_per_w",
        "K/W",
        (
            RISE_MIN_SHARE * R_AT_HIGHEST_CONVECTION_K_PER_W[0],
            RISE_MAX_SHARE * R_AT_LOWEST_CONVECTION_K_PER_W[0],
        ),
        "steady TCA thermistor rise per TCA watt (TUNE)",
    ),
    field_info(
        "pla_to_tca_k_per_w",
        "K/W",
        (
            0.0,
            RISE_MAX_SHARE * R_AT_LOWEST_CONVECTION_K_PER_W[2] * 2.0,
        ),
        "steady TCA thermistor rise per PLA watt (TUNE)",
    ),
    field_info(
        "tca_to_pla_k_per_w",
        "K/W",
        (
            0.0,
            RISE_MAX_SHARE * R_AT_LOWEST_CONVECTION_K_PER_W[2] * 2.0,
        ),
        "steady PLA thermistor rise per TCA watt (TUNE)",
    ),
    field_info(
        "pla_tau_s",
        "s",
        (TAU_RANGE_S.0, TAU_RANGE_S.1),
        "PLA thermistor step-response time constant (TUNE)",
    ),
    field_info(
        "tca_tau_s",
        "s",
        (TAU_RANGE_S.0, TAU_RANGE_S.1),
        "TCA thermistor step-response time constant (TUNE)",
    ),
    field_info(
        "map_count",
        "1",
        (0.0, MEASURED_MEMORY),
        "MEASURED reports in the TCA map (weight)",
    ),
    field_info(
        "map_sum_x_k",
        "K",
        (-MEASURED_MEMORY * 110.0, MEASURED_MEMORY * 110.0),
        "sum of estimated TCA rises at lock",
    ),
    field_info(
        "map_sum_y_k",
        "K",
        (-MEASURED_MEMORY * 110.0, MEASURED_MEMORY * 110.0),
        "sum of TCA rises the measured radii need",
    ),
    field_info(
        "map_sum_xx_k2",
        "K2",
        (0.0, MEASURED_MEMORY * 110.0 * 110.0),
        "sum of squared estimated rises",
    ),
    field_info(
        "map_sum_xy_k2",
        "K2",
        (
            -MEASURED_MEMORY * 110.0 * 110.0,
            MEASURED_MEMORY * 110.0 * 110.0,
        ),
        "sum of estimated times needed rises",
    ),
    field_info(
        "power_count",
        "1",
        (0.0, MEASURED_MEMORY),
        "MEASURED reports in the power scale (weight)",
    ),
    field_info(
        "power_sum_ratio",
        "1",
        (0.0, MEASURED_MEMORY * POWER_SCALE_RANGE.1),
        "sum of power needed over table power",
    ),
    field_info(
        "convection_w_m2k",
        "W/m2K",
        (CONVECTION_RANGE_W_M2K.0, CONVECTION_RANGE_W_M2K.1),
        "rim convection of the thermal model (TUNE: water or still air)",
    ),
    field_info(
        "tca_tcr_ppm_per_k",
        "ppm/K",
        TCA_TCR_RANGE_PPM_PER_K,
        "temperature coefficient of the TCA's resistance (TUNE, where current is sensed)",
    ),
    field_info(
        "tca_self_bend",
        "1",
        (0.0, 1.0),
        "1: closed bends on the TCA's own temperature (current sense; 0: its thermistor)",
    ),
    field_info(
        "tca_strain_k_m",
        "K m",
        (-STRAIN_MAX_K_M, STRAIN_MAX_K_M),
        "own temperature's miss per 1/m of bend (rest-shape gauge; docs/shape.md)",
    ),
    field_info(
        "tca_strain_sd_share",
        "1",
        (0.0, STRAIN_SD_SHARE_MAX),
        "the strain factor's uncertainty, a share of it (0: no gauge learnt; docs/shape.md)",
    ),
    field_info(
        "version",
        "1",
        (LAYOUT_VERSION, LAYOUT_VERSION),
        "calibration layout version",
    ),
];

/// This link's calibration (see the module docs). Plain fields with units in their names.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Calibration {
    /// Steady PLA thermistor rise per PLA watt, K/W.
    pub pla_rise_k_per_w: f32,
    /// Steady TCA thermistor rise per TCA watt, K/W.
    pub tca_rise_k_per_w: f32,
    /// Steady TCA thermistor rise per PLA watt (the PLA-to-TCA coupling), K/W.
    pub pla_to_tca_k_per_w: f32,
    /// Steady PLA thermistor rise per TCA watt (the TCA-to-PLA coupling), K/W.
    pub tca_to_pla_k_per_w: f32,
    /// PLA thermistor step-response time constant, s.
    pub pla_tau_s: f32,
    /// TCA thermistor step-response time constant, s.
    pub tca_tau_s: f32,
    /// Weight of the `MEASURED` reports in the TCA map (a count that fades past
    /// [`MEASURED_MEMORY`]).
    pub map_count: f32,
    /// Sum of the estimated TCA rises at lock `x`, K.
    pub map_sum_x_k: f32,
    /// Sum of the needed rises `y`, K.
    pub map_sum_y_k: f32,
    /// Sum of `x²`, K².
    pub map_sum_xx_k2: f32,
    /// Sum of `x·y`, K².
    pub map_sum_xy_k2: f32,
    /// Weight of the reports in the power scale.
    pub power_count: f32,
    /// Sum of the reported power ratios (power the radius needed / the table's power).
    pub power_sum_ratio: f32,
    /// Convection at the link's rim the thermal model assumes, W/(m² K): the link file's (still
    /// water) unless `TUNE` found still air ([`crate::tune`]). The rises above are this link's
    /// thermistors' at it; the model's own rises at it are [`Calibration::model_resistances`].
    pub convection_w_m2k: f32,
    /// Temperature coefficient of the TCA's resistance, ppm/K: what its own thermometer reads
    /// it with (STATUS `t_tca_self_c`); fitted by `TUNE` on a board that senses current.
    pub tca_tcr_ppm_per_k: f32,
    /// 1: `closed` bends on the TCA's own temperature where the board senses current; 0 (the
    /// default): on its thermistor ([`Calibration::self_sensed`]). A choice, not a fit: the
    /// map's reports are of one view, so switching starts the map afresh.
    pub tca_self_bend: f32,
    /// The own thermometer's strain factor, K·m ([`Calibration::strain_k_m`]): the rest-shape
    /// gauge read as temperature ([`Calibration::set_gauge`]).
    pub tca_strain_k_m: f32,
    /// The strain factor's uncertainty (one sigma) as a share of it, 1: the rest-shape gauge's
    /// ([`Calibration::gauge`]), kept so a link that was reset reads its shape again after one
    /// MEASURED instead of two; 0 (the default) where no gauge was learnt.
    pub tca_strain_sd_share: f32,
    /// Layout version ([`LAYOUT_VERSION`]): a stored calibration of another layout is not this
    /// one.
    pub version: f32,
}

impl Default for Calibration {
    fn default() -> Self {
        Self::DEFAULT
    }
}

/// Why a MEASURED report was refused by [`Calibration::fold_map`] or
/// [`Calibration::fold_power`] (the calibration is then unchanged).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ReportRejection {
    /// A value of the report is NaN or infinite.
    NotFinite,
    /// The fitted map's slope would be outside [`MAP_SLOPE_RANGE`] (the slope).
    Slope(f32),
    /// The fitted map would correct some rise in [`MAP_SPAN_K`] by more than
    /// [`MAP_MAX_CORRECTION_K`] (the largest correction, K).
    Correction(f32),
    /// The power ratio is outside [`POWER_SCALE_RANGE`] (the ratio).
    PowerRatio(f32),
    /// The table power of the morph or of the measured radius is under this, W: a ratio of
    /// such powers says nothing.
    PowerTooSmall(f32),
    /// A sum would leave its field's range (the field).
    Field(FieldInfo),
}

/// A calibration whose rises do not fit the model at its convection
/// ([`Calibration::share_rule`]): the field, its share of the model's rise, and the shares
/// allowed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Inconsistent {
    /// The rise out of line.
    pub field: FieldInfo,
    /// Its share of the model's rise at [`Calibration::convection_w_m2k`], 1.
    pub share: f32,
    /// The shares allowed, 1.
    pub allowed: (f32, f32),
}

/// The shares of the model's rise each rise field may have (field index, allowed shares): a
/// thermistor's own [`RISE_MIN_SHARE`]..[`RISE_MAX_SHARE`], a coupling up to twice the top
/// share. The one rule `TUNE` fits and `CONFIG SET` are both held to.
pub const SHARE_RULE: [(usize, (f32, f32)); 4] = [
    (0, (RISE_MIN_SHARE, RISE_MAX_SHARE)),
    (1, (RISE_MIN_SHARE, RISE_MAX_SHARE)),
    (2, (0.0, 2.0 * RISE_MAX_SHARE)),
    (3, (0.0, 2.0 * RISE_MAX_SHARE)),
];

/// Index in [`FIELDS`] of [`Calibration::convection_w_m2k`]: the field the rises' shares are
/// judged at, so its own range depends on them.
pub const CONVECTION_FIELD: usize = 13;

/// Why a value was refused by [`Calibration::set`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum CalibrationError {
    /// No field has this index.
    NoSuchField,
    /// The value is NaN, infinite or outside the field's range.
    OutOfRange(FieldInfo),
}

impl Calibration {
    /// The compiled-in link: the lumped model's rises, the nominal time constants, no report.
    pub const DEFAULT: Calibration = Calibration {
        pla_rise_k_per_w: R_PP_K_PER_W,
        tca_rise_k_per_w: R_TT_K_PER_W,
        pla_to_tca_k_per_w: R_TP_K_PER_W,
        tca_to_pla_k_per_w: R_TP_K_PER_W,
        pla_tau_s: DEFAULT_PLA_TAU_S,
        tca_tau_s: DEFAULT_TCA_TAU_S,
        map_count: 0.0,
        map_sum_x_k: 0.0,
        map_sum_y_k: 0.0,
        map_sum_xx_k2: 0.0,
        map_sum_xy_k2: 0.0,
        power_count: 0.0,
        power_sum_ratio: 0.0,
        convection_w_m2k: LINK.surroundings.h_w_m2k as f32,
        tca_tcr_ppm_per_k: TCA_TCR_NOMINAL_PPM_PER_K,
        tca_self_bend: 0.0,
        tca_strain_k_m: 0.0,
        tca_strain_sd_share: 0.0,
        version: LAYOUT_VERSION,
    };

    fn slot(&mut self, index: usize) -> Option<&mut f32> {
        Some(match index {
            0 => &mut self.pla_rise_k_per_w,
            1 => &mut self.tca_rise_k_per_w,
            2 => &mut self.pla_to_tca_k_per_w,
            3 => &mut self.tca_to_pla_k_per_w,
            4 => &mut self.pla_tau_s,
            5 => &mut self.tca_tau_s,
            6 => &mut self.map_count,
            7 => &mut self.map_sum_x_k,
            8 => &mut self.map_sum_y_k,
            9 => &mut self.map_sum_xx_k2,
            10 => &mut self.map_sum_xy_k2,
            11 => &mut self.power_count,
            12 => &mut self.power_sum_ratio,
            13 => &mut self.convection_w_m2k,
            14 => &mut self.tca_tcr_ppm_per_k,
            SELF_BEND_FIELD => &mut self.tca_self_bend,
            16 => &mut self.tca_strain_k_m,
            17 => &mut self.tca_strain_sd_share,
            18 => &mut self.version,
            _ => return None,
        })
    }

    /// Field number `index`'s value (see [`FIELDS`]), or `None` past the last.
    pub fn get(&self, index: usize) -> Option<f32> {
        (index < FIELD_COUNT).then(|| self.value(index))
    }

    /// Field number `index`'s value, NaN past the last; `const`, so the settings registry can
    /// take the compiled-in values as its defaults at compile time.
    pub const fn value(&self, index: usize) -> f32 {
        match index {
            0 => self.pla_rise_k_per_w,
            1 => self.tca_rise_k_per_w,
            2 => self.pla_to_tca_k_per_w,
            3 => self.tca_to_pla_k_per_w,
            4 => self.pla_tau_s,
            5 => self.tca_tau_s,
            6 => self.map_count,
            7 => self.map_sum_x_k,
            8 => self.map_sum_y_k,
            9 => self.map_sum_xx_k2,
            10 => self.map_sum_xy_k2,
            11 => self.power_count,
            12 => self.power_sum_ratio,
            13 => self.convection_w_m2k,
            14 => self.tca_tcr_ppm_per_k,
            SELF_BEND_FIELD => self.tca_self_bend,
            16 => self.tca_strain_k_m,
            17 => self.tca_strain_sd_share,
            18 => self.version,
            _ => f32::NAN,
        }
    }

    /// Sets field number `index` to `value` if it is within the field's range; otherwise
    /// changes nothing and says why.
    pub fn set(&mut self, index: usize, value: f32) -> Result<(), CalibrationError> {
        let info = *FIELDS.get(index).ok_or(CalibrationError::NoSuchField)?;
        if !(value >= info.min && value <= info.max) {
            return Err(CalibrationError::OutOfRange(info));
        }
        *self.slot(index).ok_or(CalibrationError::NoSuchField)? = value;
        Ok(())
    }

    /// True if every field is within its range (a calibration read from storage is used only
    /// then).
    pub fn valid(&self) -> bool {
        self.first_invalid().is_none()
    }

    /// The convection the model runs at, W/(m² K): [`Calibration::convection_w_m2k`], or the
    /// link file's where that is not a number in range (a calibration is range-checked when
    /// set; this keeps the model finite whatever it is handed).
    pub fn model_convection_w_m2k(&self) -> f32 {
        let h = self.convection_w_m2k;
        if h >= CONVECTION_RANGE_W_M2K.0 && h <= CONVECTION_RANGE_W_M2K.1 {
            h
        } else {
            LINK.surroundings.h_w_m2k as f32
        }
    }

    /// The model's steady rises per watt at [`Calibration::model_convection_w_m2k`], K/W: what
    /// the rises of a thermistor that reads its whole node are ([`WATER_RESISTANCES`], built
    /// in, at the link file's convection).
    pub fn model_resistances(&self) -> ResistanceMatrix {
        let h = self.model_convection_w_m2k();
        if h == LINK.surroundings.h_w_m2k as f32 {
            return WATER_RESISTANCES;
        }
        resistance_matrix(h)
    }

    /// Whether this link's thermistors' rises have been fitted (`TUNE`, or set): any of them
    /// differs from the compiled-in link's. The supervisor's expectation then takes the fit
    /// instead of bracketing the surroundings; a convection set alone is no fit of the beads.
    pub fn fitted(&self) -> bool {
        let d = Calibration::DEFAULT;
        self.pla_rise_k_per_w != d.pla_rise_k_per_w
            || self.tca_rise_k_per_w != d.tca_rise_k_per_w
            || self.pla_to_tca_k_per_w != d.pla_to_tca_k_per_w
            || self.tca_to_pla_k_per_w != d.tca_to_pla_k_per_w
    }

    /// Whether every rise is the share [`SHARE_RULE`] allows of the model's own at
    /// [`Calibration::convection_w_m2k`] (the first one that is not, if any).
    pub fn share_rule(&self) -> Result<(), Inconsistent> {
        let r = self.model_resistances();
        let model = [r.r_pp, r.r_tt, r.r_tp, r.r_tp];
        for (k, &(i, allowed)) in SHARE_RULE.iter().enumerate() {
            let share = self.value(i) / model[k];
            if !(share >= allowed.0 && share <= allowed.1) {
                return Err(Inconsistent {
                    field: FIELDS[i],
                    share,
                    allowed,
                });
            }
        }
        Ok(())
    }

    /// Share of its node's rise the thermistor of `heater` reads (its fitted rise per watt over
    /// the model's), clamped to the accepted range: what the observer multiplies its modelled
    /// rise by before comparing it with the reading.
    pub fn sensor_gain(&self, heater: crate::vocab::Heater) -> f32 {
        let r = self.model_resistances();
        let (fit, model) = match heater {
            crate::vocab::Heater::Pla => (self.pla_rise_k_per_w, r.r_pp),
            crate::vocab::Heater::Tca => (self.tca_rise_k_per_w, r.r_tt),
        };
        let g = fit / model;
        if g.is_finite() {
            g.clamp(RISE_MIN_SHARE, RISE_MAX_SHARE)
        } else {
            1.0
        }
    }

    /// Share of the other heater's part of its node's rise the thermistor of `heater` reads
    /// (its fitted coupling over the model's), in `[0, 3]`.
    pub fn cross_gain(&self, heater: crate::vocab::Heater) -> f32 {
        let fit = match heater {
            crate::vocab::Heater::Pla => self.tca_to_pla_k_per_w,
            crate::vocab::Heater::Tca => self.pla_to_tca_k_per_w,
        };
        let g = fit / self.model_resistances().r_tp;
        if g.is_finite() {
            g.clamp(0.0, 3.0)
        } else {
            1.0
        }
    }

    /// The TCA map `(a, b)`: the rise the mechanics need is `a + b × the estimate's rise`, K.
    /// `(0, 1)` with no report, and also when the stored sums give a map [`fold_map`] would
    /// refuse (a slope outside [`MAP_SLOPE_RANGE`], a correction over [`MAP_MAX_CORRECTION_K`],
    /// or not finite): sums set field by field or saved under other priors never steer a morph
    /// beyond the bounds a report is held to.
    ///
    /// [`fold_map`]: Calibration::fold_map
    pub fn map(&self) -> (f32, f32) {
        let (a, b) = self.map_fit();
        match map_bounds(a, b) {
            Ok(()) => (a, b),
            Err(_) => (0.0, 1.0),
        }
    }

    /// The map's least-squares fit before its slope is bounded (what a fold checks).
    fn map_fit(&self) -> (f32, f32) {
        map_of(
            self.map_count,
            self.map_sum_x_k,
            self.map_sum_y_k,
            self.map_sum_xx_k2,
            self.map_sum_xy_k2,
        )
    }

    /// The first field out of its range, if any.
    fn first_invalid(&self) -> Option<FieldInfo> {
        (0..FIELD_COUNT).find_map(|i| {
            let v = self.get(i).unwrap_or(f32::NAN);
            (!(v >= FIELDS[i].min && v <= FIELDS[i].max)).then_some(FIELDS[i])
        })
    }

    /// The estimate's TCA rise to aim at so that the link's true rise is `need_rise_k`, K.
    pub fn aim_rise_k(&self, need_rise_k: f32) -> f32 {
        let (a, b) = self.map();
        (need_rise_k - a) / b
    }

    /// The rise the mechanics see for an estimate's rise `estimate_rise_k`, K.
    pub fn true_rise_k(&self, estimate_rise_k: f32) -> f32 {
        let (a, b) = self.map();
        a + b * estimate_rise_k
    }

    /// Adds one report to the TCA map: the estimate's rise at lock `x_k` and the rise the
    /// measured radius needs `y_k`, K, counted `weight` (0–1] of a caliper's MEASURED (a rest
    /// reading counts by its uncertainty, [`crate::shape`]); returns the new map `(a, b)`. Refused, changing nothing
    /// and saying why, if the refitted map's slope would be outside [`MAP_SLOPE_RANGE`] or it
    /// would correct by more than [`MAP_MAX_CORRECTION_K`] within [`MAP_SPAN_K`].
    pub fn fold_map(
        &mut self,
        x_k: f32,
        y_k: f32,
        weight: f32,
    ) -> Result<(f32, f32), ReportRejection> {
        if !(x_k.is_finite() && y_k.is_finite() && weight > 0.0 && weight <= 1.0) {
            return Err(ReportRejection::NotFinite);
        }
        let w = weight;
        let mut next = *self;
        if next.map_count + w > MEASURED_MEMORY {
            let keep = (MEASURED_MEMORY - w) / next.map_count;
            next.map_count *= keep;
            next.map_sum_x_k *= keep;
            next.map_sum_y_k *= keep;
            next.map_sum_xx_k2 *= keep;
            next.map_sum_xy_k2 *= keep;
        }
        next.map_count += w;
        next.map_sum_x_k += w * x_k;
        next.map_sum_y_k += w * y_k;
        next.map_sum_xx_k2 += w * x_k * x_k;
        next.map_sum_xy_k2 += w * x_k * y_k;
        let (a, b) = next.map_fit();
        map_bounds(a, b)?;
        if let Some(f) = next.first_invalid() {
            return Err(ReportRejection::Field(f));
        }
        *self = next;
        Ok((a, b))
    }

    /// Forgets the map's reports (`MEASURED`): what they paired no longer describes what `closed`
    /// bends on.
    pub fn clear_map(&mut self) {
        self.map_count = 0.0;
        self.map_sum_x_k = 0.0;
        self.map_sum_y_k = 0.0;
        self.map_sum_xx_k2 = 0.0;
        self.map_sum_xy_k2 = 0.0;
    }

    /// The TCA's temperature coefficient of resistance, 1/K ([`Calibration::tca_tcr_ppm_per_k`]
    /// is kept in ppm/K so the settings' three decimals hold it whole).
    pub fn tcr_per_k(&self) -> f32 {
        self.tca_tcr_ppm_per_k * 1e-6
    }

    /// Whether `closed` bends on the TCA's own temperature where the board senses current
    /// ([`Calibration::tca_self_bend`]; docs/strategies.md, "Bending on the TCA's own
    /// temperature").
    pub fn self_sensed(&self) -> bool {
        self.tca_self_bend >= 0.5
    }

    /// The TCA's temperature coefficient changed from `old_ppm_per_k` to the present one (a
    /// `TUNE`): what was learnt in the own temperature's scale is rescaled to the new one (a
    /// rise reads `old / new` times as large), so no report is lost.
    pub fn rescale_own(&mut self, old_ppm_per_k: f32) {
        let r = old_ppm_per_k / self.tca_tcr_ppm_per_k;
        if !r.is_finite() {
            return;
        }
        self.tca_strain_k_m =
            crate::mathf::clamp(self.tca_strain_k_m * r, -STRAIN_MAX_K_M, STRAIN_MAX_K_M);
        if self.self_sensed() {
            self.map_sum_x_k *= r;
            self.map_sum_xx_k2 *= r * r;
            self.map_sum_xy_k2 *= r;
        }
    }

    /// The own thermometer's strain factor, K·m: what it reads low per 1/m the link has bent
    /// tighter since its rest reference (the coil sits off the rod's axis, so the bend strains
    /// it and shifts its resistance; the sign is the link's own). The true temperature is the
    /// own reading plus this times the change of curvature; 0 (the default: no source gives the
    /// term, sign included) until the rest-shape gauge has been learnt from two known shapes
    /// ([`Calibration::set_gauge`]). Within ±[`STRAIN_MAX_K_M`]: the field's range,
    /// which `set`, a stored load, the gauge and `rescale_own` keep.
    pub fn strain_k_m(&self) -> f32 {
        self.tca_strain_k_m
    }

    /// The rest-shape gauge ([`crate::shape`]): the coil's `ΔR/R` per 1/m of bend and its
    /// variance, from the strain factor through the coefficient (`−factor × α`) and
    /// [`Calibration::tca_strain_sd_share`]; `None` until one was learnt (or set).
    pub fn gauge(&self) -> Option<(f32, f32)> {
        let g = -self.tca_strain_k_m * self.tcr_per_k();
        let sd = self.tca_strain_sd_share * g;
        (g != 0.0 && sd != 0.0 && g.is_finite()).then_some((g, sd * sd))
    }

    /// Sets the strain factor and its uncertainty from the rest-shape gauge `gauge_per_m`
    /// (`ΔR/R` per 1/m of bend) and its variance: read as temperature through the coefficient
    /// the gauge is what the own thermometer misses, `−gauge / α`; returns that factor.
    /// Refused, changing nothing, if it is past ±[`STRAIN_MAX_K_M`], its uncertainty past
    /// [`STRAIN_SD_SHARE_MAX`] of it, or either not a number.
    pub fn set_gauge(&mut self, gauge_per_m: f32, var: f32) -> Result<f32, ReportRejection> {
        let s = -gauge_per_m / self.tcr_per_k();
        let share = crate::mathf::sqrt(var) / gauge_per_m.abs();
        if !(s.is_finite() && share.is_finite()) {
            return Err(ReportRejection::NotFinite);
        }
        if !(s.abs() <= STRAIN_MAX_K_M) {
            return Err(ReportRejection::Correction(s.abs()));
        }
        if !(share > 0.0 && share <= STRAIN_SD_SHARE_MAX) {
            return Err(ReportRejection::Correction(share));
        }
        self.tca_strain_k_m = s;
        self.tca_strain_sd_share = share;
        Ok(s)
    }

    /// The table power's scale for the power strategies: the mean of the reported ratios,
    /// with a prior of 1 worth [`MAP_PRIOR_WEIGHT`] reports.
    pub fn power_scale(&self) -> f32 {
        let s = (self.power_sum_ratio + MAP_PRIOR_WEIGHT) / (self.power_count + MAP_PRIOR_WEIGHT);
        if s.is_finite() {
            s.clamp(POWER_SCALE_RANGE.0, POWER_SCALE_RANGE.1)
        } else {
            1.0
        }
    }

    /// Adds one report to the power scale: the power the measured radius needed over the
    /// table's power for it. Refused, changing nothing, outside [`POWER_SCALE_RANGE`].
    pub fn fold_power(&mut self, ratio: f32) -> Result<f32, ReportRejection> {
        if !ratio.is_finite() {
            return Err(ReportRejection::NotFinite);
        }
        if !(ratio >= POWER_SCALE_RANGE.0 && ratio <= POWER_SCALE_RANGE.1) {
            return Err(ReportRejection::PowerRatio(ratio));
        }
        let mut next = *self;
        if next.power_count + 1.0 > MEASURED_MEMORY {
            let keep = (MEASURED_MEMORY - 1.0) / next.power_count;
            next.power_count *= keep;
            next.power_sum_ratio *= keep;
        }
        next.power_count += 1.0;
        next.power_sum_ratio += ratio;
        if let Some(f) = next.first_invalid() {
            return Err(ReportRejection::Field(f));
        }
        *self = next;
        Ok(self.power_scale())
    }
}

/// The ridge least-squares line through the sums, pulled towards `(0, 1)`; the slope is not
/// bounded here (see [`Calibration::map`]).
/// Whether the map `(a, b)` is one a report may give: its slope within [`MAP_SLOPE_RANGE`] and
/// its correction at most [`MAP_MAX_CORRECTION_K`] over [`MAP_SPAN_K`] (NaN fails both).
fn map_bounds(a: f32, b: f32) -> Result<(), ReportRejection> {
    if !a.is_finite() {
        return Err(ReportRejection::NotFinite);
    }
    if !(b >= MAP_SLOPE_RANGE.0 && b <= MAP_SLOPE_RANGE.1) {
        return Err(ReportRejection::Slope(b));
    }
    // The aim for each needed rise y is (y − a) / b; linear in y, so its ends bound it.
    let worst = [MAP_SPAN_K.0, MAP_SPAN_K.1]
        .iter()
        .map(|&y| ((y - a) / b - y).abs())
        .fold(0.0f32, f32::max);
    if !(worst <= MAP_MAX_CORRECTION_K) {
        return Err(ReportRejection::Correction(worst));
    }
    Ok(())
}

fn map_of(n: f32, sx: f32, sy: f32, sxx: f32, sxy: f32) -> (f32, f32) {
    let la = MAP_OFFSET_PRIOR_WEIGHT;
    let lb = MAP_PRIOR_WEIGHT * MAP_PRIOR_RISE_K * MAP_PRIOR_RISE_K;
    // Normal equations of Σ(y − a − b x)² + la·a² + lb·(b − 1)².
    let (m00, m01, m11) = (n + la, sx, sxx + lb);
    let (r0, r1) = (sy, sxy + lb);
    let det = m00 * m11 - m01 * m01;
    if !(det.abs() > 1e-6) {
        return (0.0, 1.0);
    }
    let a = (r0 * m11 - m01 * r1) / det;
    let b = (m00 * r1 - m01 * r0) / det;
    if a.is_finite() && b.is_finite() {
        (a, b)
    } else {
        (0.0, 1.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_strain_factor_follows_the_gauge_bounded_and_rescaled_with_the_coefficient() {
        let mut c = Calibration::DEFAULT;
        assert_eq!(c.strain_k_m(), 0.0);
        assert_eq!(c.gauge(), None);
        // A gauge of 3e-4 per 1/m at 1.5e-3/K reads 0.2 K low per 1/m of bend.
        let var = (0.1f32 * 3e-4) * (0.1 * 3e-4);
        let s = c.set_gauge(-3e-4, var).unwrap();
        assert!((s - 0.2).abs() < 1e-5, "{s}");
        assert_eq!(c.strain_k_m(), s);
        let (g, v) = c.gauge().unwrap();
        assert!(
            (g + 3e-4).abs() < 1e-9 && (v / var - 1.0).abs() < 1e-3,
            "{g} {v}"
        );
        // Past the bounds or not a number: nothing changes.
        for (g, v) in [
            (0.01, var),
            (-0.01, var),
            (f32::NAN, var),
            (f32::INFINITY, var),
            (-3e-4, 1.0e4),
            (-3e-4, f32::NAN),
        ] {
            let before = c;
            assert!(c.set_gauge(g, v).is_err(), "{g} {v}");
            assert_eq!(c, before);
        }
        // A coefficient twice as large reads every rise half as large: so does the factor,
        // while the gauge, the coil's own, stays.
        let (before, g) = (c.strain_k_m(), c.gauge().unwrap().0);
        c.tca_tcr_ppm_per_k = 3000.0;
        c.rescale_own(1500.0);
        assert!((c.strain_k_m() - before / 2.0).abs() < 1e-4);
        assert!((c.gauge().unwrap().0 / g - 1.0).abs() < 1e-4);
        assert!(!c.self_sensed());
        c.tca_self_bend = 1.0;
        assert!(c.self_sensed());
    }

    #[test]
    fn defaults_are_the_compiled_in_link_and_within_range() {
        let c = Calibration::default();
        assert!(c.valid());
        assert_eq!(c.map(), (0.0, 1.0));
        assert_eq!(c.power_scale(), 1.0);
        assert!((c.sensor_gain(crate::vocab::Heater::Tca) - 1.0).abs() < 1e-6);
        assert!((c.cross_gain(crate::vocab::Heater::Pla) - 1.0).abs() < 1e-6);
        for (i, f) in FIELDS.iter().enumerate() {
            let v = c.get(i).unwrap();
            assert!(v >= f.min && v <= f.max, "{}: {v}", f.name);
        }
        assert_eq!(c.get(FIELD_COUNT), None);
    }

    #[test]
    fn set_refuses_out_of_range_and_changes_nothing() {
        let mut c = Calibration::default();
        for bad in [f32::NAN, -1.0, 1e9, f32::INFINITY] {
            assert!(matches!(
                c.set(1, bad),
                Err(CalibrationError::OutOfRange(_))
            ));
        }
        assert_eq!(c, Calibration::default());
        assert_eq!(c.set(99, 1.0), Err(CalibrationError::NoSuchField));
        c.set(1, 30.0).unwrap();
        assert_eq!(c.tca_rise_k_per_w, 30.0);
        assert_eq!(c.get(1), Some(30.0));
    }

    #[test]
    fn three_reports_fit_offset_and_slope() {
        // The link needs 0.9 × the estimate's rise less 4 K (a bead reading the PLA's heat).
        let need = |x: f32| 0.9 * x - 4.0;
        let mut c = Calibration::default();
        for x in [20.0f32, 40.0, 60.0] {
            c.fold_map(x, need(x), 1.0).unwrap();
        }
        let (a, b) = c.map();
        assert!((b - 0.9).abs() < 0.02 && (a + 4.0).abs() < 0.6, "{a} {b}");
        for x in [15.0f32, 30.0, 50.0] {
            let aim = c.aim_rise_k(need(x));
            assert!((aim - x).abs() < 0.5, "{x}: {aim}");
        }
    }

    #[test]
    fn fewer_reports_move_fewer_parameters_and_each_one_moves_towards_the_truth() {
        let need = |x: f32| 0.9 * x - 4.0;
        let miss = |c: &Calibration| {
            [15.0f32, 35.0, 55.0]
                .iter()
                .map(|&x| (c.true_rise_k(x) - need(x)).abs())
                .fold(0.0f32, f32::max)
        };
        let mut c = Calibration::default();
        let mut last = miss(&c);
        for (n, x) in [40.0f32, 20.0, 60.0].into_iter().enumerate() {
            c.fold_map(x, need(x), 1.0).unwrap();
            let (a, b) = c.map();
            let now = miss(&c);
            // One report splits its correction between offset and slope, both the right way,
            // and brings its own rise most of the way (8 K off before).
            if n == 0 {
                assert!(a < 0.0 && a > -6.0 && b < 1.0 && b > 0.8, "{a} {b}");
                let own = (c.true_rise_k(40.0) - need(40.0)).abs();
                assert!(own < 0.35 * 8.0, "{own}");
            }
            assert!(now < last, "report {n}: {now} K, before {last} K");
            last = now;
        }
        assert!(last < 1.0, "{last}");
    }

    #[test]
    fn degenerate_reports_fit_the_offset_and_keep_the_slope_near_one() {
        // Three reports at one rise: no slope information; the prior keeps it near 1.
        let mut c = Calibration::default();
        for _ in 0..3 {
            c.fold_map(30.0, 27.0, 1.0).unwrap();
        }
        let (a, b) = c.map();
        assert!((a + 30.0 * (b - 1.0) + 3.0).abs() < 0.3, "{a} {b}");
        assert!(b > 0.9 && b <= 1.0, "{b}");
        // Reports at zero rise fit the offset alone.
        let mut z = Calibration::default();
        for _ in 0..3 {
            z.fold_map(0.0, -2.0, 1.0).unwrap();
        }
        let (a, b) = z.map();
        let shrunk = -2.0 * 3.0 / (3.0 + MAP_OFFSET_PRIOR_WEIGHT);
        assert!(
            (a - shrunk).abs() < 0.01 && (b - 1.0).abs() < 1e-3,
            "{a} {b}"
        );
    }

    #[test]
    fn absurd_reports_are_refused_say_why_and_change_nothing() {
        let mut c = Calibration::default();
        assert!(matches!(
            c.fold_map(30.0, 90.0, 1.0),
            Err(ReportRejection::Slope(_) | ReportRejection::Correction(_))
        ));
        assert_eq!(
            c.fold_map(f32::NAN, 30.0, 1.0),
            Err(ReportRejection::NotFinite)
        );
        assert_eq!(
            c.fold_map(30.0, f32::INFINITY, 1.0),
            Err(ReportRejection::NotFinite)
        );
        assert_eq!(c, Calibration::default());
        // A slope past its range is refused, not clamped into use.
        let mut s = Calibration::default();
        for x in [20.0f32, 40.0] {
            s.fold_map(x, 0.8 * x, 1.0).unwrap();
        }
        let before = s;
        match s.fold_map(60.0, 0.2 * 60.0, 1.0) {
            Err(ReportRejection::Slope(b)) => assert!(b < MAP_SLOPE_RANGE.0, "{b}"),
            Err(ReportRejection::Correction(k)) => assert!(k > MAP_MAX_CORRECTION_K, "{k}"),
            other => panic!("{other:?}"),
        }
        assert_eq!(s, before);
        // A uniform offset beyond the largest correction.
        let mut o = Calibration::default();
        assert!(matches!(
            o.fold_map(5.0, 5.0 + 4.0 * MAP_MAX_CORRECTION_K, 1.0),
            Err(ReportRejection::Correction(_))
        ));
        assert_eq!(o, Calibration::default());
        assert_eq!(c.fold_power(5.0), Err(ReportRejection::PowerRatio(5.0)));
        assert_eq!(c.fold_power(f32::NAN), Err(ReportRejection::NotFinite));
        assert_eq!(c, Calibration::default());
    }

    #[test]
    fn stored_sums_beyond_a_reports_bounds_steer_nothing() {
        // Sums set field by field (CONFIG SET, or a blob saved under other priors) that give a
        // map no report could: eight "reports" of a 60 K correction at every rise.
        let mut c = Calibration::default();
        let field = |name: &str| FIELDS.iter().position(|f| f.name == name).unwrap();
        for (name, v) in [
            ("map_count", 8.0),
            ("map_sum_x_k", 8.0 * 30.0),
            ("map_sum_y_k", 8.0 * 90.0),
            ("map_sum_xx_k2", 8.0 * 30.0 * 30.0 + 8.0 * 100.0),
            ("map_sum_xy_k2", 8.0 * 30.0 * 90.0 + 8.0 * 100.0),
        ] {
            c.set(field(name), v).unwrap();
        }
        assert!(
            map_bounds(c.map_fit().0, c.map_fit().1).is_err(),
            "{:?}",
            c.map_fit()
        );
        assert_eq!(c.map(), (0.0, 1.0));
        assert_eq!(c.aim_rise_k(40.0), 40.0);
        // A report's bounds, NaN included.
        assert_eq!(map_bounds(f32::NAN, 1.0), Err(ReportRejection::NotFinite));
        assert!(map_bounds(0.0, f32::NAN).is_err());
        assert_eq!(map_bounds(0.0, 1.0), Ok(()));
    }

    #[test]
    fn old_reports_fade_past_the_memory() {
        let mut c = Calibration::default();
        for _ in 0..40 {
            c.fold_power(1.2).unwrap();
        }
        assert!(c.power_count <= MEASURED_MEMORY);
        assert!((c.power_scale() - 1.2).abs() < 0.02);
        assert!(c.valid());
    }

    #[test]
    fn the_rises_are_read_against_the_model_at_the_calibrated_convection() {
        use crate::vocab::Heater;
        let water = Calibration::DEFAULT;
        for h in [Heater::Pla, Heater::Tca] {
            assert!((water.sensor_gain(h) - 1.0).abs() < 1e-4);
            assert!((water.cross_gain(h) - 1.0).abs() < 1e-4);
        }
        // Still air: the model rises further per watt, so the water rises read as a bead that
        // sees a share of its node, and the air model's own as 1.
        let mut air = water;
        air.set(13, 20.0).unwrap();
        let r = air.model_resistances();
        assert!(r.r_pp > 1.5 * R_PP_K_PER_W && r.r_tp > 3.0 * R_TP_K_PER_W);
        assert!(
            air.sensor_gain(Heater::Pla) < 0.7,
            "{}",
            air.sensor_gain(Heater::Pla)
        );
        air.pla_rise_k_per_w = r.r_pp;
        assert!((air.sensor_gain(Heater::Pla) - 1.0).abs() < 1e-4);
        // Outside its range the field is refused; a value that got in anyway runs the water model.
        assert!(air.set(13, 5.0).is_err());
        let mut bad = water;
        bad.convection_w_m2k = f32::NAN;
        assert_eq!(bad.model_convection_w_m2k(), water.convection_w_m2k);
        assert_eq!(FIELDS[CONVECTION_FIELD].name, "convection_w_m2k");
    }
}

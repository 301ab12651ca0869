//! The wire text of `TUNE` and `MEASURED`: their replies, refusals and `event: tune ...` lines
//! (kept beside [`super::reply`], the rest of the protocol's text).

use super::reply::error;
use super::{ErrorCode, OutLine, EVENT_TAG, OK};
use crate::calibration::{Calibration, CalibrationError, ReportRejection};
use crate::fixed::Fixed;
use crate::tune::{Rejection, TuneEvent, TuneFailure, TUNE_START_MAX_RISE_K};
use crate::vocab::Heater;
use core::fmt::Write;

/// The doc that explains TUNE, MEASURED and their settings; their refusals point to it.
pub const CALIBRATION_DOC: &str = "docs/calibration.md";
/// The section of [`CALIBRATION_DOC`] that explains the two commands (the replies name only the
/// doc, to stay within the line cap).
pub const CALIBRATION_DOC_SECTION: &str = "Tune and calibrate";

/// HELP lines of the two commands (appended to [`super::reply::HELP`]).
pub const HELP: [&str; 2] = [
    "TUNE\tfit the thermal model to this link (heats, <3 min)",
    "MEASURED <radius_mm>\tthe radius measured after the last morph (calibrates)",
];

/// TUNE accepted: `ok total_s=<s>`.
pub fn tune_started(l: &mut OutLine, total_s: f32) {
    let _ = write!(l, "{OK} total_s={}", Fixed(total_s, 0));
}

/// TUNE or MORPH or MEASURED refused while a tune runs: `error: busy a tune is running; ...`.
pub fn busy_tuning(l: &mut OutLine) {
    error(
        l,
        ErrorCode::Busy,
        format_args!("a tune is running; wait for event: tune done or send ABORT"),
    );
}

/// TUNE refused on a warm link: `error: busy the <heater> thermistor reads <k> K above
/// ambient; ...`.
pub fn tune_link_warm(l: &mut OutLine, heater: Heater, rise_k: f32) {
    error(
        l,
        ErrorCode::Busy,
        format_args!(
            "the {} thermistor reads {} K above ambient; TUNE starts from a link at rest \
             (within {} K), try again when it has cooled",
            heater.as_str(),
            Fixed(rise_k, 1),
            Fixed(TUNE_START_MAX_RISE_K, 1)
        ),
    );
}

/// MEASURED accepted after a model-strategy morph: `ok map_offset_k=<a> map_slope=<b>
/// reports=<n>`.
pub fn measured_map(l: &mut OutLine, a_k: f32, b: f32, reports: f32) {
    let _ = write!(
        l,
        "{OK} map_offset_k={} map_slope={} reports={}",
        Fixed(a_k, 2),
        Fixed(b, 3),
        Fixed(reports, 1)
    );
}

/// MEASURED accepted after a power-strategy morph: `ok power_scale=<s> reports=<n>`.
pub fn measured_power(l: &mut OutLine, scale: f32, reports: f32) {
    let _ = write!(
        l,
        "{OK} power_scale={} reports={}",
        Fixed(scale, 3),
        Fixed(reports, 1)
    );
}

/// MEASURED with nothing to attach it to.
pub fn measured_no_morph(l: &mut OutLine) {
    error(
        l,
        ErrorCode::NoFinishedMorph,
        format_args!(
            "no finished morph to attach the radius to; MORPH, wait for event: done, then \
             measure (see {CALIBRATION_DOC})"
        ),
    );
}

/// A second MEASURED for the same morph.
pub fn measured_twice(l: &mut OutLine) {
    error(
        l,
        ErrorCode::AlreadyMeasured,
        format_args!(
            "this morph's radius is already counted (each morph counts once); MORPH again"
        ),
    );
}

/// MEASURED for a morph made under another calibration (a TUNE, `CONFIG RESET` or
/// `CONFIG SET` of a calibration value since): its radius no longer says what this link does.
pub fn measured_stale(l: &mut OutLine) {
    error(
        l,
        ErrorCode::NoFinishedMorph,
        format_args!(
            "no finished morph under the current calibration (TUNE, CONFIG RESET or SET \
             changed it since); MORPH again"
        ),
    );
}

/// MEASURED outside what the link can reach: `error: out-of-range measured radius must be
/// <min>..<max> mm`.
pub fn measured_out_of_range(l: &mut OutLine, min_mm: f32, max_mm: f32) {
    error(
        l,
        ErrorCode::OutOfRange,
        format_args!(
            "measured radius must be {}..{} mm (what this link can reach)",
            Fixed(min_mm, 2),
            Fixed(max_mm, 2)
        ),
    );
}

/// MEASURED that contradicts the link's own rest-shape reading of the same morph by more than
/// both uncertainties allow: `error: out-of-range measured <mm> mm contradicts the rest-shape
/// reading <mm> ± <mm> mm; calibration unchanged, measure again (see docs/shape.md)`.
pub fn measured_contradicts(l: &mut OutLine, measured_mm: f32, read_mm: f32, sigma_mm: f32) {
    error(
        l,
        ErrorCode::OutOfRange,
        format_args!(
            "measured {} mm contradicts the rest-shape reading {} ± {} mm; calibration \
             unchanged, measure again (see docs/shape.md)",
            Fixed(measured_mm, 2),
            Fixed(read_mm, 2),
            Fixed(sigma_mm, 2)
        ),
    );
}

/// MEASURED whose correction would leave the calibration's bounds, naming the bound:
/// `error: out-of-range report refused: <why>; calibration unchanged, check the measurement
/// (see docs/calibration.md ...)`.
pub fn measured_implausible(l: &mut OutLine, why: ReportRejection) {
    error(
        l,
        ErrorCode::OutOfRange,
        format_args!(
            "report refused: {}; calibration unchanged, check the measurement (see \
             {CALIBRATION_DOC})",
            Why(why)
        ),
    );
}

/// A [`ReportRejection`] in words.
struct Why(ReportRejection);

impl core::fmt::Display for Why {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        use crate::calibration::{MAP_MAX_CORRECTION_K, MAP_SLOPE_RANGE, POWER_SCALE_RANGE};
        match self.0 {
            ReportRejection::NotFinite => f.write_str("not a finite number"),
            ReportRejection::Slope(b) => write!(
                f,
                "map slope {} outside {}..{}",
                Fixed(b, 3),
                Fixed(MAP_SLOPE_RANGE.0, 2),
                Fixed(MAP_SLOPE_RANGE.1, 2)
            ),
            ReportRejection::Correction(k) => write!(
                f,
                "map correction {} K over {} K",
                Fixed(k, 1),
                Fixed(MAP_MAX_CORRECTION_K, 1)
            ),
            ReportRejection::PowerRatio(r) => write!(
                f,
                "power ratio {} outside {}..{}",
                Fixed(r, 3),
                Fixed(POWER_SCALE_RANGE.0, 2),
                Fixed(POWER_SCALE_RANGE.1, 2)
            ),
            ReportRejection::PowerTooSmall(w) => {
                write!(f, "a table power under {} W says nothing", Fixed(w, 2))
            }
            ReportRejection::Field(info) => write!(f, "{} out of its range", info.name),
        }
    }
}

/// A calibration value refused (by index, for a settings shell).
pub fn calibration_refused(l: &mut OutLine, e: CalibrationError) {
    match e {
        CalibrationError::NoSuchField => error(
            l,
            ErrorCode::BadArgument,
            format_args!("no such calibration field"),
        ),
        CalibrationError::OutOfRange(f) => error(
            l,
            ErrorCode::OutOfRange,
            format_args!(
                "{} must be {}..{} {}",
                f.name,
                Fixed(f.min, 3),
                Fixed(f.max, 3),
                f.unit
            ),
        ),
    }
}

fn rejection(l: &mut OutLine, why: &Rejection) {
    match why {
        Rejection::NoFit => {
            let _ = l.push_str("no rising, settling record (both methods failed)");
        }
        Rejection::Extrapolated(fit_k, seen_k) => {
            let _ = write!(
                l,
                "fitted rise {} K is over {}x the {} K the record ended at (record too short)",
                Fixed(*fit_k, 1),
                Fixed(crate::tune::TUNE_MAX_EXTRAPOLATION, 1),
                Fixed(*seen_k, 1)
            );
        }
        Rejection::Residual(res_k, allowed_k) => {
            let _ = write!(
                l,
                "record strays {} K from its fitted step (allowed {} K): drifting bead?",
                Fixed(*res_k, 2),
                Fixed(*allowed_k, 2)
            );
        }
        Rejection::OutOfBounds(f, v) => {
            let _ = write!(
                l,
                "{}={} outside {}..{} {}",
                f.name,
                Fixed(*v, 2),
                Fixed(f.min, 2),
                Fixed(f.max, 2),
                f.unit
            );
        }
    }
}

/// The fitted values of a finished tune, `name=value` each.
fn fitted_values(l: &mut OutLine, c: &Calibration) {
    let _ = write!(
        l,
        "pla_rise_k_per_w={} tca_rise_k_per_w={} pla_to_tca_k_per_w={} tca_to_pla_k_per_w={} \
         pla_tau_s={} tca_tau_s={} convection_w_m2k={} tca_tcr_ppm_per_k={}",
        Fixed(c.pla_rise_k_per_w, 2),
        Fixed(c.tca_rise_k_per_w, 2),
        Fixed(c.pla_to_tca_k_per_w, 2),
        Fixed(c.tca_to_pla_k_per_w, 2),
        Fixed(c.pla_tau_s, 1),
        Fixed(c.tca_tau_s, 1),
        Fixed(c.convection_w_m2k, 1),
        Fixed(c.tca_tcr_ppm_per_k, 0)
    );
}

/// One `event: tune ...` line.
pub fn tune_event(l: &mut OutLine, e: &TuneEvent) {
    let _ = write!(l, "{EVENT_TAG} tune ");
    match e {
        TuneEvent::Step { step, t_s, power_w } => {
            let _ = write!(
                l,
                "step {} t={} power_w={}",
                step.as_str(),
                Fixed(*t_s, 1),
                Fixed(*power_w, 2)
            );
        }
        TuneEvent::Fit {
            what,
            rise_k_per_w,
            tau_s,
            method,
            residual_k,
        } => {
            let _ = write!(
                l,
                "fit {} rise_k_per_w={} tau_s={} method={} residual_k={}",
                what.as_str(),
                Fixed(*rise_k_per_w, 2),
                Fixed(*tau_s, 1),
                method.as_str(),
                Fixed(*residual_k, 2)
            );
        }
        TuneEvent::StillAir { rise_k, t_s } => {
            let _ = write!(
                l,
                "still-air pla rose {} K in {} s, far faster than in water: the still-air model \
                 is used (convection_w_m2k={})",
                Fixed(*rise_k, 1),
                Fixed(*t_s, 1),
                Fixed(crate::tune::TUNE_STILL_AIR_W_M2K, 1)
            );
        }
        TuneEvent::Kept { what, why } => {
            let _ = write!(l, "kept {} old value: ", what.as_str());
            rejection(l, why);
        }
        TuneEvent::Done(c) => {
            let _ = l.push_str("done ");
            fitted_values(l, c);
        }
        TuneEvent::Failed(f) => {
            let _ = l.push_str("failed ");
            match f {
                TuneFailure::Aborted => {
                    let _ = l.push_str("aborted");
                }
                TuneFailure::Tripped => {
                    let _ = l.push_str("safety trip (see the alarm)");
                }
                TuneFailure::Fit(what, why) => {
                    let _ = write!(l, "{} fit: ", what.as_str());
                    rejection(l, why);
                }
                TuneFailure::PlaTooFast(t_s) => {
                    let _ = write!(
                        l,
                        "pla reached its cap in {} s, faster than its power can heat it even in \
                         still air (MOSFET stuck on?)",
                        Fixed(*t_s, 1)
                    );
                }
                TuneFailure::AmbientMoved(k) => {
                    let _ = write!(
                        l,
                        "ambient moved {} K during the tune; tune in a still bath",
                        Fixed(*k, 1)
                    );
                }
                TuneFailure::TcaTooFast(rise_k) => {
                    let _ = write!(
                        l,
                        "tca rose {} K, far faster than in water or still air (is its bead on it?)",
                        Fixed(*rise_k, 1)
                    );
                }
            }
            let _ = write!(l, "; heaters off, calibration kept (see {CALIBRATION_DOC})");
        }
    }
}

/// `event: shape radius_mm=<mm> sigma_mm=<mm> learnt=<0|1>` (a shape read at rest, folded
/// into the calibration or not) or `event: shape none reason=<why>` (docs/shape.md).
pub fn shape_event(l: &mut OutLine, e: &crate::shape::ShapeEvent) {
    let _ = write!(l, "{EVENT_TAG} shape ");
    let _ = match e.none {
        None => write!(
            l,
            "radius_mm={} sigma_mm={} learnt={}",
            Fixed(e.radius_mm, 2),
            Fixed(e.sigma_mm, 2),
            if e.learnt { "1" } else { "0" }
        ),
        Some(why) => write!(l, "none reason={}", why.as_str()),
    };
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::calibration::FIELDS;
    use crate::tune::Fitted;
    extern crate std;
    use std::format;
    use std::vec::Vec;

    /// [`CALIBRATION_DOC`] (`include_str!` takes only a literal; the test checks they agree).
    const CALIBRATION_DOC_TEXT: &str = include_str!("../../docs/calibration.md");

    /// Every line that points at the doc, with the longest values its numbers can take.
    fn lines_naming_the_doc() -> Vec<OutLine> {
        let big = -12345.6;
        let mut failures = Vec::new();
        for what in [
            Fitted::Own(Heater::Pla),
            Fitted::Own(Heater::Tca),
            Fitted::PlaToTca,
            Fitted::TcaToPla,
        ] {
            failures.push(TuneFailure::Fit(what, Rejection::NoFit));
            failures.push(TuneFailure::Fit(what, Rejection::Extrapolated(big, big)));
            failures.push(TuneFailure::Fit(what, Rejection::Residual(big, big)));
            for f in FIELDS {
                failures.push(TuneFailure::Fit(what, Rejection::OutOfBounds(f, big)));
            }
        }
        failures.extend([
            TuneFailure::Aborted,
            TuneFailure::Tripped,
            TuneFailure::PlaTooFast(big),
            TuneFailure::AmbientMoved(big),
            TuneFailure::TcaTooFast(big),
        ]);
        let mut lines = Vec::new();
        for f in failures {
            let mut l = OutLine::new();
            tune_event(&mut l, &TuneEvent::Failed(f));
            lines.push(l);
        }
        let mut reports = Vec::from([
            ReportRejection::NotFinite,
            ReportRejection::Slope(big),
            ReportRejection::Correction(big),
            ReportRejection::PowerRatio(big),
            ReportRejection::PowerTooSmall(big),
        ]);
        reports.extend(FIELDS.map(ReportRejection::Field));
        for why in reports {
            let mut l = OutLine::new();
            measured_implausible(&mut l, why);
            lines.push(l);
        }
        let mut l = OutLine::new();
        measured_no_morph(&mut l);
        lines.push(l);
        lines
    }

    #[test]
    fn replies_name_a_doc_section_that_exists_whole() {
        assert_eq!(
            CALIBRATION_DOC, "docs/calibration.md",
            "the doc the test reads"
        );
        assert!(
            CALIBRATION_DOC_TEXT.contains(&format!("\n## {CALIBRATION_DOC_SECTION}\n")),
            "{CALIBRATION_DOC} has no \"## {CALIBRATION_DOC_SECTION}\" heading"
        );
        let tail = format!("(see {CALIBRATION_DOC})");
        for l in lines_naming_the_doc() {
            // Not truncated: the whole pointer fits the line.
            assert!(l.ends_with(&tail), "{l}");
        }
    }
}

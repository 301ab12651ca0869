//! Every reply, event and alarm line the firmware and the simulated builds send.
//!
//! Each function appends one line (without its ending) to an [`OutLine`]; the callers
//! (controller, stats, the simulated link) pass values, never text. Error replies are built from
//! an [`ErrorCode`] and their detail. Nothing here reaches [`OutLine`]'s capacity.

use super::{
    ErrorCode, Medium, Mode, OutLine, ProtoError, Sensor, SimFault, ALARM_TAG, DATA_TAG, ERROR_TAG,
    EVENT_TAG, OK, PROTOCOL_VERSION,
};
use crate::fixed::Fixed;
use crate::supervisor::{Fault, FaultCode, Subject, SAFETY_DOC, SUPPLY_MAX_V, SUPPLY_MIN_V};
use crate::vocab::ResetCause;
use crate::vocab::{Heater, Phase};
use core::fmt::{self, Write};

/// HELP text, one `data:` line each.
pub const HELP: [&str; 15] = [
    "MORPH <radius_mm> [auto|paper|gated|boost|closed]  morph to a radius (see RANGE)",
    "STATUS                          phase, temperatures, powers, supply, fault, targets, mode",
    "ABORT                           both heaters off at once, phase idle",
    "RESET                           clear a latched fault once its cause is gone",
    "RANGE                           reachable radii in mm",
    "TABLE                           TCA power / radius table",
    "VERSION                         firmware and protocol version",
    "HELP                            this list",
    "STATS                           control-loop timing (us) and reset cause; hardware only",
    "SIM STATE|FAULT|SUPPLY|AMBIENT|MEDIUM|WAIT|CLEAR|PANIC|STALL  simulated builds only",
    "SIM WAIT <s>                    run <s> of simulated time, then ok; morph-sim only",
    "SIM FAULT thermistor-drift <pla|tca|amb> <K/s>  reading drifts from now; negative reads low",
    "CONFIG [SET <name> <value>|RESET]  list, change or reset the settings",
    "SAVE                            write the settings to flash (idle only)",
    "HEAT <pla|tca> <power_w> <s>    one heater at a low power for a while (bring-up)",
];

/// `STATS` on a build that does not time its control loop.
pub const ERR_STATS_UNSUPPORTED: ProtoError = ProtoError {
    code: ErrorCode::Unsupported,
    text: "STATS measures the control loop on hardware; this build has none",
};

/// `SIM ...` on hardware.
pub const ERR_SIM_UNSUPPORTED: ProtoError = ProtoError {
    code: ErrorCode::Unsupported,
    text: "SIM commands exist only in simulated builds (morph-sim, the emulator)",
};

/// `SIM PANIC` on the host simulator.
pub const ERR_SIM_PANIC_UNSUPPORTED: ProtoError = ProtoError {
    code: ErrorCode::Unsupported,
    text: "SIM PANIC exists only in the emulated image",
};

/// `SIM STALL` on the host simulator.
pub const ERR_SIM_STALL_UNSUPPORTED: ProtoError = ProtoError {
    code: ErrorCode::Unsupported,
    text: "SIM STALL exists only in the emulated image",
};

/// `SIM WAIT` where the clock cannot be skipped (the emulated image runs at firmware time).
pub const ERR_SIM_WAIT_UNSUPPORTED: ProtoError = ProtoError {
    code: ErrorCode::Unsupported,
    text: "SIM WAIT needs a simulator that owns its clock (morph-sim); firmware time cannot be skipped",
};

/// A line that lost bytes on the way in (the receive buffer was full, or the UART overran): its
/// content may be pieces of two lines, so it was not run.
pub const ERR_OVERRUN: ProtoError = ProtoError {
    code: ErrorCode::Overrun,
    text:
        "Input was lost while this line arrived (receive overrun); it was not run, send it again.",
};

/// A command that would start heating (MORPH, TUNE, HEAT) read ahead of an ABORT in the same
/// read: the ABORT was acted on first and the command is not run after it.
pub const ERR_ABORTED_AHEAD: ProtoError = ProtoError {
    code: ErrorCode::Aborted,
    text: "An ABORT followed this line in the same read; the heaters stay off and it was not run.",
};

/// Replies the serial task dropped because commands arrived faster than the line could carry
/// their replies (each command was run): `error: busy <n> replies dropped; ...`. Sent once the
/// output has room again, so a flood costs one notice, and input is never what is lost.
pub fn replies_dropped(l: &mut OutLine, n: u32) {
    error(
        l,
        ErrorCode::Busy,
        format_args!(
            "{n} replies dropped: commands came faster than the serial line could answer; \
             they were run"
        ),
    );
}

/// Longest boot line, bytes: the [`OutLine`] bound less room for the line ending.
pub const BOOT_LINE_MAX: usize = 190;

/// Appends the reason of the fatal error that ended the previous run to a [`boot`] line:
/// ` panic="<reason>"`, the reason truncated so the line stays within [`BOOT_LINE_MAX`], and
/// any `"`, `\\` or non-printable character shown as `'`/`/`/`?`.
pub fn boot_panic(l: &mut OutLine, reason: &str) {
    let _ = l.push_str(" panic=\"");
    let room = BOOT_LINE_MAX.saturating_sub(l.len() + 1);
    for c in reason.chars().take(room) {
        let c = match c {
            '"' => '\'',
            '\\' => '/',
            ' '..='~' => c,
            _ => '?',
        };
        let _ = l.push(c);
    }
    let _ = l.push('"');
}

/// `error: <code> <detail>`.
pub fn error(l: &mut OutLine, code: ErrorCode, detail: fmt::Arguments<'_>) {
    let _ = write!(l, "{ERROR_TAG} {} {detail}", code.as_str());
}

/// `data: <text>`.
pub fn data(l: &mut OutLine, text: impl fmt::Display) {
    let _ = write!(l, "{DATA_TAG} {text}");
}

/// `data: <text>` for fixed text, by plain copies rather than `core::fmt`: HELP sends some
/// twenty of these in one reply, and a flood of HELP must not hold the control task up.
pub fn data_text(l: &mut OutLine, text: &str) {
    let _ = l
        .push_str(DATA_TAG)
        .and_then(|()| l.push(' '))
        .and_then(|()| l.push_str(text));
}

/// The bare success reply, `ok`.
pub fn ok(l: &mut OutLine) {
    let _ = l.push_str(OK);
}

/// `ok <fields>`.
fn ok_with(l: &mut OutLine, fields: fmt::Arguments<'_>) {
    let _ = write!(l, "{OK} {fields}");
}

/// `RANGE`: `ok min_mm=<min> max_mm=<max>`.
pub fn range(l: &mut OutLine, min_mm: f32, max_mm: f32) {
    ok_with(
        l,
        format_args!("min_mm={} max_mm={}", Fixed(min_mm, 2), Fixed(max_mm, 2)),
    );
}

/// One `TABLE` row: `data: <power_w> <radius_mm>`.
pub fn table_row(l: &mut OutLine, power_w: f32, radius_mm: f32) {
    data(
        l,
        format_args!("{} {}", Fixed(power_w, 3), Fixed(radius_mm, 2)),
    );
}

/// `VERSION`: `ok version=<firmware> protocol=<PROTOCOL_VERSION>`.
pub fn version(l: &mut OutLine, firmware: &str) {
    ok_with(
        l,
        format_args!("version={firmware} protocol={PROTOCOL_VERSION}"),
    );
}

/// What `STATUS` reports.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct StatusReport {
    /// Current phase.
    pub phase: Phase,
    /// Target radius, mm (NaN when there is none: written `-`).
    pub target_mm: f32,
    /// PLA temperature, °C.
    pub t_pla_c: f32,
    /// TCA temperature, °C.
    pub t_tca_c: f32,
    /// Ambient temperature, °C.
    pub t_amb_c: f32,
    /// PLA heater power, W.
    pub p_pla_w: f32,
    /// TCA heater power, W.
    pub p_tca_w: f32,
    /// Supply, V.
    pub supply_v: f32,
    /// The latched fault, if any.
    pub fault: Option<FaultCode>,
    /// The PLA heater's target temperature, °C (NaN when it has none: written `-`).
    pub pla_target_c: f32,
    /// The TCA heater's target temperature, °C (NaN when it has none: written `-`).
    pub tca_target_c: f32,
    /// The strategy the running or last morph ran, `auto` resolved (None before the first).
    pub mode: Option<Mode>,
}

/// `STATUS`: `ok phase= target_mm= t_pla_c= t_tca_c= t_amb_c= p_pla_w= p_tca_w= supply_v= fault=
/// pla_target_c= tca_target_c= mode=` (the last three appended in that order, so a parser of the
/// older line still finds its fields).
pub fn status(l: &mut OutLine, s: &StatusReport) {
    let _ = write!(
        l,
        "{OK} phase={} target_mm={}",
        s.phase.as_str(),
        Dash(s.target_mm)
    );
    let _ = write!(
        l,
        " t_pla_c={} t_tca_c={} t_amb_c={} p_pla_w={} p_tca_w={} supply_v={} fault={}",
        Fixed(s.t_pla_c, 2),
        Fixed(s.t_tca_c, 2),
        Fixed(s.t_amb_c, 2),
        Fixed(s.p_pla_w, 3),
        Fixed(s.p_tca_w, 3),
        Fixed(s.supply_v, 2),
        s.fault.map(|f| f.as_str()).unwrap_or("none"),
    );
    let _ = write!(
        l,
        " pla_target_c={} tca_target_c={} mode={}",
        Dash(s.pla_target_c),
        Dash(s.tca_target_c),
        s.mode.map_or("-", Mode::as_str)
    );
}

/// A value with 2 decimals, or `-` for NaN (no value).
struct Dash(f32);

impl fmt::Display for Dash {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.0.is_nan() {
            f.write_str("-")
        } else {
            Fixed(self.0, 2).fmt(f)
        }
    }
}

/// MORPH refused: `error: fault-latched <code> is latched; ...`.
pub fn fault_latched(l: &mut OutLine, code: FaultCode) {
    error(
        l,
        ErrorCode::FaultLatched,
        format_args!(
            "{} is latched; send RESET once it has cleared",
            code.as_str()
        ),
    );
}

/// MORPH refused while a morph runs: `error: busy a morph is in phase <phase>; ...`.
pub fn busy_morphing(l: &mut OutLine, phase: Phase) {
    error(
        l,
        ErrorCode::Busy,
        format_args!("a morph is in phase {}; send ABORT first", phase.as_str()),
    );
}

/// MORPH refused before the first sensor frame: `error: busy no sensor reading yet; ...`.
pub fn busy_no_reading(l: &mut OutLine) {
    error(
        l,
        ErrorCode::Busy,
        format_args!("no sensor reading yet; try again in a moment"),
    );
}

/// MORPH radius outside the table: `error: out-of-range reachable=<min>..<max>`.
pub fn radius_out_of_range(l: &mut OutLine, min_mm: f32, max_mm: f32) {
    error(
        l,
        ErrorCode::OutOfRange,
        format_args!("reachable={}..{}", Fixed(min_mm, 2), Fixed(max_mm, 2)),
    );
}

/// RESET with nothing latched: `ok fault=none`.
pub fn reset_nothing(l: &mut OutLine) {
    ok_with(l, format_args!("fault=none"));
}

/// RESET cleared a fault: `ok cleared=<code>`.
pub fn reset_cleared(l: &mut OutLine, code: FaultCode) {
    ok_with(l, format_args!("cleared={}", code.as_str()));
}

/// RESET refused: `error: fault-active <code> <sentence>`.
pub fn fault_active(l: &mut OutLine, still: &Fault) {
    error(
        l,
        ErrorCode::FaultActive,
        format_args!("{}", FaultText(still)),
    );
}

/// `event: phase <phase> t=<s>[ power_w=<W>]`.
pub fn phase_event(l: &mut OutLine, phase: Phase, t_s: f32, power_w: Option<f32>) {
    let _ = write!(
        l,
        "{EVENT_TAG} phase {} t={}",
        phase.as_str(),
        Fixed(t_s, 1)
    );
    if let Some(p) = power_w {
        let _ = write!(l, " power_w={}", Fixed(p, 3));
    }
}

/// `event: done t=<s> radius_mm=<mm>`.
pub fn done_event(l: &mut OutLine, t_s: f32, radius_mm: f32) {
    let _ = write!(
        l,
        "{EVENT_TAG} done t={} radius_mm={}",
        Fixed(t_s, 1),
        Fixed(radius_mm, 2)
    );
}

/// The alarm line of a trip: `alarm: <code> <sentence>; heaters off, RESET when cleared
/// (<settings>; see docs/safety.md)`, naming the settings that govern it and the doc whose
/// `SAFETY_DOC_SECTION` explains them (Klipper's habit; the heading is left out to keep
/// the line within its cap).
pub fn alarm(l: &mut OutLine, f: &Fault) {
    let _ = write!(
        l,
        "{ALARM_TAG} {}; heaters off, RESET when cleared ({}; see {SAFETY_DOC})",
        FaultText(f),
        f.settings()
    );
}

/// The line the firmware sends once at boot:
/// `event: boot reset=<cause> board=<name> version=<v>`.
pub fn boot(l: &mut OutLine, cause: ResetCause, board: &str, firmware: &str) {
    let _ = write!(
        l,
        "{EVENT_TAG} boot reset={} board={} version={}",
        cause.as_str(),
        board,
        firmware
    );
}

/// What `STATS` reports, µs unless named otherwise.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct StatsReport {
    /// Ticks since boot.
    pub ticks: u32,
    /// Last step time.
    pub step_us: u32,
    /// Longest step time.
    pub step_max_us: u32,
    /// Longest ADC burst.
    pub adc_max_us: u32,
    /// Shortest tick period (0 before two ticks).
    pub period_min_us: u32,
    /// Longest tick period (0 before two ticks).
    pub period_max_us: u32,
    /// Largest deviation of a period from nominal.
    pub jitter_max_us: u32,
    /// Late ticks.
    pub late: u32,
    /// Why the chip last reset.
    pub reset: ResetCause,
}

/// `STATS`: `ok ticks= step_us= step_max_us= adc_max_us= period_min_us= period_max_us=
/// jitter_max_us= late= reset=`.
pub fn stats(l: &mut OutLine, s: &StatsReport) {
    ok_with(
        l,
        format_args!(
            "ticks={} step_us={} step_max_us={} adc_max_us={} period_min_us={} \
             period_max_us={} jitter_max_us={} late={} reset={}",
            s.ticks,
            s.step_us,
            s.step_max_us,
            s.adc_max_us,
            s.period_min_us,
            s.period_max_us,
            s.jitter_max_us,
            s.late,
            s.reset.as_str()
        ),
    );
}

/// `SIM STATE`: `ok time_s= radius_mm= t_pla_c= t_tca_c=` (the simulated truth).
pub fn sim_state(l: &mut OutLine, time_s: f32, radius_mm: f32, t_pla_c: f32, t_tca_c: f32) {
    ok_with(
        l,
        format_args!(
            "time_s={} radius_mm={} t_pla_c={} t_tca_c={}",
            Fixed(time_s, 1),
            Fixed(radius_mm, 2),
            Fixed(t_pla_c, 2),
            Fixed(t_tca_c, 2)
        ),
    );
}

/// `SIM FAULT`: `ok fault=<kind> target=<sensor>`.
pub fn sim_fault(l: &mut OutLine, kind: SimFault, target: Sensor) {
    ok_with(
        l,
        format_args!("fault={} target={}", kind.as_str(), target.as_str()),
    );
}

/// `SIM SUPPLY`: `ok supply_v=<V>`.
pub fn sim_supply(l: &mut OutLine, supply_v: f32) {
    ok_with(l, format_args!("supply_v={}", Fixed(supply_v, 2)));
}

/// `SIM SUPPLY` refused: `error: out-of-range supply must be 0..<max> V`.
pub fn sim_supply_out_of_range(l: &mut OutLine, max_v: f32) {
    error(
        l,
        ErrorCode::OutOfRange,
        format_args!("supply must be 0..{} V", Fixed(max_v, 0)),
    );
}

/// `SIM AMBIENT`: `ok t_amb_c=<°C>`.
pub fn sim_ambient(l: &mut OutLine, t_amb_c: f32) {
    ok_with(l, format_args!("t_amb_c={}", Fixed(t_amb_c, 2)));
}

/// `SIM AMBIENT` refused: `error: out-of-range ambient must be <lo>..<hi> C`.
pub fn sim_ambient_out_of_range(l: &mut OutLine, lo_c: f32, hi_c: f32) {
    error(
        l,
        ErrorCode::OutOfRange,
        format_args!("ambient must be {}..{} C", Fixed(lo_c, 0), Fixed(hi_c, 0)),
    );
}

/// `SIM MEDIUM`: `ok medium=<water|air>`.
pub fn sim_medium(l: &mut OutLine, m: Medium) {
    ok_with(l, format_args!("medium={}", m.as_str()));
}

/// `SIM WAIT` refused: `error: out-of-range wait must be 0..<max> s`.
pub fn sim_wait_out_of_range(l: &mut OutLine, max_s: f32) {
    error(
        l,
        ErrorCode::OutOfRange,
        format_args!("wait must be 0..{} s", Fixed(max_s, 0)),
    );
}

/// A `SIM` setting the plant refused (`SIM SUPPLY`, `SIM AMBIENT`, `SIM MEDIUM` on a plant
/// that cannot change it): `error: unsupported SIM <WORD>: the plant cannot change that`.
pub fn sim_setting_unsupported(l: &mut OutLine, setting: SimSetting) {
    error(
        l,
        ErrorCode::Unsupported,
        format_args!("SIM {}: the plant cannot change that", setting.as_str()),
    );
}

/// A `SIM` command that changes the plant (for [`sim_setting_unsupported`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SimSetting {
    /// `SIM SUPPLY`.
    Supply,
    /// `SIM AMBIENT`.
    Ambient,
    /// `SIM MEDIUM`.
    Medium,
}

impl SimSetting {
    /// The command's word.
    pub fn as_str(self) -> &'static str {
        match self {
            SimSetting::Supply => "SUPPLY",
            SimSetting::Ambient => "AMBIENT",
            SimSetting::Medium => "MEDIUM",
        }
    }
}

/// The word of a fault's subject.
fn subject_str(s: &Subject) -> &'static str {
    match s {
        Subject::Sensor(x) => x.as_str(),
        Subject::Heater(h) => h.as_str(),
        Subject::Phase(p) => p.as_str(),
        Subject::Supply => "supply",
        Subject::Frame => "sensors",
    }
}

/// `<code> <sentence>` for a fault (alarms and `fault-active`).
struct FaultText<'a>(&'a Fault);

impl fmt::Display for FaultText<'_> {
    fn fmt(&self, l: &mut fmt::Formatter<'_>) -> fmt::Result {
        let f = self.0;
        let s = subject_str(&f.subject);
        let v = Fixed(f.value, 1);
        match f.code {
            FaultCode::ThermistorOpen => write!(
                l,
                "thermistor-open {s} thermistor reads open circuit; check its wiring"
            ),
            FaultCode::ThermistorShort => write!(
                l,
                "thermistor-short {s} thermistor reads short circuit; check its wiring"
            ),
            FaultCode::UnderTemperature => {
                write!(l, "under-temperature {s} reads {v} C, below its minimum")
            }
            FaultCode::OverTemperature if matches!(f.subject, Subject::Heater(_)) => write!(
                l,
                "over-temperature {s} part estimated {v} C from its thermistor, above its maximum"
            ),
            FaultCode::OverTemperature => {
                write!(l, "over-temperature {s} reads {v} C, above its maximum")
            }
            FaultCode::HeaterNotHeating => {
                write!(l, "heater-not-heating {s} rose {v} K; check wiring, MOSFET")
            }
            FaultCode::HeatingWhileOff => {
                write!(l, "heating-while-off {s} rose {v} K; check its MOSFET")
            }
            FaultCode::StaleSensor => write!(l, "stale-sensor no sensor frame for {v} s"),
            FaultCode::SupplyOutOfRange => write!(
                l,
                "supply-out-of-range supply reads {v} V, allowed {}..{}",
                Fixed(SUPPLY_MIN_V, 1),
                Fixed(SUPPLY_MAX_V, 1)
            ),
            FaultCode::PhaseTimeout => write!(l, "phase-timeout phase {s} did not finish in time"),
            FaultCode::SensorFrozen => {
                write!(l, "sensor-frozen {s} moved {v} K")
            }
            FaultCode::SensorImplausible if f.subject == Subject::Sensor(Sensor::Amb) => {
                write!(
                    l,
                    "sensor-implausible {s} drifts {} K/s steadily",
                    Fixed(f.value, 2)
                )
            }
            FaultCode::SensorImplausible if matches!(f.subject, Subject::Heater(_)) => write!(
                l,
                "sensor-implausible {s} heater alone, tca gains {v} K more; check wiring, tca MOSFET"
            ),
            FaultCode::SensorImplausible => {
                write!(l, "sensor-implausible {s} off its expected rise by {v} K")
            }
        }
    }
}

/// HEAT power or duration outside its bounds (`crate::pulse`): one text for both (flash).
pub const ERR_HEAT_RANGE: ProtoError = ProtoError {
    code: ErrorCode::OutOfRange,
    text: "HEAT power must be above 0 and at most 20 % of the heater's cap (pla 1 W, tca 0.4 W), for more than 0 and at most 60 s.",
};

/// HEAT refused because its heater has had its pulse time for the window:
/// `error: busy <heater> has <s> s of HEAT left in this window ...`.
pub fn heat_budget(l: &mut OutLine, heater: Heater, left_s: f32) {
    error(
        l,
        ErrorCode::Busy,
        format_args!(
            "{} has {} s of HEAT left: at most {} s per heater in any {} s, the rest is back \
             as it cools",
            heater.as_str(),
            Fixed(left_s.max(0.0), 1),
            Fixed(crate::pulse::HEAT_MAX_S, 0),
            Fixed(crate::pulse::HEAT_WINDOW_S, 0)
        ),
    );
}

/// MORPH refused while a HEAT pulse runs.
pub const ERR_BUSY_HEATING: ProtoError = ProtoError {
    code: ErrorCode::Busy,
    text: "a HEAT pulse runs; send ABORT first",
};
/// `SIM FAULT thermistor-drift`: `ok fault=thermistor-drift target=<sensor> rate_k_per_s=<K/s>`.
pub fn sim_fault_drift(l: &mut OutLine, target: Sensor, rate_k_per_s: f32) {
    ok_with(
        l,
        format_args!(
            "fault={} target={} rate_k_per_s={}",
            SimFault::ThermistorDrift.as_str(),
            target.as_str(),
            Fixed(rate_k_per_s, 3)
        ),
    );
}

/// `SIM FAULT thermistor-drift` refused: `error: out-of-range drift must be -<max>..<max> K/s`.
pub fn sim_drift_out_of_range(l: &mut OutLine, max_k_per_s: f32) {
    error(
        l,
        ErrorCode::OutOfRange,
        format_args!(
            "drift must be -{}..{} K/s",
            Fixed(max_k_per_s, 1),
            Fixed(max_k_per_s, 1)
        ),
    );
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::format_error;

    fn line(f: impl FnOnce(&mut OutLine)) -> OutLine {
        let mut l = OutLine::new();
        f(&mut l);
        l
    }

    #[test]
    fn data_text_is_the_data_line_of_its_text() {
        for h in HELP {
            assert_eq!(line(|l| data_text(l, h)), line(|l| data(l, h)), "{h}");
        }
        assert_eq!(line(|l| data_text(l, "")).as_str(), "data: ");
    }

    #[test]
    fn boot_line_with_a_panic_reason_stays_in_bounds() {
        let l = line(|l| {
            boot(l, ResetCause::Software, "nucleo-f401re", "0.1.0");
            boot_panic(l, "panicked at src/x.rs:1:2: \"quoted\" \\ é\n");
        });
        assert_eq!(
            l.as_str(),
            "event: boot reset=software board=nucleo-f401re version=0.1.0 \
             panic=\"panicked at src/x.rs:1:2: 'quoted' / ??\""
        );
        let long = "x".repeat(500);
        let l = line(|l| {
            boot(l, ResetCause::Watchdog, "b-l475e-iot01a-emulated", "0.1.0");
            boot_panic(l, &long);
        });
        assert_eq!(l.len(), BOOT_LINE_MAX);
        assert!(l.ends_with("xx\""), "{l}");
        let l = line(|l| replies_dropped(l, 37));
        assert!(l.starts_with("error: busy 37 replies dropped"), "{l}");
        assert_eq!(
            format_error(&ERR_OVERRUN).split(' ').nth(1),
            Some("overrun")
        );
    }

    #[test]
    fn status_ends_with_the_targets_and_mode_and_fits_the_line_at_its_widest() {
        let report = |phase, fault, targets: (f32, f32)| StatusReport {
            phase,
            target_mm: 38.0,
            t_pla_c: 74.171,
            t_tca_c: 56.88,
            t_amb_c: 21.94,
            p_pla_w: 1.25,
            p_tca_w: 0.7,
            supply_v: 12.0,
            fault,
            pla_target_c: targets.0,
            tca_target_c: targets.1,
            mode: Some(Mode::Closed),
        };
        let l = line(|l| status(l, &report(Phase::Bend, None, (75.0, 62.5))));
        assert_eq!(
            l.as_str(),
            "ok phase=bend target_mm=38.00 t_pla_c=74.17 t_tca_c=56.88 t_amb_c=21.94 \
             p_pla_w=1.250 p_tca_w=0.700 supply_v=12.00 fault=none \
             pla_target_c=75.00 tca_target_c=62.50 mode=closed"
        );
        let idle = StatusReport {
            target_mm: f32::NAN,
            mode: None,
            ..report(Phase::Idle, None, (f32::NAN, f32::NAN))
        };
        let l = line(|l| status(l, &idle));
        assert!(
            l.ends_with("fault=none pla_target_c=- tca_target_c=- mode=-"),
            "{l}"
        );
        // The widest values a link gives: every temperature at five digits with a sign, the
        // heaters at their caps, the longest fault word; the line must end whole.
        for (phase, fault, targets) in [
            (Phase::Release, None, (75.0, 110.0)),
            (
                Phase::Fault,
                Some(FaultCode::SupplyOutOfRange),
                (f32::NAN, f32::NAN),
            ),
            (
                Phase::Fault,
                Some(FaultCode::HeaterNotHeating),
                (f32::NAN, f32::NAN),
            ),
        ] {
            let wide = StatusReport {
                target_mm: 99.99,
                t_pla_c: -99.99,
                t_tca_c: -99.99,
                t_amb_c: -99.99,
                p_pla_w: 5.0,
                p_tca_w: 5.0,
                supply_v: 99.99,
                ..report(phase, fault, targets)
            };
            let l = line(|l| status(l, &wide));
            assert!(l.ends_with(" mode=closed"), "truncated: {l}");
            assert!(l.len() < l.capacity(), "{} bytes: {l}", l.len());
        }
    }

    #[test]
    fn sim_replies() {
        let l = line(|l| sim_state(l, 12.34, 38.456, 70.0, 40.125));
        assert_eq!(
            l,
            "ok time_s=12.3 radius_mm=38.46 t_pla_c=70.00 t_tca_c=40.13"
        );
        let l = line(|l| sim_fault(l, SimFault::HeaterOpen, Sensor::Tca));
        assert_eq!(l, "ok fault=heater-open target=tca");
        assert_eq!(
            line(|l| sim_fault_drift(l, Sensor::Tca, -0.2)),
            "ok fault=thermistor-drift target=tca rate_k_per_s=-0.200"
        );
        assert_eq!(
            line(|l| sim_drift_out_of_range(l, 10.0)),
            "error: out-of-range drift must be -10.0..10.0 K/s"
        );
        assert_eq!(line(|l| sim_supply(l, 5.0)), "ok supply_v=5.00");
        assert_eq!(
            line(|l| sim_supply_out_of_range(l, 30.0)),
            "error: out-of-range supply must be 0..30 V"
        );
        assert_eq!(line(|l| sim_ambient(l, -5.0)), "ok t_amb_c=-5.00");
        assert_eq!(
            line(|l| sim_ambient_out_of_range(l, -10.0, 60.0)),
            "error: out-of-range ambient must be -10..60 C"
        );
        assert_eq!(line(|l| sim_medium(l, Medium::Air)), "ok medium=air");
        assert_eq!(
            line(|l| sim_wait_out_of_range(l, 3600.0)),
            "error: out-of-range wait must be 0..3600 s"
        );
        assert_eq!(
            line(|l| sim_setting_unsupported(l, SimSetting::Medium)),
            "error: unsupported SIM MEDIUM: the plant cannot change that"
        );
        assert_eq!(
            format_error(&ERR_SIM_WAIT_UNSUPPORTED),
            "error: unsupported SIM WAIT needs a simulator that owns its clock (morph-sim); \
             firmware time cannot be skipped"
        );
        assert_eq!(line(ok), "ok");
        assert_eq!(
            format_error(&ERR_SIM_PANIC_UNSUPPORTED),
            "error: unsupported SIM PANIC exists only in the emulated image"
        );
    }

    #[test]
    fn every_error_code_is_built_from_its_variant() {
        let fault = Fault {
            code: FaultCode::StaleSensor,
            subject: Subject::Frame,
            value: 1.0,
        };
        let cases = [
            (line(busy_no_reading), ErrorCode::Busy),
            (line(|l| busy_morphing(l, Phase::Bend)), ErrorCode::Busy),
            (
                line(|l| fault_latched(l, FaultCode::StaleSensor)),
                ErrorCode::FaultLatched,
            ),
            (line(|l| fault_active(l, &fault)), ErrorCode::FaultActive),
            (
                line(|l| radius_out_of_range(l, 30.0, 46.0)),
                ErrorCode::OutOfRange,
            ),
            (
                line(|l| sim_supply_out_of_range(l, 30.0)),
                ErrorCode::OutOfRange,
            ),
            (format_error(&ERR_STATS_UNSUPPORTED), ErrorCode::Unsupported),
            (format_error(&ERR_SIM_UNSUPPORTED), ErrorCode::Unsupported),
        ];
        for (l, code) in cases {
            let rest = l.strip_prefix("error: ").expect("an error line");
            assert!(rest.starts_with(code.as_str()), "{l}");
            assert!(crate::protocol::classify(&l) == crate::protocol::LineKind::Error);
        }
        assert_eq!(
            line(|l| busy_morphing(l, Phase::Bend)),
            "error: busy a morph is in phase bend; send ABORT first"
        );
        assert_eq!(
            line(|l| fault_active(l, &fault)),
            "error: fault-active stale-sensor no sensor frame for 1.0 s"
        );
    }

    #[test]
    fn version_names_the_protocol_version() {
        let l = line(|l| version(l, "0.1.0"));
        assert_eq!(l, "ok version=0.1.0 protocol=1");
        assert_eq!(PROTOCOL_VERSION, 1);
    }
}

#[cfg(test)]
mod alarm_tests {
    use super::*;
    use crate::supervisor::{Fault, FaultCode, Subject, SAFETY_DOC_SECTION};
    use crate::vocab::Phase;
    use crate::vocab::{Heater, Sensor};
    extern crate std;
    use std::format;
    use std::vec::Vec;

    /// [`SAFETY_DOC`] (`include_str!` takes only a literal; the test checks they agree).
    const SAFETY_DOC_TEXT: &str = include_str!("../../docs/safety.md");

    /// Every kind of trip, with every subject it can have.
    fn every_fault() -> Vec<Fault> {
        let sensors = Sensor::ALL.map(Subject::Sensor);
        let phases = [Phase::Soften, Phase::Bend, Phase::Lock, Phase::Release].map(Subject::Phase);
        let heaters = Heater::ALL.map(Subject::Heater);
        let cases: [(FaultCode, &[Subject]); 13] = [
            (FaultCode::ThermistorOpen, &sensors),
            (FaultCode::ThermistorShort, &sensors),
            (FaultCode::UnderTemperature, &sensors),
            (FaultCode::OverTemperature, &sensors),
            (FaultCode::OverTemperature, &heaters),
            (FaultCode::HeaterNotHeating, &heaters),
            (FaultCode::HeatingWhileOff, &heaters),
            (FaultCode::StaleSensor, &[Subject::Frame]),
            (FaultCode::SupplyOutOfRange, &[Subject::Supply]),
            (FaultCode::PhaseTimeout, &phases),
            (FaultCode::SensorFrozen, &sensors),
            (FaultCode::SensorImplausible, &sensors),
            (FaultCode::SensorImplausible, &heaters),
        ];
        cases
            .iter()
            .flat_map(|(code, subjects)| {
                subjects.iter().map(move |&subject| Fault {
                    code: *code,
                    subject,
                    value: -123.4,
                })
            })
            .collect()
    }

    /// The safety doc's section `heading` (a `## ` heading), up to the next `## ` heading.
    fn doc_section(heading: &str) -> &'static str {
        let start = SAFETY_DOC_TEXT
            .find(&format!("\n## {heading}\n"))
            .unwrap_or_else(|| panic!("{SAFETY_DOC} has no \"## {heading}\" heading"));
        let body = &SAFETY_DOC_TEXT[start + 1..];
        let end = body[3..].find("\n## ").map_or(body.len(), |e| e + 3);
        &body[..end]
    }

    #[test]
    fn every_alarm_names_its_settings_and_a_doc_section_that_explains_them() {
        assert_eq!(SAFETY_DOC, "docs/safety.md", "the doc the test reads");
        let section = doc_section(SAFETY_DOC_SECTION);
        for f in every_fault() {
            let mut l = OutLine::new();
            alarm(&mut l, &f);
            assert!(
                l.starts_with(&format!("alarm: {} ", f.code.as_str())),
                "{l}"
            );
            let tail = format!(
                "; heaters off, RESET when cleared ({}; see {SAFETY_DOC})",
                f.settings()
            );
            // Not truncated: the whole suffix fits the line.
            assert!(l.ends_with(&tail), "{l}");
            for setting in f.settings().split(", ") {
                assert!(
                    section.contains(&format!("`{setting}`")),
                    "{SAFETY_DOC} \"{SAFETY_DOC_SECTION}\" does not explain `{setting}` ({l})"
                );
            }
        }
    }
}

// ---- Settings: CONFIG, CONFIG SET, CONFIG RESET, SAVE and the boot's config event. ----

/// Where the settings are explained; their errors point to it.
pub const SETTINGS_DOC: &str = "docs/settings.md";

/// One setting as `CONFIG` shows it (the caller copies it from the settings registry).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SettingRow<'a> {
    /// Wire name.
    pub name: &'a str,
    /// Unit (`-` for a choice).
    pub unit: &'a str,
    /// Current value (a choice's index).
    pub value: f32,
    /// Compiled-in value.
    pub default: f32,
    /// Smallest allowed value.
    pub min: f32,
    /// Largest allowed value.
    pub max: f32,
    /// Decimals to show.
    pub decimals: u8,
    /// A choice's words (empty for a number).
    pub choices: &'a [&'a str],
}

impl SettingRow<'_> {
    fn word(&self, v: f32) -> &str {
        self.choices.get(v as usize).copied().unwrap_or("?")
    }
}

/// The value `v` of `r` as the wire shows it: a number with its decimals, or a choice's word.
struct SettingValue<'a>(&'a SettingRow<'a>, f32);

impl fmt::Display for SettingValue<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.0.choices.is_empty() {
            write!(f, "{}", Fixed(self.1, self.0.decimals))
        } else {
            f.write_str(self.0.word(self.1))
        }
    }
}

/// The allowed values of `r`: `<min>..<max> <unit>` or `<word>|<word>|...`.
struct SettingRange<'a>(&'a SettingRow<'a>);

impl fmt::Display for SettingRange<'_> {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let r = self.0;
        if r.choices.is_empty() {
            let d = r.decimals;
            write!(f, "{}..{} {}", Fixed(r.min, d), Fixed(r.max, d), r.unit)
        } else {
            for (i, w) in r.choices.iter().enumerate() {
                if i > 0 {
                    f.write_str("|")?;
                }
                f.write_str(w)?;
            }
            Ok(())
        }
    }
}

/// One `CONFIG` line: `data: <name>=<value> <unit> range=<min>..<max> default=<d>`, or for a
/// choice `data: <name>=<word> choices=<a>|<b>|... default=<word>`.
pub fn config_row(l: &mut OutLine, r: &SettingRow) {
    if r.choices.is_empty() {
        data(
            l,
            format_args!(
                "{}={} {} range={}..{} default={}",
                r.name,
                SettingValue(r, r.value),
                r.unit,
                Fixed(r.min, r.decimals),
                Fixed(r.max, r.decimals),
                SettingValue(r, r.default)
            ),
        );
    } else {
        data(
            l,
            format_args!(
                "{}={} choices={} default={}",
                r.name,
                SettingValue(r, r.value),
                SettingRange(r),
                SettingValue(r, r.default)
            ),
        );
    }
}

/// The end of `CONFIG`: `ok settings=<n>`.
pub fn config_end(l: &mut OutLine, count: usize) {
    ok_with(l, format_args!("settings={count}"));
}

/// `CONFIG SET` done: `ok <name>=<value> saved=no` (SAVE keeps it across a restart).
pub fn config_set(l: &mut OutLine, r: &SettingRow) {
    ok_with(
        l,
        format_args!("{}={} saved=no", r.name, SettingValue(r, r.value)),
    );
}

/// `CONFIG RESET` done: `ok config=defaults saved=no`.
pub fn config_reset(l: &mut OutLine) {
    ok_with(l, format_args!("config=defaults saved=no"));
}

/// `CONFIG SET` of a name no setting has:
/// `error: bad-argument no setting named <name>; send CONFIG for the list (docs/settings.md)`.
pub fn config_unknown(l: &mut OutLine, name: &str) {
    error(
        l,
        ErrorCode::BadArgument,
        format_args!("no setting named {name}; send CONFIG for the list ({SETTINGS_DOC})"),
    );
}

/// `CONFIG SET` of a value that is no number (or no choice's word):
/// `error: bad-argument <name> takes <range> (docs/settings.md)`.
pub fn config_malformed(l: &mut OutLine, r: &SettingRow) {
    let what = if r.choices.is_empty() {
        "a number in"
    } else {
        "one of"
    };
    error(
        l,
        ErrorCode::BadArgument,
        format_args!(
            "{} takes {what} {} ({SETTINGS_DOC})",
            r.name,
            SettingRange(r)
        ),
    );
}

/// `CONFIG SET` of a value outside the range:
/// `error: out-of-range <name>=<v> <unit> is outside <min>..<max> <unit> (docs/settings.md)`.
pub fn config_out_of_range(l: &mut OutLine, r: &SettingRow, v: f32) {
    error(
        l,
        ErrorCode::OutOfRange,
        format_args!(
            "{}={} {} is outside {} ({SETTINGS_DOC})",
            r.name,
            Fixed(v, r.decimals.max(1)),
            r.unit,
            SettingRange(r)
        ),
    );
}

/// `CONFIG SET` of a calibration value that leaves a rise out of line with the model:
/// `error: out-of-range <name>=<v> <unit> puts <field> at <share>x the model's rise at
/// convection_w_m2k=<h>, outside <lo>..<hi>x (docs/settings.md)`.
pub fn config_inconsistent(
    l: &mut OutLine,
    r: &SettingRow,
    v: f32,
    why: &crate::calibration::Inconsistent,
    convection_w_m2k: f32,
) {
    error(
        l,
        ErrorCode::OutOfRange,
        format_args!(
            "{}={} {} puts {} at {}x the model's rise at convection_w_m2k={}, outside {}..{}x ({SETTINGS_DOC})",
            r.name,
            Fixed(v, r.decimals.max(1)),
            r.unit,
            why.field.name,
            Fixed(why.share, 2),
            Fixed(convection_w_m2k, 1),
            Fixed(why.allowed.0, 1),
            Fixed(why.allowed.1, 1)
        ),
    );
}

/// `CONFIG SET`, `CONFIG RESET` or `SAVE` while a morph runs:
/// `error: busy settings stay as they are while a morph, TUNE or HEAT runs (phase <p>); ABORT or
/// wait for done`.
pub fn config_busy(l: &mut OutLine, phase: Phase) {
    error(
        l,
        ErrorCode::Busy,
        format_args!(
            "settings stay as they are while a morph, TUNE or HEAT runs (phase {}); ABORT or wait for done",
            phase.as_str()
        ),
    );
}

/// `SAVE` done: `ok saved bytes=<n> erases=<n>` (the blob's size and the pages it erased).
pub fn saved(l: &mut OutLine, bytes: u32, erases: u32) {
    ok_with(l, format_args!("saved bytes={bytes} erases={erases}"));
}

/// `SAVE` failed: `error: storage SAVE failed (<why>); the previous settings stay in flash`.
pub fn save_failed(l: &mut OutLine, why: &str) {
    error(
        l,
        ErrorCode::Storage,
        format_args!("SAVE failed ({why}); the previous settings stay in flash"),
    );
}

/// `SAVE` on a build without settings storage.
pub const ERR_SAVE_UNSUPPORTED: ProtoError = ProtoError {
    code: ErrorCode::Unsupported,
    text: "SAVE needs settings storage and this build has none (morph-sim: --flash-file PATH)",
};

/// At boot, the stored settings were loaded: `event: config loaded settings=<n>`, or, when
/// they are the previous SAVE's because the newest is damaged (`skipped` is why),
/// `event: config loaded settings=<n> save=previous reason=<why>`: the user learns that the
/// last SAVE did not hold, rather than running older values unawares.
pub fn config_loaded_event(l: &mut OutLine, count: usize, skipped: Option<&str>) {
    let _ = write!(l, "{EVENT_TAG} config loaded settings={count}");
    if let Some(why) = skipped {
        let _ = write!(l, " save=previous reason={why}");
    }
}

/// At boot, the defaults are in force: `event: config defaults reason=<why>[ setting=<name>]`
/// (`setting` names a stored value that was out of its range).
pub fn config_defaults_event(l: &mut OutLine, reason: &str, setting: Option<&str>) {
    let _ = write!(l, "{EVENT_TAG} config defaults reason={reason}");
    if let Some(s) = setting {
        let _ = write!(l, " setting={s}");
    }
}

#[cfg(test)]
mod settings_tests {
    use super::*;
    use crate::protocol::format_error;

    const TIMEOUT: SettingRow = SettingRow {
        name: "soften_timeout_s",
        unit: "s",
        value: 45.0,
        default: 60.0,
        min: 20.0,
        max: 120.0,
        decimals: 0,
        choices: &[],
    };
    const MODE: SettingRow = SettingRow {
        name: "auto_mode",
        unit: "-",
        value: 1.0,
        default: 3.0,
        min: 0.0,
        max: 3.0,
        decimals: 0,
        choices: &["paper", "gated", "boost", "closed"],
    };

    fn line(f: impl FnOnce(&mut OutLine)) -> OutLine {
        let mut l = OutLine::new();
        f(&mut l);
        l
    }

    #[test]
    fn settings_lines_name_the_setting_unit_and_range() {
        assert_eq!(
            line(|l| config_row(l, &TIMEOUT)),
            "data: soften_timeout_s=45 s range=20..120 default=60"
        );
        assert_eq!(
            line(|l| config_row(l, &MODE)),
            "data: auto_mode=gated choices=paper|gated|boost|closed default=closed"
        );
        assert_eq!(
            line(|l| config_set(l, &MODE)),
            "ok auto_mode=gated saved=no"
        );
        assert_eq!(
            line(|l| config_out_of_range(l, &TIMEOUT, 500.0)),
            "error: out-of-range soften_timeout_s=500.0 s is outside 20..120 s (docs/settings.md)"
        );
        assert_eq!(
            line(|l| config_malformed(l, &MODE)),
            "error: bad-argument auto_mode takes one of paper|gated|boost|closed (docs/settings.md)"
        );
        assert_eq!(
            line(|l| config_loaded_event(l, 21, None)),
            "event: config loaded settings=21"
        );
        assert_eq!(
            line(|l| config_loaded_event(l, 21, Some("crc-mismatch"))),
            "event: config loaded settings=21 save=previous reason=crc-mismatch"
        );
        assert_eq!(
            line(|l| config_defaults_event(l, "out-of-range", Some("lock_timeout_s"))),
            "event: config defaults reason=out-of-range setting=lock_timeout_s"
        );
        for l in [
            line(|l| config_unknown(l, "x")),
            line(|l| config_busy(l, Phase::Bend)),
            line(|l| save_failed(l, "flash-error")),
            format_error(&ERR_SAVE_UNSUPPORTED),
        ] {
            assert_eq!(
                crate::protocol::classify(&l),
                crate::protocol::LineKind::Error,
                "{l}"
            );
        }
    }
}

//! STATUS, the morph's events (`event: phase`, `event: done`), the boot line, STATS, and
//! the replies of the commands that start or refuse a morph or a pulse.

use super::alarm::FaultText;
use super::*;

/// `RANGE`: `ok min_mm=<min> max_mm=<max>`.
pub fn range(l: &mut OutLine, min_mm: f32, max_mm: f32) {
    ok_with(
        l,
        format_args!(
            "min_mm={} max_mm={}",
            Fixed::up2(min_mm),
            Fixed::down2(max_mm)
        ),
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
    /// Each heater's current while driven (PLA, TCA), A (NaN where not sensed: `-`).
    pub current_a: [f32; 2],
    /// Each heater's measured resistance (PLA, TCA), Ω (NaN where not sensed: `-`).
    pub resistance_ohm: [f32; 2],
    /// The TCA's mean temperature from its own resistance, °C (NaN where not sensed: `-`).
    pub t_tca_self_c: f32,
    /// The heater supply's cut-off is closed.
    pub supply_on: bool,
    /// The link's radius read at rest after the last morph and its sigma, mm (NaN while none:
    /// `-`; docs/shape.md).
    pub shape_mm: [f32; 2],
}

/// `STATUS`: `ok phase= target_mm= t_pla_c= t_tca_c= t_amb_c= p_pla_w= p_tca_w= supply_v= fault=
/// pla_target_c= tca_target_c= mode= i_pla_a= i_tca_a= r_pla_ohm= r_tca_ohm= t_tca_self_c=
/// cutoff= shape_mm= shape_sigma_mm=` (each group appended after the older ones, so a parser of
/// an older line still finds its fields).
pub fn status(l: &mut OutLine, s: &StatusReport) {
    let _ = write!(
        l,
        "{OK} phase={} target_mm={}",
        s.phase.as_str(),
        Dashed(s.target_mm, 2)
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
        Dashed(s.pla_target_c, 2),
        Dashed(s.tca_target_c, 2),
        s.mode.map_or("-", Mode::as_str)
    );
    let [i_pla, i_tca] = s.current_a;
    let [r_pla, r_tca] = s.resistance_ohm;
    let _ = write!(
        l,
        " i_pla_a={} i_tca_a={} r_pla_ohm={} r_tca_ohm={} t_tca_self_c={} cutoff={}",
        Dashed(i_pla, 3),
        Dashed(i_tca, 3),
        Dashed(r_pla, 2),
        Dashed(r_tca, 2),
        Dashed(s.t_tca_self_c, 2),
        if s.supply_on { "closed" } else { "open" }
    );
    let _ = write!(
        l,
        " shape_mm={} shape_sigma_mm={}",
        Dashed(s.shape_mm[0], 2),
        Dashed(s.shape_mm[1], 2)
    );
}

/// A value with this many decimals, or `-` for NaN (no value).
struct Dashed(f32, u8);

impl fmt::Display for Dashed {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.0.is_nan() {
            f.write_str("-")
        } else {
            Fixed(self.0, self.1).fmt(f)
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
        format_args!("reachable={}..{}", Fixed::up2(min_mm), Fixed::down2(max_mm)),
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

/// `event: done t=<s> radius_mm=<mm>`, and ` missed_mm=<estimate − target>` when the estimate
/// missed its target ([`crate::sequencer::DONE_MISS_SHARE`]).
pub fn done_event(l: &mut OutLine, t_s: f32, radius_mm: f32, missed_mm: Option<f32>) {
    let _ = write!(
        l,
        "{EVENT_TAG} done t={} radius_mm={}",
        Fixed(t_s, 1),
        Fixed(radius_mm, 2)
    );
    if let Some(m) = missed_mm {
        let _ = write!(l, " missed_mm={}", Fixed(m, 2));
    }
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
            "{} has {} s of HEAT left: at most {} s per heater, given back at that per {} s \
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::format_error;
    use crate::protocol::reply::line;

    #[test]
    fn boot_line_with_a_panic_reason_stays_in_bounds() {
        let l = line(|l| {
            boot(l, ResetCause::Software, "nucleo-f401re", "0.1.0");
            boot_panic(l, "panicked at src/x.rs:1:2: \"quoted\" \\ é\n");
        });
        assert_eq!(
            l.as_str(),
            "event: boot reset=software board=nucleo-f401re version=0.1.0 \
             panic=\"panicked at src/x.rs:1:2: 'quoted' / ???\""
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
            current_a: [0.4, 1.846],
            resistance_ohm: [30.0, 6.5],
            t_tca_self_c: 57.25,
            supply_on: true,
            shape_mm: [38.12, 0.71],
        };
        let l = line(|l| status(l, &report(Phase::Bend, None, (75.0, 62.5))));
        assert_eq!(
            l.as_str(),
            "ok phase=bend target_mm=38.00 t_pla_c=74.17 t_tca_c=56.88 t_amb_c=21.94 \
             p_pla_w=1.250 p_tca_w=0.700 supply_v=12.00 fault=none \
             pla_target_c=75.00 tca_target_c=62.50 mode=closed \
             i_pla_a=0.400 i_tca_a=1.846 r_pla_ohm=30.00 r_tca_ohm=6.50 t_tca_self_c=57.25 cutoff=closed \
             shape_mm=38.12 shape_sigma_mm=0.71"
        );
        let idle = StatusReport {
            target_mm: f32::NAN,
            mode: None,
            current_a: [f32::NAN; 2],
            resistance_ohm: [f32::NAN; 2],
            t_tca_self_c: f32::NAN,
            supply_on: false,
            shape_mm: [f32::NAN; 2],
            ..report(Phase::Idle, None, (f32::NAN, f32::NAN))
        };
        let l = line(|l| status(l, &idle));
        assert!(
            l.ends_with(
                "fault=none pla_target_c=- tca_target_c=- mode=- i_pla_a=- i_tca_a=- \
                 r_pla_ohm=- r_tca_ohm=- t_tca_self_c=- cutoff=open shape_mm=- shape_sigma_mm=-"
            ),
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
                current_a: [-9.999, -9.999],
                resistance_ohm: [-999.99, -999.99],
                t_tca_self_c: -999.99,
                supply_on: false,
                shape_mm: [-999.99, -999.99],
                ..report(phase, fault, targets)
            };
            let l = line(|l| status(l, &wide));
            assert!(l.ends_with(" shape_sigma_mm=-999.99"), "truncated: {l}");
            assert!(l.len() < l.capacity(), "{} bytes: {l}", l.len());
        }
    }

    #[test]
    fn version_names_the_protocol_version() {
        let l = line(|l| version(l, "0.1.0"));
        assert_eq!(l, "ok version=0.1.0 protocol=1");
        assert_eq!(PROTOCOL_VERSION, 1);
    }
}

//! The client side: what kind of line a device sent. Used by morphctl, the QEMU harness, xtask
//! and the tests, so "is this the final reply?" is answered in one place.
//!
//! A command's reply is any number of `data:` lines and then exactly one final line, `ok[ ...]`
//! or `error: ...` (multi-line replies such as HELP and TABLE end with a plain `ok`; there is
//! no other terminator). `event:` and `alarm:` lines may arrive at any time, also between a
//! command and its final reply.

use super::{ALARM_TAG, DATA_TAG, ERROR_TAG, EVENT_TAG, OK};

/// The kind of a received line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LineKind {
    /// A final success reply: `ok` alone or `ok <fields>`.
    Ok,
    /// A final error reply: `error:...` (the firmware writes `error: <code> <text>`).
    Error,
    /// A data line before a final reply: `data:...`.
    Data,
    /// The boot line: `event: boot ...`.
    Boot,
    /// The end of a morph: `event: done ...`.
    Done,
    /// Any other event (`event: phase ...`).
    Event,
    /// A safety trip: `alarm:...`.
    Alarm,
    /// An empty line.
    Blank,
    /// Anything else: not the morphlink protocol.
    Other,
}

impl LineKind {
    /// True for the line that ends a command's reply (`ok...` or `error:...`).
    pub fn is_final(self) -> bool {
        matches!(self, LineKind::Ok | LineKind::Error)
    }

    /// True for unsolicited lines (events, the boot line and alarms).
    pub fn is_unsolicited(self) -> bool {
        matches!(
            self,
            LineKind::Boot | LineKind::Done | LineKind::Event | LineKind::Alarm
        )
    }
}

/// True if `rest` is empty or starts with a space: `word` was a whole word.
fn word_ends(rest: &str) -> bool {
    rest.is_empty() || rest.starts_with(' ')
}

/// The link an unsolicited line of a board with several links names (`@2 event: ...` is link
/// 1, 0-based) and the line without its address; `None` and the whole line for a line without
/// one (a board with one link, and every command's reply).
pub fn link_of(line: &str) -> (Option<usize>, &str) {
    let Some(rest) = line.strip_prefix('@') else {
        return (None, line);
    };
    let Some((word, rest)) = rest.split_once(' ') else {
        return (None, line);
    };
    match word.parse::<usize>() {
        Ok(n) if n >= 1 => (Some(n - 1), rest),
        _ => (None, line),
    }
}

/// Classifies one received line (without its line ending); a line addressed to a link
/// (`@2 event: done ...`) is classified by what follows its address.
pub fn classify(line: &str) -> LineKind {
    let line = link_of(line).1;
    if let Some(rest) = line.strip_prefix(OK) {
        if word_ends(rest) {
            return LineKind::Ok;
        }
        return LineKind::Other;
    }
    if line.starts_with(ERROR_TAG) {
        return LineKind::Error;
    }
    if line.starts_with(DATA_TAG) {
        return LineKind::Data;
    }
    if line.starts_with(ALARM_TAG) {
        return LineKind::Alarm;
    }
    if let Some(rest) = line.strip_prefix(EVENT_TAG) {
        let rest = rest.trim_start_matches(' ');
        let is = |name: &str| rest.strip_prefix(name).is_some_and(word_ends);
        return if is("boot") {
            LineKind::Boot
        } else if is("done") {
            LineKind::Done
        } else {
            LineKind::Event
        };
    }
    if line.is_empty() {
        LineKind::Blank
    } else {
        LineKind::Other
    }
}

/// `GAIT <r1> .. <rN>[ <mode>]`, the line a client sends for a gait (radii in mm, each in its
/// shortest form): morphctl's and the xtasks' one spelling of it.
pub fn gait_line(radii_mm: &[f32], mode: Option<&str>) -> super::OutLine {
    use core::fmt::Write;
    let mut l = super::OutLine::new();
    let _ = l.push_str("GAIT");
    for r in radii_mm {
        let _ = write!(l, " {r}");
    }
    if let Some(m) = mode {
        let _ = write!(l, " {m}");
    }
    l
}

/// True if `line` ends a command's reply (`ok`, `ok ...` or `error:...`).
pub fn is_final_reply(line: &str) -> bool {
    classify(line).is_final()
}

/// The text of a `data:` line after its tag, leading whitespace removed; None for other lines.
pub fn data_text(line: &str) -> Option<&str> {
    line.strip_prefix(DATA_TAG).map(str::trim_start)
}

/// The value of `key=` in a reply line (`ok phase=bend ...`), None if the line has no such field.
pub fn field<'a>(line: &'a str, key: &str) -> Option<&'a str> {
    line.split(' ')
        .find_map(|w| w.strip_prefix(key)?.strip_prefix('='))
}

/// A STATUS reply, parsed. Numbers are None when the field is missing, `-` or not a number;
/// the fields STATUS gained later (the target temperatures, the mode, then the current sense
/// and the cut-off) are None on a device that does not send them, and the current sense is
/// `-`, so None, on a board without it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Status<'a> {
    /// Phase word (`idle`, `soften`, `bend`, `lock`, `release`, `fault`).
    pub phase: &'a str,
    /// Target radius, mm.
    pub target_mm: Option<f32>,
    /// PLA, TCA and ambient thermistors, °C.
    pub temps_c: [Option<f32>; 3],
    /// PLA and TCA heater powers, W.
    pub powers_w: [Option<f32>; 2],
    /// Measured supply, V.
    pub supply_v: Option<f32>,
    /// Fault word (`none` or a fault code).
    pub fault: &'a str,
    /// The PLA and TCA heaters' target temperatures, °C (None: no target, or an older device).
    pub targets_c: [Option<f32>; 2],
    /// The strategy the running or last morph ran (None: none yet, or an older device).
    pub mode: Option<&'a str>,
    /// Each heater's current while driven (PLA, TCA), A (None: not sensed, or an older device).
    pub currents_a: [Option<f32>; 2],
    /// Each heater's measured resistance (PLA, TCA), Ω (None: not sensed, or an older device).
    pub resistances_ohm: [Option<f32>; 2],
    /// The TCA's mean temperature from its own resistance, °C: a second reading of the TCA
    /// beside its thermistor bead (None: not sensed, or an older device).
    pub t_tca_self_c: Option<f32>,
    /// The heater supply's cut-off switch: true closed (the heaters have a supply), false open
    /// (it opens on every alarm); None from an older device or a word neither `closed` nor `open`.
    pub cutoff_closed: Option<bool>,
}

impl<'a> Status<'a> {
    /// Parses a STATUS reply; None unless it is an `ok` line with a `phase=` field.
    pub fn parse(line: &'a str) -> Option<Status<'a>> {
        if classify(line) != LineKind::Ok {
            return None;
        }
        let num = |key: &str| field(line, key).and_then(|v| v.parse::<f32>().ok());
        Some(Status {
            phase: field(line, "phase")?,
            target_mm: num("target_mm"),
            temps_c: [num("t_pla_c"), num("t_tca_c"), num("t_amb_c")],
            powers_w: [num("p_pla_w"), num("p_tca_w")],
            supply_v: num("supply_v"),
            fault: field(line, "fault").unwrap_or("none"),
            targets_c: [num("pla_target_c"), num("tca_target_c")],
            mode: field(line, "mode").filter(|m| *m != "-"),
            currents_a: [num("i_pla_a"), num("i_tca_a")],
            resistances_ohm: [num("r_pla_ohm"), num("r_tca_ohm")],
            t_tca_self_c: num("t_tca_self_c"),
            cutoff_closed: match field(line, "cutoff") {
                Some("closed") => Some(true),
                Some("open") => Some(false),
                _ => None,
            },
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ok_lines() {
        assert_eq!(classify("ok"), LineKind::Ok);
        assert_eq!(classify("ok phase=idle target_mm=-"), LineKind::Ok);
        assert_eq!(classify("okay"), LineKind::Other);
        assert_eq!(classify("OK"), LineKind::Other);
        assert!(is_final_reply("ok"));
        assert!(is_final_reply("ok version=0.1.0 protocol=1"));
    }

    #[test]
    fn error_lines() {
        assert_eq!(classify("error: busy a morph is running"), LineKind::Error);
        assert_eq!(
            classify("error: line-too-long Lines are..."),
            LineKind::Error
        );
        assert!(is_final_reply("error: unknown-command x"));
        assert_eq!(classify("errors"), LineKind::Other);
    }

    #[test]
    fn data_lines() {
        assert_eq!(classify("data: 0.000 46.46"), LineKind::Data);
        assert!(!is_final_reply("data: 0.000 46.46"));
        assert_eq!(data_text("data: 0.000 46.46"), Some("0.000 46.46"));
        assert_eq!(data_text("data:x"), Some("x"));
        assert_eq!(data_text("ok"), None);
    }

    #[test]
    fn event_lines() {
        for l in [
            "event: phase soften t=0.0",
            "event: phase bend t=20.0 power_w=0.700",
        ] {
            assert_eq!(classify(l), LineKind::Event, "{l}");
            assert!(classify(l).is_unsolicited() && !is_final_reply(l));
        }
        assert_eq!(classify("event: doneness"), LineKind::Event);
    }

    #[test]
    fn done_lines() {
        let l = "event: done t=95.0 radius_mm=38.00";
        assert_eq!(classify(l), LineKind::Done);
        assert!(classify(l).is_unsolicited() && !is_final_reply(l));
    }

    #[test]
    fn boot_lines() {
        let l = "event: boot reset=pin board=nucleo-f401re version=0.1.0";
        assert_eq!(classify(l), LineKind::Boot);
        assert!(classify(l).is_unsolicited() && !is_final_reply(l));
    }

    #[test]
    fn alarm_lines() {
        let l = "alarm: stale-sensor no sensor frame for 1.0 s; heaters off, RESET when cleared";
        assert_eq!(classify(l), LineKind::Alarm);
        assert!(classify(l).is_unsolicited() && !is_final_reply(l));
    }

    #[test]
    fn blank_and_other_lines() {
        assert_eq!(classify(""), LineKind::Blank);
        assert_eq!(classify(" "), LineKind::Other);
        assert_eq!(classify("AT+OK"), LineKind::Other);
        for k in [LineKind::Blank, LineKind::Other] {
            assert!(!k.is_final() && !k.is_unsolicited());
        }
    }

    #[test]
    fn status_lines_parse_with_and_without_the_target_fields() {
        let new = "ok phase=bend target_mm=38.00 t_pla_c=74.17 t_tca_c=56.88 t_amb_c=21.94 \
                   p_pla_w=1.250 p_tca_w=0.700 supply_v=12.00 fault=none \
                   pla_target_c=75.00 tca_target_c=- mode=closed";
        let s = Status::parse(new).unwrap();
        assert_eq!(s.phase, "bend");
        assert_eq!(s.target_mm, Some(38.0));
        assert_eq!(s.temps_c, [Some(74.17), Some(56.88), Some(21.94)]);
        assert_eq!(s.powers_w, [Some(1.25), Some(0.7)]);
        assert_eq!(s.supply_v, Some(12.0));
        assert_eq!(s.fault, "none");
        assert_eq!(s.targets_c, [Some(75.0), None]);
        assert_eq!(s.mode, Some("closed"));
        // A device from before the targets: the same fields, the new ones None.
        let old = "ok phase=idle target_mm=- t_pla_c=22.00 t_tca_c=22.00 t_amb_c=22.00 \
                   p_pla_w=0.000 p_tca_w=0.000 supply_v=12.00 fault=none";
        let s = Status::parse(old).unwrap();
        assert_eq!(
            (s.phase, s.target_mm, s.targets_c, s.mode),
            ("idle", None, [None, None], None)
        );
        assert_eq!(
            (
                s.currents_a,
                s.resistances_ohm,
                s.t_tca_self_c,
                s.cutoff_closed
            ),
            ([None, None], [None, None], None, None)
        );
        assert_eq!(Status::parse("ok"), None);
        assert_eq!(Status::parse("error: busy phase=bend"), None);
        assert_eq!(field("ok t_pla_c=1 t_pla=2", "t_pla"), Some("2"));
    }

    #[test]
    fn status_lines_parse_the_current_sense_and_the_cutoff() {
        let line = "ok phase=bend target_mm=38.00 t_pla_c=74.17 t_tca_c=56.88 t_amb_c=21.94 \
                    p_pla_w=1.250 p_tca_w=0.700 supply_v=12.00 fault=none \
                    pla_target_c=75.00 tca_target_c=- mode=closed \
                    i_pla_a=0.417 i_tca_a=0.194 r_pla_ohm=28.80 r_tca_ohm=18.61 \
                    t_tca_self_c=58.12 cutoff=closed";
        let s = Status::parse(line).unwrap();
        assert_eq!(s.currents_a, [Some(0.417), Some(0.194)]);
        assert_eq!(s.resistances_ohm, [Some(28.8), Some(18.61)]);
        assert_eq!(s.t_tca_self_c, Some(58.12));
        assert_eq!(s.cutoff_closed, Some(true));
        // The older fields are read as before.
        assert_eq!(
            (s.phase, s.mode, s.targets_c),
            ("bend", Some("closed"), [Some(75.0), None])
        );
        // A board without current sense: `-` for what it does not have; the cut-off is given.
        let bare = "ok phase=fault target_mm=- t_pla_c=22.00 t_tca_c=22.00 t_amb_c=22.00 \
                    p_pla_w=0.000 p_tca_w=0.000 supply_v=12.00 fault=heater-open \
                    pla_target_c=- tca_target_c=- mode=closed \
                    i_pla_a=- i_tca_a=- r_pla_ohm=- r_tca_ohm=- t_tca_self_c=- cutoff=open";
        let s = Status::parse(bare).unwrap();
        assert_eq!(
            (
                s.currents_a,
                s.resistances_ohm,
                s.t_tca_self_c,
                s.cutoff_closed
            ),
            ([None, None], [None, None], None, Some(false))
        );
        assert_eq!((s.phase, s.fault), ("fault", "heater-open"));
        // A cut-off word this parser does not know is not taken for either state.
        let odd = bare.replace("cutoff=open", "cutoff=stuck");
        assert_eq!(Status::parse(&odd).unwrap().cutoff_closed, None);
    }

    #[test]
    fn the_firmware_s_own_status_line_parses_back_to_its_values() {
        use crate::protocol::reply::{status, StatusReport};
        use crate::protocol::{Mode, OutLine};
        use crate::vocab::Phase;
        let report = StatusReport {
            phase: Phase::Lock,
            target_mm: 38.0,
            t_pla_c: 61.5,
            t_tca_c: 57.0,
            t_amb_c: 22.0,
            p_pla_w: 0.0,
            p_tca_w: 0.7,
            supply_v: 12.0,
            fault: None,
            pla_target_c: f32::NAN,
            tca_target_c: 57.5,
            mode: Some(Mode::Closed),
            current_a: [f32::NAN, 0.194],
            resistance_ohm: [f32::NAN, 18.61],
            t_tca_self_c: 58.12,
            supply_on: true,
            shape_mm: [f32::NAN; 2],
        };
        let mut l = OutLine::new();
        status(&mut l, &report);
        let s = Status::parse(&l).unwrap();
        assert_eq!(s.currents_a, [None, Some(0.194)]);
        assert_eq!(s.resistances_ohm, [None, Some(18.61)]);
        assert_eq!(s.t_tca_self_c, Some(58.12));
        assert_eq!(s.cutoff_closed, Some(true));
        let mut l = OutLine::new();
        status(
            &mut l,
            &StatusReport {
                supply_on: false,
                ..report
            },
        );
        assert_eq!(Status::parse(&l).unwrap().cutoff_closed, Some(false));
    }
}

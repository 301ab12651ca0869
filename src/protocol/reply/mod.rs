//! Every reply, event and alarm line the firmware and the simulated builds send, by concern:
//! the shared line builders and protocol-wide errors here; [`status`](mod@status) (STATUS, the morph's
//! events, the command replies), [`alarm`](mod@alarm) (alarm lines and fault sentences), [`sim`] (the
//! simulated builds' `SIM` replies) and [`config`] (CONFIG, SAVE and the boot's config events).
//! `TUNE` and `MEASURED` are in [`super::tune_reply`].
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

pub mod alarm;
pub mod config;
pub mod sim;
pub mod status;

pub use alarm::*;
pub use config::*;
pub use sim::*;
pub use status::*;

/// HELP text, one `data:` line each ([`help_line`]: the tab is the column the descriptions
/// start at): these, then [`HELP_SIM`] in a simulated build, then [`HELP_TAIL`].
pub const HELP: [&str; 9] = [
    "MORPH <radius_mm> [auto|paper|gated|boost|closed]\tmorph to a radius (see RANGE)",
    "STATUS\tphase, temperatures, powers, supply, fault, targets, mode, currents, cut-off",
    "ABORT\tboth heaters off at once, phase idle",
    "RESET\tclear a latched fault once its cause is gone",
    "RANGE\treachable radii in mm",
    "TABLE\tTCA power / radius table",
    "VERSION\tfirmware and protocol version",
    "HELP\tthis list",
    "STATS\tcontrol-loop timing (us) and reset cause; hardware only",
];

/// HELP's `SIM` lines, in a simulated build only (a board's image answers every `SIM` line
/// `error: unsupported`, so its HELP does not offer them).
pub const HELP_SIM: [&str; 3] = [
    "SIM STATE|FAULT|SUPPLY|AMBIENT|MEDIUM|WAIT|CLEAR|PANIC|STALL\tsimulated builds only",
    "SIM WAIT <s>\trun <s> of simulated time, then ok; morph-sim only",
    "SIM FAULT thermistor-drift <pla|tca|amb> <K/s>\treading drifts from now; negative reads low",
];

/// HELP's last lines (after [`HELP_SIM`]).
pub const HELP_TAIL: [&str; 3] = [
    "CONFIG [SET <name> <value>|RESET]\tlist, change or reset the settings",
    "SAVE\twrite the settings to flash (idle only)",
    "HEAT <pla|tca> <power_w> <s>\tone heater at a low power for a while (bring-up)",
];

/// `STATS` on a build that does not time its control loop.
pub const ERR_STATS_UNSUPPORTED: ProtoError = ProtoError {
    code: ErrorCode::Unsupported,
    text: "STATS measures the control loop on hardware; this build has none",
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
/// any `"`, `\\` or non-printable byte shown as `'`/`/`/`?` (a character beyond ASCII as one
/// `?` per byte: bytes, not characters, so the image needs no UTF-8 decoder for it).
pub fn boot_panic(l: &mut OutLine, reason: &str) {
    let _ = l.push_str(" panic=\"");
    let room = BOOT_LINE_MAX.saturating_sub(l.len() + 1);
    for b in reason.bytes().take(room) {
        let c = match b {
            b'"' => '\'',
            b'\\' => '/',
            b' '..=b'~' => b as char,
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

/// Column of a HELP line's description, bytes after `data: `.
pub const HELP_COLUMN: usize = 32;

/// One HELP line, `data: <syntax><spaces><description>`, from `text`'s `<syntax>\t<description>`:
/// the spaces reach [`HELP_COLUMN`], two at least. Stored with a tab instead of its padding,
/// the table costs some 300 B less flash; the copy is still only a copy (a HELP reply is built
/// within a tick's margin, docs/emulation.md).
pub fn help_line(l: &mut OutLine, text: &str) {
    let _ = l.push_str(DATA_TAG).and_then(|()| l.push(' '));
    let start = l.len();
    // Byte by byte (HELP is ASCII): no slicing, whose char-boundary panic would bring the
    // formatting machinery into the image.
    for &b in text.as_bytes() {
        if b != b'\t' {
            let _ = l.push(char::from(b));
            continue;
        }
        let end = l.len().max(start + HELP_COLUMN - 2) + 2;
        while l.len() < end && l.push(' ').is_ok() {}
    }
}

/// The bare success reply, `ok`.
pub fn ok(l: &mut OutLine) {
    let _ = l.push_str(OK);
}

/// `ok <fields>`.
fn ok_with(l: &mut OutLine, fields: fmt::Arguments<'_>) {
    let _ = write!(l, "{OK} {fields}");
}

/// The line `f` writes: the reply tests' one way to build a line.
#[cfg(test)]
pub(crate) fn line(f: impl FnOnce(&mut OutLine)) -> OutLine {
    let mut l = OutLine::new();
    f(&mut l);
    l
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::protocol::format_error;

    #[test]
    fn data_text_is_the_data_line_of_its_text() {
        for h in HELP.iter().chain(&HELP_SIM).chain(&HELP_TAIL) {
            assert_eq!(line(|l| data_text(l, h)), line(|l| data(l, h)), "{h}");
        }
        assert_eq!(line(|l| data_text(l, "")).as_str(), "data: ");
    }

    #[test]
    fn help_lines_align_their_descriptions_at_the_column_or_two_spaces_past_a_long_syntax() {
        let short = line(|l| help_line(l, "STATUS\tphase"));
        assert_eq!(
            short.as_str().find("phase"),
            Some("data: ".len() + HELP_COLUMN)
        );
        assert!(short.as_str().starts_with("data: STATUS "));
        let long = line(|l| help_line(l, "CONFIG [SET <name> <value>|RESET]\tlist"));
        assert_eq!(
            long.as_str(),
            "data: CONFIG [SET <name> <value>|RESET]  list"
        );
        for h in HELP.iter().chain(&HELP_SIM).chain(&HELP_TAIL) {
            assert_eq!(h.matches('\t').count(), 1, "{h}");
        }
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
}

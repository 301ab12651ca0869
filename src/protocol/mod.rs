//! Protocol v1: the one home of the wire text. Bounded line assembly and the vocabulary here,
//! command parsing in [`command`], every reply, event and alarm line in [`reply`], the serial
//! path's input and output queues and ABORT-first scan in [`serial`], and the client side's
//! line classifier in [`client`]. No other module writes wire text (checked by
//! `tests/wire_text.rs`).
//!
//! ASCII lines ending in `\n`, `\r` or `\r\n`, at most [`MAX_LINE`] characters,
//! commands case-insensitive. Every command line gets exactly one final reply (`ok ...` or
//! `error: <code> <text>`), optionally preceded by `data: ...` lines. Unsolicited lines are
//! `event: ...` and `alarm: <code> <text>`.

pub mod client;
pub mod command;
pub mod links;
pub mod reply;
pub mod serial;
pub mod tune_reply;

pub use client::{classify, is_final_reply, LineKind};
pub use command::parse_line;

/// Protocol version, as `VERSION` reports it (`ok version=<v> protocol=<PROTOCOL_VERSION>`).
pub const PROTOCOL_VERSION: u32 = 1;

/// A reply line that is exactly this, or starts with it and a space, is a success.
pub const OK: &str = "ok";
/// Tag of the error reply, `error: <code> <text>`.
pub const ERROR_TAG: &str = "error:";
/// Tag of a data line before a final reply, `data: ...`.
pub const DATA_TAG: &str = "data:";
/// Tag of an unsolicited event line, `event: <name> ...`.
pub const EVENT_TAG: &str = "event:";
/// Tag of an unsolicited alarm line, `alarm: <code> <text>`.
pub const ALARM_TAG: &str = "alarm:";

/// Longest accepted line in characters, excluding the line ending.
pub const MAX_LINE: usize = 64;

/// Morph strategy requested with `MORPH <radius_mm> [mode]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// The default: whichever strategy the strategy chart picked
    /// ([`crate::strategy::AUTO_STRATEGY`]).
    Auto,
    /// The paper's fixed timing: PLA 4 W 0–20 s, 1.5 W 20–70 s; TCA 20–120 s.
    Paper,
    /// Thermistor-gated phases with the table's power: soften until the PLA reads soft, bend
    /// until the TCA thermistor settles, lock until the PLA reads rigid.
    Gated,
    /// Model-based feed-forward: the controller's thermal model is driven open loop to the
    /// target temperatures with overdrive, then holds them at the steady power.
    Boost,
    /// Closed-loop temperature control of both heaters from the thermistors, with the model as
    /// observer and the release spring-back compensated.
    Closed,
}

pub use crate::vocab::{Heater, Sensor};

/// Surrounding medium of the simulated link.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Medium {
    /// Still water, h = 101.3 W/(m² K).
    Water,
    /// Still air, h = 20 W/(m² K).
    Air,
}

/// Faults the simulated link can be told to show (`SIM FAULT <kind> [pla|tca|amb]`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SimFault {
    /// Thermistor wire broken: the divider reads full scale.
    ThermistorOpen,
    /// Thermistor shorted: the divider reads zero.
    ThermistorShort,
    /// Thermistor stuck: its reading freezes at the value it had when the fault was injected
    /// (a hung ADC channel, a bead glued to something else).
    ThermistorStuck,
    /// Heater wire broken: commanded power produces no heat.
    HeaterOpen,
    /// MOSFET shorted: the heater runs at full supply power whatever is commanded.
    HeaterStuck,
    /// Thermistor drifting: its reading moves away from the truth at a steady rate from the
    /// moment of injection (a cracked bead, a failing pull-up); `SIM FAULT thermistor-drift
    /// <pla|tca|amb> <K/s>`, negative reads low ([`SimCommand::Drift`]).
    ThermistorDrift,
    /// The supply's cut-off never opens (welded relay contacts, a failed P-MOSFET); `SIM
    /// FAULT cutoff-stuck`, no target. Combines with the others: with `heater-stuck` nothing
    /// the firmware does stops the heater.
    CutoffStuck,
}

/// Simulator-only commands (`SIM ...`), answered by `morph-sim` and emulated builds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SimCommand {
    /// `SIM STATE`: report the simulated truth.
    State,
    /// `SIM FAULT <kind> [pla|tca|amb]`; the target defaults to `pla`.
    Fault(SimFault, Sensor),
    /// `SIM SUPPLY <volts>`.
    Supply(f32),
    /// `SIM AMBIENT <°C>`.
    Ambient(f32),
    /// `SIM MEDIUM <water|air>`.
    Medium(Medium),
    /// `SIM CLEAR`: remove every injected fault.
    Clear,
    /// `SIM WAIT <s>`: the rig runs the controller and the plant for that much simulated time
    /// at the normal control rate (events as usual), then answers `ok`; bounded by
    /// `morphlink::bench::SIM_WAIT_MAX_S`. Only a rig that owns the clock (`morph-sim`) can;
    /// the emulated image answers `error: unsupported` (firmware time cannot be skipped).
    Wait(f32),
    /// `SIM PANIC`: the emulated image panics on purpose, to prove the panic path (heaters
    /// off, failing exit); the host simulator refuses it.
    Panic,
    /// `SIM STALL`: the emulated image stops running its tasks on purpose (a busy loop in
    /// thread mode), to prove the watchdog: it fires within its timeout, heaters off, and the
    /// next boot says `reset=watchdog`; the host simulator refuses it.
    Stall,
    /// `SIM FAULT thermistor-drift <pla|tca|amb> <K/s>`: the sensor's reading drifts from the
    /// truth by this rate, K/s, from the moment of injection (negative: reads low); the rate
    /// is bounded by `morphlink::bench::SIM_DRIFT_MAX_K_PER_S`.
    Drift(Sensor, f32),
}

/// A parsed command line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Command {
    /// `MORPH <radius_mm> [auto|paper|gated|boost|closed]`.
    Morph {
        /// Target bending radius in millimetres.
        radius_mm: f32,
        /// Strategy.
        mode: Mode,
    },
    /// `STATUS`.
    Status,
    /// `ABORT`: both heaters off at once, phase idle.
    Abort,
    /// `RESET`: clear a latched fault if its condition has cleared.
    Reset,
    /// `RANGE`: reachable radii.
    Range,
    /// `TABLE`: the power/radius table.
    Table,
    /// `VERSION`.
    Version,
    /// `HELP`.
    Help,
    /// `STATS`: control-loop timing and reset cause (firmware builds).
    Stats,
    /// `SIM ...` (simulated builds only).
    Sim(SimCommand),
    /// `CONFIG`, `CONFIG SET <name> <value>`, `CONFIG RESET`: the named settings.
    Config(ConfigCommand),
    /// `SAVE`: write the settings to flash.
    Save,
    /// `HEAT <pla|tca> <power_w> <s>`: one heater at a low fixed power for a few seconds,
    /// supervised (bring-up; bounds in [`crate::pulse`]).
    Heat {
        /// The heater.
        heater: Heater,
        /// Power, W.
        power_w: f32,
        /// Duration, s.
        duration_s: f32,
    },
    /// `TUNE`: the thermal autotune (see [`crate::tune`]).
    Tune,
    /// `MEASURED <radius_mm>`: the radius the user measured after the last finished morph.
    Measured {
        /// Measured radius, mm.
        radius_mm: f32,
    },
}

/// What `CONFIG` does.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ConfigCommand {
    /// `CONFIG`: list every setting with its unit, value and range.
    List,
    /// `CONFIG SET <name> <value>`: the name and value as sent (checked by the settings).
    Set {
        /// Setting name.
        name: Word,
        /// Value text: a number, or a choice's word.
        value: Word,
    },
    /// `CONFIG RESET`: every setting back to its default (not saved).
    Reset,
}

/// Longest [`Word`], bytes.
pub const WORD_MAX: usize = 32;

/// One word of a command line, copied so a [`Command`] stays `Copy` and owns no borrow.
#[derive(Clone, Copy, PartialEq, Eq)]
pub struct Word {
    bytes: [u8; WORD_MAX],
    len: u8,
}

impl Word {
    /// `w` as a word; `None` if longer than [`WORD_MAX`].
    pub fn new(w: &str) -> Option<Word> {
        if w.len() > WORD_MAX {
            return None;
        }
        let mut bytes = [0; WORD_MAX];
        bytes[..w.len()].copy_from_slice(w.as_bytes());
        Some(Word {
            bytes,
            len: w.len() as u8,
        })
    }

    /// The word's text.
    pub fn as_str(&self) -> &str {
        // Built from a line's `&str`, which is printable ASCII ([`crate::fixed::ascii_str`]).
        crate::fixed::ascii_str(&self.bytes[..self.len as usize]).unwrap_or("")
    }
}

impl core::fmt::Debug for Word {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        write!(f, "{:?}", self.as_str())
    }
}

/// Error codes of `error: <code> <text>` replies (kebab-case on the wire).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ErrorCode {
    /// The first word is not a command.
    UnknownCommand,
    /// An argument is missing, extra or malformed.
    BadArgument,
    /// A command that takes no arguments got some: the error's text is the command, and the
    /// wire reads `bad-argument <command> takes no arguments.` (one sentence for every such
    /// command, not one each in flash).
    NoArguments,
    /// A radius outside the reachable range, or a SIM value outside its limits.
    OutOfRange,
    /// A morph is running; ABORT first.
    Busy,
    /// A fault is latched; RESET first.
    FaultLatched,
    /// RESET refused: the fault's condition is still present.
    FaultActive,
    /// The line exceeded [`MAX_LINE`] characters.
    LineTooLong,
    /// The command exists but this build cannot do it (e.g. `SIM` on hardware).
    Unsupported,
    /// Input was lost while the line arrived (receive buffer full, UART overrun); the line
    /// was not run.
    Overrun,
    /// The settings storage failed (SAVE did not complete).
    Storage,
    /// MEASURED with no finished morph to attach the radius to.
    NoFinishedMorph,
    /// MEASURED again for a morph whose radius is already counted.
    AlreadyMeasured,
    /// A command that would start heating (MORPH, TUNE, HEAT) arrived ahead of an ABORT in
    /// the same read: the ABORT came first, so it was not run.
    Aborted,
}

/// A protocol error: a code and a sentence for the user.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ProtoError {
    /// Machine-readable code.
    pub code: ErrorCode,
    /// Human-readable explanation (no line breaks).
    pub text: &'static str,
}

impl ErrorCode {
    /// The kebab-case wire word of this code, as in `error: <code> <text>`.
    pub fn as_str(self) -> &'static str {
        match self {
            ErrorCode::UnknownCommand => "unknown-command",
            ErrorCode::BadArgument | ErrorCode::NoArguments => "bad-argument",
            ErrorCode::OutOfRange => "out-of-range",
            ErrorCode::Busy => "busy",
            ErrorCode::FaultLatched => "fault-latched",
            ErrorCode::FaultActive => "fault-active",
            ErrorCode::LineTooLong => "line-too-long",
            ErrorCode::Unsupported => "unsupported",
            ErrorCode::Overrun => "overrun",
            ErrorCode::Storage => "storage",
            ErrorCode::NoFinishedMorph => "no-finished-morph",
            ErrorCode::AlreadyMeasured => "already-measured",
            ErrorCode::Aborted => "aborted",
        }
    }
}

impl Mode {
    /// The lowercase wire word (`auto`, `paper`, `gated`, `boost`, `closed`).
    pub fn as_str(self) -> &'static str {
        match self {
            Mode::Auto => "auto",
            Mode::Paper => "paper",
            Mode::Gated => "gated",
            Mode::Boost => "boost",
            Mode::Closed => "closed",
        }
    }
}

impl Medium {
    /// The lowercase wire word (`water`, `air`).
    pub fn as_str(self) -> &'static str {
        match self {
            Medium::Water => "water",
            Medium::Air => "air",
        }
    }
}

impl SimFault {
    /// The lowercase wire word (`thermistor-open`, `thermistor-short`, `thermistor-stuck`,
    /// `heater-open`, `heater-stuck`, `thermistor-drift`).
    pub fn as_str(self) -> &'static str {
        match self {
            SimFault::ThermistorOpen => "thermistor-open",
            SimFault::ThermistorShort => "thermistor-short",
            SimFault::ThermistorStuck => "thermistor-stuck",
            SimFault::HeaterOpen => "heater-open",
            SimFault::HeaterStuck => "heater-stuck",
            SimFault::ThermistorDrift => "thermistor-drift",
            SimFault::CutoffStuck => "cutoff-stuck",
        }
    }
}

/// Every [`Mode`], for matching wire words.
pub const MODES: [Mode; 5] = [
    Mode::Auto,
    Mode::Paper,
    Mode::Gated,
    Mode::Boost,
    Mode::Closed,
];

/// What [`LineAssembler::push`] reports when a line ends.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Assembled<'a> {
    /// A complete line without its ending (may be empty; callers ignore blank lines).
    Line(&'a str),
    /// The line exceeded [`MAX_LINE`] bytes; its content was dropped.
    TooLong,
    /// The line is not valid UTF-8; its content was dropped.
    Invalid,
}

/// What [`LineAssembler::push_checked`] reports for a line that lost bytes: the receiver
/// dropped input ([`LineAssembler::overrun`]) while it was in progress, so its content (which
/// may be pieces of two lines) was dropped. Answered with
/// [`reply::ERR_OVERRUN`], never run.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Overrun;

/// Collects bytes into lines in a fixed [`MAX_LINE`]-byte buffer, without allocation.
///
/// `\n`, `\r` and `\r\n` each end a line (the `\n` of a `\r\n` ends nothing more, so CRLF
/// makes no empty line). Bytes past [`MAX_LINE`] are discarded and the line reports
/// [`Assembled::TooLong`] once, at its end, so a flood of garbage costs one error reply, not
/// one per byte. A receiver that drops bytes calls [`LineAssembler::overrun`]: the line in
/// progress then ends as [`Overrun`] (from [`LineAssembler::push_checked`]) instead of being
/// joined with whatever follows the gap.
#[derive(Clone, Debug)]
pub struct LineAssembler {
    buf: [u8; MAX_LINE],
    len: usize,
    overflow: bool,
    overrun: bool,
    after_cr: bool,
}

impl Default for LineAssembler {
    fn default() -> Self {
        Self::new()
    }
}

impl LineAssembler {
    /// An empty assembler.
    pub const fn new() -> Self {
        Self {
            buf: [0; MAX_LINE],
            len: 0,
            overflow: false,
            overrun: false,
            after_cr: false,
        }
    }

    /// True between lines: nothing of a line received yet, and no overrun marked.
    pub fn at_line_start(&self) -> bool {
        self.len == 0 && !self.overflow && !self.overrun
    }

    /// Marks input lost at this point (a full receive buffer, a UART overrun): the line in
    /// progress, whatever its bytes so far, ends as [`Overrun`].
    pub fn overrun(&mut self) {
        self.overrun = true;
        // The lost bytes may have held the `\n` of a `\r\n`, or a whole line: the next `\n`
        // is not known to belong to the last `\r`.
        self.after_cr = false;
    }

    /// Feeds one received byte; returns the finished line when `byte` ends one. For sources
    /// that never call [`LineAssembler::overrun`]; a line marked so is reported as
    /// [`Assembled::Invalid`] (its content dropped).
    pub fn push(&mut self, byte: u8) -> Option<Assembled<'_>> {
        self.push_checked(byte)
            .map(|r| r.unwrap_or(Assembled::Invalid))
    }

    /// Feeds one received byte; returns the finished line when `byte` ends one, or
    /// [`Overrun`] if input was lost while it was in progress.
    pub fn push_checked(&mut self, byte: u8) -> Option<Result<Assembled<'_>, Overrun>> {
        match byte {
            b'\r' | b'\n' => {
                let crlf = byte == b'\n' && self.after_cr;
                self.after_cr = byte == b'\r';
                if crlf {
                    return None;
                }
                let len = self.len;
                let overflow = self.overflow;
                let overrun = self.overrun;
                self.len = 0;
                self.overflow = false;
                self.overrun = false;
                if overrun {
                    return Some(Err(Overrun));
                }
                if overflow {
                    return Some(Ok(Assembled::TooLong));
                }
                Some(Ok(match crate::fixed::ascii_str(&self.buf[..len]) {
                    Some(line) => Assembled::Line(line),
                    None => Assembled::Invalid,
                }))
            }
            _ => {
                self.after_cr = false;
                if self.len < MAX_LINE {
                    self.buf[self.len] = byte;
                    self.len += 1;
                } else {
                    self.overflow = true;
                }
                None
            }
        }
    }
}

/// Reply to an [`Assembled::TooLong`] line; the text names [`MAX_LINE`].
pub const ERR_LINE_TOO_LONG: ProtoError = ProtoError {
    code: ErrorCode::LineTooLong,
    text: "Lines are limited to 64 characters.",
};

/// Reply to an [`Assembled::Invalid`] line.
pub const ERR_INVALID_LINE: ProtoError = ProtoError {
    code: ErrorCode::BadArgument,
    text: "The line is not valid text; commands are plain ASCII.",
};

/// Capacity of an [`OutLine`], bytes: the longest line, STATUS with its current-sense and
/// rest-shape fields, fits (its test writes the widest values).
pub const OUT_LINE_BYTES: usize = 336;

/// One reply or event line, without its line ending, at most [`OUT_LINE_BYTES`].
pub type OutLine = heapless::String<OUT_LINE_BYTES>;

/// Formats `error: <code> <text>` (a part past [`OutLine`]'s capacity is left out; no built-in
/// text comes near it: a test holds every one under it).
pub fn format_error(err: &ProtoError) -> OutLine {
    let mut out = OutLine::new();
    let tail = if err.code == ErrorCode::NoArguments {
        " takes no arguments."
    } else {
        ""
    };
    for part in [ERROR_TAG, " ", err.code.as_str(), " ", err.text, tail] {
        let _ = out.push_str(part);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fixed::Fixed;
    use proptest::prelude::*;
    use std::{format, string::String, vec::Vec};

    fn code(line: &str) -> Option<ErrorCode> {
        parse_line(line).err().map(|e| e.code)
    }

    fn sim(line: &str) -> SimCommand {
        match parse_line(line) {
            Ok(Some(Command::Sim(s))) => s,
            other => panic!("{line:?} gave {other:?}"),
        }
    }

    #[test]
    fn wire_words() {
        assert_eq!(ErrorCode::UnknownCommand.as_str(), "unknown-command");
        assert_eq!(ErrorCode::BadArgument.as_str(), "bad-argument");
        assert_eq!(ErrorCode::OutOfRange.as_str(), "out-of-range");
        assert_eq!(ErrorCode::Busy.as_str(), "busy");
        assert_eq!(ErrorCode::FaultLatched.as_str(), "fault-latched");
        assert_eq!(ErrorCode::FaultActive.as_str(), "fault-active");
        assert_eq!(ErrorCode::LineTooLong.as_str(), "line-too-long");
        assert_eq!(ErrorCode::Unsupported.as_str(), "unsupported");
        assert_eq!(ErrorCode::Overrun.as_str(), "overrun");
        assert_eq!(Mode::Paper.as_str(), "paper");
        assert_eq!(Sensor::Amb.as_str(), "amb");
        assert_eq!(Heater::Tca.as_str(), "tca");
        assert_eq!(Heater::Pla.as_str(), "pla");
        assert_eq!(Medium::Water.as_str(), "water");
        assert_eq!(SimFault::ThermistorShort.as_str(), "thermistor-short");
        assert_eq!(SimFault::HeaterStuck.as_str(), "heater-stuck");
        assert_eq!(SimFault::ThermistorStuck.as_str(), "thermistor-stuck");
    }

    #[test]
    fn blank_lines_are_nothing() {
        for line in ["", " ", "\t \t", "\r", " \x0c "] {
            assert_eq!(parse_line(line), Ok(None), "{line:?}");
        }
    }

    #[test]
    fn simple_commands_any_case_and_spacing() {
        assert_eq!(parse_line("STATUS"), Ok(Some(Command::Status)));
        assert_eq!(parse_line("  status \r"), Ok(Some(Command::Status)));
        assert_eq!(parse_line("Abort"), Ok(Some(Command::Abort)));
        assert_eq!(parse_line("reset"), Ok(Some(Command::Reset)));
        assert_eq!(parse_line("RANGE"), Ok(Some(Command::Range)));
        assert_eq!(parse_line("table"), Ok(Some(Command::Table)));
        assert_eq!(parse_line("VeRsIoN"), Ok(Some(Command::Version)));
        assert_eq!(parse_line("\thelp"), Ok(Some(Command::Help)));
        assert_eq!(code("STATUS now"), Some(ErrorCode::NoArguments));
        assert_eq!(code("HELP me"), Some(ErrorCode::NoArguments));
        assert_eq!(
            format_error(&parse_line("TUNE now").unwrap_err()).as_str(),
            "error: bad-argument TUNE takes no arguments."
        );
        assert_eq!(
            format_error(&parse_line("config reset all").unwrap_err()).as_str(),
            "error: bad-argument CONFIG RESET takes no arguments."
        );
    }

    #[test]
    fn morph() {
        let morph = |radius_mm, mode| Ok(Some(Command::Morph { radius_mm, mode }));
        assert_eq!(parse_line("MORPH 38"), morph(38.0, Mode::Auto));
        assert_eq!(
            parse_line("morph \t 38.5   paper"),
            morph(38.5, Mode::Paper)
        );
        assert_eq!(parse_line("MORPH 12 AUTO"), morph(12.0, Mode::Auto));
        // Range checking against the table happens elsewhere.
        assert_eq!(parse_line("MORPH 100000"), morph(100_000.0, Mode::Auto));
        let err = parse_line("MORPH").unwrap_err();
        assert_eq!(err.code, ErrorCode::BadArgument);
        assert!(err.text.contains("radius in mm"));
        for bad in [
            "MORPH 0",
            "MORPH -3",
            "MORPH -0",
            "MORPH abc",
            "MORPH 1e2",
            "MORPH inf",
            "MORPH nan",
            "MORPH 38 fast",
            "MORPH 38 auto extra",
            "MORPH 3８",
        ] {
            assert_eq!(code(bad), Some(ErrorCode::BadArgument), "{bad}");
        }
    }

    #[test]
    fn sim_commands() {
        assert_eq!(sim("SIM STATE"), SimCommand::State);
        assert_eq!(sim("sim clear"), SimCommand::Clear);
        assert_eq!(sim("SIM STALL"), SimCommand::Stall);
        assert_eq!(
            sim("SIM FAULT thermistor-open"),
            SimCommand::Fault(SimFault::ThermistorOpen, Sensor::Pla)
        );
        assert_eq!(
            sim("SIM FAULT Thermistor-Short amb"),
            SimCommand::Fault(SimFault::ThermistorShort, Sensor::Amb)
        );
        assert_eq!(
            sim("SIM FAULT heater-stuck TCA"),
            SimCommand::Fault(SimFault::HeaterStuck, Sensor::Tca)
        );
        assert_eq!(
            sim("SIM FAULT thermistor-drift tca -0.2"),
            SimCommand::Drift(Sensor::Tca, -0.2)
        );
        assert_eq!(
            sim("sim fault THERMISTOR-DRIFT amb 1"),
            SimCommand::Drift(Sensor::Amb, 1.0)
        );
        for bad in [
            "SIM FAULT thermistor-drift",
            "SIM FAULT thermistor-drift tca",
            "SIM FAULT thermistor-drift tca fast",
            "SIM FAULT thermistor-drift tca 0.2 more",
            "SIM FAULT thermistor-drift heater 0.2",
        ] {
            assert_eq!(code(bad), Some(ErrorCode::BadArgument), "{bad}");
        }
        assert_eq!(sim("SIM SUPPLY 4.5"), SimCommand::Supply(4.5));
        assert_eq!(sim("SIM AMBIENT -5"), SimCommand::Ambient(-5.0));
        assert_eq!(sim("SIM MEDIUM air"), SimCommand::Medium(Medium::Air));
        assert_eq!(sim("SIM MEDIUM WATER"), SimCommand::Medium(Medium::Water));
        assert_eq!(sim("SIM WAIT 60"), SimCommand::Wait(60.0));
        assert_eq!(sim("sim wait 0.5"), SimCommand::Wait(0.5));
        // The range (negative, too long) is the rig's to refuse, with out-of-range.
        assert_eq!(sim("SIM WAIT -1"), SimCommand::Wait(-1.0));
        for bad in [
            "SIM",
            "SIM NOTHING",
            "SIM STATE now",
            "SIM CLEAR all",
            "SIM STALL now",
            "SIM FAULT",
            "SIM FAULT melted",
            "SIM FAULT heater-open amb",
            "SIM FAULT heater-open pla extra",
            "SIM FAULT thermistor-open xyz",
            "SIM SUPPLY",
            "SIM SUPPLY five",
            "SIM SUPPLY 5 V",
            "SIM AMBIENT",
            "SIM AMBIENT 1e3",
            "SIM MEDIUM",
            "SIM MEDIUM oil",
            "SIM MEDIUM air water",
            "SIM WAIT",
            "SIM WAIT soon",
            "SIM WAIT nan",
            "SIM WAIT 1 s",
        ] {
            // On the wire: `bad-argument` (a command of no arguments given some included).
            assert_eq!(
                code(bad).map(ErrorCode::as_str),
                Some("bad-argument"),
                "{bad}"
            );
        }
    }

    #[test]
    fn unknown_and_non_ascii() {
        assert_eq!(code("FLY"), Some(ErrorCode::UnknownCommand));
        assert_eq!(code("MORPHX 38"), Some(ErrorCode::UnknownCommand));
        assert_eq!(code("ＳＴＡＴＵＳ"), Some(ErrorCode::UnknownCommand));
        assert_eq!(code("STATUS ü"), Some(ErrorCode::NoArguments));
        assert_eq!(code("\u{FFFD}"), Some(ErrorCode::UnknownCommand));
    }

    #[test]
    fn error_texts_are_sentences_that_fit() {
        let lines = [
            "FLY",
            "STATUS x",
            "ABORT x",
            "RESET x",
            "RANGE x",
            "TABLE x",
            "VERSION x",
            "HELP x",
            "MORPH",
            "MORPH x",
            "MORPH 0",
            "MORPH 1 x",
            "MORPH 1 auto x",
            "SIM",
            "SIM x",
            "SIM STATE x",
            "SIM CLEAR x",
            "SIM FAULT",
            "SIM FAULT heater-open x",
            "SIM FAULT heater-open amb",
            "SIM FAULT heater-open pla x",
            "SIM SUPPLY",
            "SIM SUPPLY 1 x",
            "SIM AMBIENT",
            "SIM AMBIENT 1 x",
            "SIM MEDIUM",
            "SIM MEDIUM air x",
            "SIM WAIT",
            "SIM WAIT 1 x",
        ];
        let errors = lines.iter().map(|l| parse_line(l).unwrap_err()).chain([
            ERR_LINE_TOO_LONG,
            ERR_INVALID_LINE,
            reply::ERR_OVERRUN,
        ]);
        for err in errors {
            // The sentence as the wire carries it (a command of no arguments: its word, then
            // ` takes no arguments.`).
            let out = format_error(&err);
            let head = format!("error: {} ", err.code.as_str());
            let text = out.as_str().strip_prefix(head.as_str()).unwrap();
            assert!(text.starts_with(err.text), "{text}");
            assert!(
                text.ends_with('.') && text.is_ascii() && !text.contains('\n'),
                "{text}"
            );
            assert!(text.as_bytes()[0].is_ascii_uppercase(), "{text}");
            assert!(out.len() < out.capacity());
        }
        assert!(ERR_LINE_TOO_LONG.text.contains(&format!("{MAX_LINE}")));
    }

    #[test]
    fn format_error_layout() {
        let out = format_error(&parse_line("MORPH").unwrap_err());
        assert_eq!(
            out.as_str(),
            "error: bad-argument MORPH needs a radius in mm, e.g. MORPH 38."
        );
    }

    /// Feeds `bytes`, collecting owned copies of each result.
    fn assemble(bytes: &[u8]) -> Vec<Result<String, Assembled<'static>>> {
        let mut asm = LineAssembler::new();
        let mut out = Vec::new();
        for &b in bytes {
            match asm.push(b) {
                None => {}
                Some(Assembled::Line(l)) => out.push(Ok(String::from(l))),
                Some(Assembled::TooLong) => out.push(Err(Assembled::TooLong)),
                Some(Assembled::Invalid) => out.push(Err(Assembled::Invalid)),
            }
        }
        out
    }

    #[test]
    fn assembler_lines() {
        let got = assemble(b"STATUS\r\n\nabc\rdef\nno end");
        assert_eq!(
            got,
            [
                Ok("STATUS".into()),
                Ok("".into()),
                Ok("abc".into()),
                Ok("def".into())
            ]
        );
    }

    #[test]
    fn assembler_cr_lf_and_crlf_each_end_one_line() {
        for ending in [&b"\n"[..], b"\r", b"\r\n"] {
            let mut stream = Vec::new();
            for cmd in [&b"ABORT"[..], b"STATUS", b"STATS"] {
                stream.extend_from_slice(cmd);
                stream.extend_from_slice(ending);
            }
            let got = assemble(&stream);
            assert_eq!(
                got,
                [Ok("ABORT".into()), Ok("STATUS".into()), Ok("STATS".into())],
                "{ending:?}"
            );
        }
        // CRLF makes no empty line, but an empty line in any ending is one.
        assert_eq!(assemble(b"\r\n\r\n").len(), 2);
        assert_eq!(assemble(b"\r\r"), [Ok("".into()), Ok("".into())]);
        assert_eq!(assemble(b"\n\r"), [Ok("".into()), Ok("".into())]);
        // LF CR: the CR ends a second (empty) line; CR LF LF: the second LF does too.
        assert_eq!(
            assemble(b"A\r\n\nB\n"),
            [Ok("A".into()), Ok("".into()), Ok("B".into())]
        );
    }

    /// Feeds `bytes` with [`LineAssembler::overrun`] called before the byte at each index in
    /// `lost_before`; `Err(None)` marks an overrun line.
    fn assemble_checked(
        bytes: &[u8],
        lost_before: &[usize],
    ) -> Vec<Result<String, Option<Assembled<'static>>>> {
        let mut asm = LineAssembler::new();
        let mut out = Vec::new();
        for (i, &b) in bytes.iter().enumerate() {
            if lost_before.contains(&i) {
                asm.overrun();
            }
            match asm.push_checked(b) {
                None => {}
                Some(Err(Overrun)) => out.push(Err(None)),
                Some(Ok(Assembled::Line(l))) => out.push(Ok(String::from(l))),
                Some(Ok(other)) => out.push(Err(Some(match other {
                    Assembled::TooLong => Assembled::TooLong,
                    _ => Assembled::Invalid,
                }))),
            }
        }
        out
    }

    #[test]
    fn assembler_overrun_marks_the_line_in_progress() {
        // Bytes lost in the middle of STATUS and the start of STATS ("STAT" + "S\n" ... gone):
        // the joined remains are one overrun line, never a command; the next line is clean.
        let got = assemble_checked(b"STATS\nABORT\n", &[3]);
        assert_eq!(got, [Err(None), Ok("ABORT".into())]);
        // Marked at a line start: the next line may be the tail of a lost one, so it is an error.
        let got = assemble_checked(b"US\nSTATUS\n", &[0]);
        assert_eq!(got, [Err(None), Ok("STATUS".into())]);
        // Overrun wins over too-long, and a lost CRLF's LF is not assumed.
        let mut long = vec![b'x'; 100];
        long.extend_from_slice(b"\rOK\r\n");
        let got = assemble_checked(&long, &[50]);
        assert_eq!(got, [Err(None), Ok("OK".into())]);
        let got = assemble_checked(b"A\r\nB\n", &[2]);
        assert_eq!(got, [Ok("A".into()), Err(None), Ok("B".into())]);
        // Once per line: the error is reported at the line's end, then cleared.
        let got = assemble_checked(b"ABC\nDEF\n", &[1, 2]);
        assert_eq!(got, [Err(None), Ok("DEF".into())]);
        // `push` (sources that cannot overrun) reports a marked line as invalid, not a line.
        let mut asm = LineAssembler::new();
        asm.overrun();
        let r: Vec<_> = b"STATUS\n"
            .iter()
            .filter_map(|&b| asm.push(b).map(|a| a == Assembled::Invalid))
            .collect();
        assert_eq!(r, [true]);
    }

    #[test]
    fn assembler_limits() {
        let exact = [b'a'; MAX_LINE];
        let mut stream = Vec::from(exact);
        stream.push(b'\n');
        stream.extend_from_slice(&[b'b'; MAX_LINE + 1]);
        stream.extend_from_slice(&[b'c'; 500]);
        stream.extend_from_slice(b"\nSTATUS\n");
        let got = assemble(&stream);
        assert_eq!(got.len(), 3);
        assert_eq!(got[0], Ok(String::from_utf8(exact.to_vec()).unwrap()));
        assert_eq!(got[1], Err(Assembled::TooLong));
        assert_eq!(got[2], Ok("STATUS".into()));
    }

    #[test]
    fn assembler_refuses_a_line_that_is_not_printable_ascii() {
        // Not UTF-8, UTF-8 that is not ASCII, a NUL, a DEL: the protocol's lines are printable
        // ASCII (and tabs).
        let got = assemble(b"ST\xffATUS\n\xc3\xbc\nMORPH 38\x00\nSTA\x7fTUS\nMORPH\t38\n");
        let invalid = Err(Assembled::Invalid);
        assert_eq!(
            got,
            [
                invalid.clone(),
                invalid.clone(),
                invalid.clone(),
                invalid,
                Ok("MORPH\t38".into())
            ]
        );
    }

    /// What the assembler should report for each segment of `bytes` ended by `\n`, `\r` or
    /// `\r\n`.
    fn model(bytes: &[u8]) -> Vec<Result<String, Assembled<'static>>> {
        let mut segments: Vec<Vec<u8>> = Vec::new();
        let mut seg = Vec::new();
        let mut after_cr = false;
        for &b in bytes {
            match b {
                b'\n' if after_cr => after_cr = false,
                b'\r' | b'\n' => {
                    segments.push(core::mem::take(&mut seg));
                    after_cr = b == b'\r';
                }
                _ => {
                    seg.push(b);
                    after_cr = false;
                }
            }
        }
        segments
            .into_iter()
            .map(|kept| {
                if kept.len() > MAX_LINE {
                    Err(Assembled::TooLong)
                } else if kept
                    .iter()
                    .all(|&b| b == b'\t' || (b' '..=b'~').contains(&b))
                {
                    Ok(String::from_utf8(kept).unwrap())
                } else {
                    Err(Assembled::Invalid)
                }
            })
            .collect()
    }

    /// Bytes weighted towards line structure: newlines, CRs, spaces, command letters, junk.
    fn stream() -> impl Strategy<Value = Vec<u8>> {
        let byte = prop_oneof![
            3 => Just(b'\n'),
            2 => Just(b'\r'),
            3 => Just(b' '),
            10 => prop::sample::select(b"MORPHSIMFAULTSTATUS0123456789.-abcdeptw".to_vec()),
            2 => any::<u8>(),
        ];
        let long = prop::collection::vec(b'a'..=b'z', 60..200);
        prop::collection::vec(
            prop_oneof![4 => prop::collection::vec(byte, 0..20), 1 => long],
            0..20,
        )
        .prop_map(|parts| parts.concat())
    }

    proptest! {

        #[test]
        fn assembler_matches_model_and_parse_answers_once(bytes in stream()) {
            let got = assemble(&bytes);
            prop_assert_eq!(&got, &model(&bytes));
            for line in got.iter().filter_map(|r| r.as_ref().ok()) {
                let result = parse_line(line);
                let blank = line.trim_matches(|c: char| c.is_ascii_whitespace()).is_empty();
                // A non-blank line gets exactly one answer: a command or an error.
                prop_assert_eq!(matches!(result, Ok(None)), blank, "{:?}", line);
            }
        }

        #[test]
        fn parse_line_never_panics(line in "\\PC{0,80}") {
            let _ = parse_line(&line);
        }

        #[test]
        fn parse_line_never_panics_on_near_commands(
            line in "(?i)(morph|sim|status|fault)( {1,2}[a-z0-9.\\-+ü]{0,8}){0,4}"
        ) {
            let result = parse_line(&line);
            prop_assert!(!matches!(result, Ok(None)));
        }

        #[test]
        fn morph_round_trip(
            radius_mm in 1e-3f32..1e5,
            decimals in 0u8..=3,
            mode in prop::option::of(prop::sample::select(MODES.to_vec())),
            upper in any::<bool>(),
            sep in "[ \t]{1,3}",
        ) {
            let number = format!("{}", Fixed(radius_mm, decimals));
            let expected = crate::fixed::parse_decimal(&number).unwrap_or(f32::NAN);
            prop_assume!(expected > 0.0);
            let mut line = format!("MORPH{sep}{number}");
            if let Some(mode) = mode {
                line = format!("{line}{sep}{}", mode.as_str());
            }
            if !upper {
                line = line.to_lowercase();
            }
            let want = Command::Morph { radius_mm: expected, mode: mode.unwrap_or(Mode::Auto) };
            prop_assert_eq!(parse_line(&line), Ok(Some(want)));
            let tol = 0.5 * 10f32.powi(-(decimals as i32)) + radius_mm * 2.0 * f32::EPSILON;
            prop_assert!((expected - radius_mm).abs() <= tol);
        }
    }
}

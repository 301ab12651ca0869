//! Protocol v1: bounded line assembly, command parsing and reply/event formatting.
//!
//! ASCII lines ending in `\n` (a `\r` before it is ignored), at most [`MAX_LINE`] characters,
//! commands case-insensitive. Every command line gets exactly one final reply (`ok ...` or
//! `error: <code> <text>`), optionally preceded by `data: ...` lines. Unsolicited lines are
//! `event: ...` and `alarm: <code> <text>`.

/// Longest accepted line in characters, excluding the line ending.
pub const MAX_LINE: usize = 64;

/// Morph strategy requested with `MORPH <radius_mm> [mode]`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Mode {
    /// Thermistor-gated phases with the table's power (the default).
    Auto,
    /// The paper's fixed timing: PLA 4 W 0–20 s, 1.5 W 20–70 s; TCA 20–120 s.
    Paper,
}

/// One of the three thermistors.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Sensor {
    /// On the PLA rod.
    Pla,
    /// Beside the TCA.
    Tca,
    /// In the surrounding medium.
    Amb,
}

/// One of the two heaters.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Heater {
    /// Nichrome wrap on the PLA rod.
    Pla,
    /// The twisted-and-coiled actuator itself (Joule heated).
    Tca,
}

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
    /// Heater wire broken: commanded power produces no heat.
    HeaterOpen,
    /// MOSFET shorted: the heater runs at full supply power whatever is commanded.
    HeaterStuck,
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
}

/// A parsed command line.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Command {
    /// `MORPH <radius_mm> [auto|paper]`.
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
    /// `SIM ...` (simulated builds only).
    Sim(SimCommand),
}

/// Error codes of `error: <code> <text>` replies (kebab-case on the wire).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ErrorCode {
    /// The first word is not a command.
    UnknownCommand,
    /// An argument is missing, extra or malformed.
    BadArgument,
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
}

/// A protocol error: a code and a sentence for the user.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ProtoError {
    /// Machine-readable code.
    pub code: ErrorCode,
    /// Human-readable explanation (no line breaks).
    pub text: &'static str,
}

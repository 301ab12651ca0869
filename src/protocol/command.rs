//! Command parsing: one received line → a [`Command`] or a [`ProtoError`].

use super::{
    Command, ConfigCommand, ErrorCode, Heater, Medium, Mode, ProtoError, Sensor, SimCommand,
    SimFault, Word, MODES,
};

/// Every [`Sensor`], for matching wire words.
const SENSORS: [Sensor; 3] = [Sensor::Pla, Sensor::Tca, Sensor::Amb];
/// Every [`Medium`], for matching wire words.
const MEDIA: [Medium; 2] = [Medium::Water, Medium::Air];
/// Every [`SimFault`], for matching wire words.
const SIM_FAULTS: [SimFault; 7] = [
    SimFault::ThermistorOpen,
    SimFault::ThermistorShort,
    SimFault::ThermistorStuck,
    SimFault::HeaterOpen,
    SimFault::HeaterStuck,
    SimFault::ThermistorDrift,
    SimFault::CutoffStuck,
];

/// Finds the item whose wire word equals `word`, ignoring ASCII case.
fn lookup<T: Copy>(items: &[T], word: &str, name: fn(T) -> &'static str) -> Option<T> {
    items
        .iter()
        .copied()
        .find(|&item| name(item).eq_ignore_ascii_case(word))
}

/// Shorthand for a `bad-argument` error.
const fn bad(text: &'static str) -> ProtoError {
    ProtoError {
        code: ErrorCode::BadArgument,
        text,
    }
}

/// Reply to a first word that is no command.
const UNKNOWN: ProtoError = ProtoError {
    code: ErrorCode::UnknownCommand,
    text: "Unknown command; send HELP for the list of commands.",
};

/// Splits on runs of spaces and tabs.
fn words(line: &str) -> impl Iterator<Item = &str> {
    line.split([' ', '\t']).filter(|w| !w.is_empty())
}

/// Parses one command line (without its line ending).
///
/// Leading/trailing ASCII whitespace is ignored and a blank line gives `Ok(None)`. Command and
/// keyword words match case-insensitively; numbers use [`crate::fixed::parse_decimal`]. Only the
/// syntax is checked here: a MORPH radius must be a positive number, but whether it is
/// reachable (and whether SIM values are within limits) is decided by the caller.
pub fn parse_line(line: &str) -> Result<Option<Command>, ProtoError> {
    let line = line.trim_matches(|c: char| c.is_ascii_whitespace());
    let mut args = words(line);
    let Some(first) = args.next() else {
        return Ok(None);
    };
    let simple = [
        ("STATUS", Command::Status),
        ("ABORT", Command::Abort),
        ("RESET", Command::Reset),
        ("RANGE", Command::Range),
        ("TABLE", Command::Table),
        ("VERSION", Command::Version),
        ("HELP", Command::Help),
        ("STATS", Command::Stats),
        ("SAVE", Command::Save),
        ("TUNE", Command::Tune),
    ];
    for (word, command) in simple {
        if first.eq_ignore_ascii_case(word) {
            return no_args(args, word).map(|()| Some(command));
        }
    }
    if first.eq_ignore_ascii_case("MEASURED") {
        return parse_measured(args).map(Some);
    }
    if first.eq_ignore_ascii_case("MORPH") {
        parse_morph(args).map(Some)
    } else if first.eq_ignore_ascii_case("SIM") {
        // A build without the simulated link answers every SIM line alike, so a board's image
        // carries neither the SIM grammar nor its error texts.
        if cfg!(feature = "sim") {
            parse_sim(args).map(|sim| Some(Command::Sim(sim)))
        } else {
            Err(super::reply::ERR_SIM_UNSUPPORTED)
        }
    } else if first.eq_ignore_ascii_case("CONFIG") {
        parse_config(args).map(|c| Some(Command::Config(c)))
    } else if first.eq_ignore_ascii_case("HEAT") {
        parse_heat(args).map(Some)
    } else {
        Err(UNKNOWN)
    }
}

/// `Ok` if `args` is exhausted, else `bad-argument <command> takes no arguments.`
/// ([`ErrorCode::NoArguments`]).
pub(crate) fn no_args<'a>(
    mut args: impl Iterator<Item = &'a str>,
    command: &'static str,
) -> Result<(), ProtoError> {
    match args.next() {
        None => Ok(()),
        Some(_) => Err(ProtoError {
            code: ErrorCode::NoArguments,
            text: command,
        }),
    }
}

/// `Ok` if `args` is exhausted, else `bad-argument` with `text`.
fn no_more<'a>(
    mut args: impl Iterator<Item = &'a str>,
    text: &'static str,
) -> Result<(), ProtoError> {
    match args.next() {
        None => Ok(()),
        Some(_) => Err(bad(text)),
    }
}

/// `MORPH <radius_mm> [auto|paper|gated|boost|closed]` after the command word.
fn parse_morph<'a>(mut args: impl Iterator<Item = &'a str>) -> Result<Command, ProtoError> {
    let radius = args
        .next()
        .ok_or(bad("MORPH needs a radius in mm, e.g. MORPH 38."))?;
    let radius_mm = crate::fixed::parse_decimal(radius).ok_or(bad(
        "MORPH radius must be a plain number of mm, e.g. MORPH 38.5.",
    ))?;
    if !radius_mm.is_finite() || radius_mm <= 0.0 {
        return Err(bad("MORPH radius must be greater than 0 mm."));
    }
    let mode = match args.next() {
        None => Mode::Auto,
        Some(word) => lookup(&MODES, word, Mode::as_str).ok_or(bad(
            "MORPH mode must be auto, paper, gated, boost or closed.",
        ))?,
    };
    no_more(
        args,
        "MORPH takes a radius and an optional mode (auto, paper, gated, boost, closed).",
    )?;
    Ok(Command::Morph { radius_mm, mode })
}

/// `SIM <subcommand> ...` after the command word.
fn parse_sim<'a>(mut args: impl Iterator<Item = &'a str>) -> Result<SimCommand, ProtoError> {
    const NEEDS_SUB: &str =
        "SIM needs STATE, FAULT, SUPPLY, AMBIENT, MEDIUM, WAIT, CLEAR, PANIC or STALL.";
    let sub = args.next().ok_or(bad(NEEDS_SUB))?;
    let is = |word: &str| sub.eq_ignore_ascii_case(word);
    let sim = if is("STATE") {
        SimCommand::State
    } else if is("CLEAR") {
        SimCommand::Clear
    } else if is("PANIC") {
        SimCommand::Panic
    } else if is("STALL") {
        SimCommand::Stall
    } else if is("FAULT") {
        parse_sim_fault(&mut args)?
    } else if is("SUPPLY") {
        let volts = number(
            args.next(),
            "SIM SUPPLY needs a voltage in V, e.g. SIM SUPPLY 5.",
        )?;
        SimCommand::Supply(volts)
    } else if is("AMBIENT") {
        let temp_c = number(
            args.next(),
            "SIM AMBIENT needs a temperature in degrees C, e.g. SIM AMBIENT 25.",
        )?;
        SimCommand::Ambient(temp_c)
    } else if is("WAIT") {
        let seconds = number(
            args.next(),
            "SIM WAIT needs a duration in s, e.g. SIM WAIT 60.",
        )?;
        SimCommand::Wait(seconds)
    } else if is("MEDIUM") {
        let medium = args
            .next()
            .and_then(|word| lookup(&MEDIA, word, Medium::as_str))
            .ok_or(bad("SIM MEDIUM needs water or air."))?;
        SimCommand::Medium(medium)
    } else {
        return Err(bad(NEEDS_SUB));
    };
    let extra = match sim {
        SimCommand::State => return no_args(args, "SIM STATE").map(|()| sim),
        SimCommand::Clear => return no_args(args, "SIM CLEAR").map(|()| sim),
        SimCommand::Panic => return no_args(args, "SIM PANIC").map(|()| sim),
        SimCommand::Stall => return no_args(args, "SIM STALL").map(|()| sim),
        SimCommand::Fault(..) => "SIM FAULT takes a kind and an optional target (pla, tca or amb).",
        SimCommand::Supply(_) => "SIM SUPPLY takes one voltage.",
        SimCommand::Ambient(_) => "SIM AMBIENT takes one temperature.",
        SimCommand::Medium(_) => "SIM MEDIUM takes one medium.",
        SimCommand::Wait(_) => "SIM WAIT takes one duration in s.",
        SimCommand::Drift(..) => {
            "SIM FAULT thermistor-drift takes a sensor and a rate in K/s, e.g. SIM FAULT thermistor-drift tca -0.2."
        }
    };
    no_more(args, extra)?;
    Ok(sim)
}

/// `SIM FAULT <kind> [pla|tca|amb]` after `FAULT`; the target defaults to `pla`.
fn parse_sim_fault<'a>(args: &mut impl Iterator<Item = &'a str>) -> Result<SimCommand, ProtoError> {
    let kind = args
        .next()
        .and_then(|word| lookup(&SIM_FAULTS, word, SimFault::as_str))
        .ok_or(bad(
            "SIM FAULT needs thermistor-open, thermistor-short, thermistor-stuck, thermistor-drift, heater-open, heater-stuck or cutoff-stuck.",
        ))?;
    if kind == SimFault::ThermistorDrift {
        return parse_sim_drift(args);
    }
    if kind == SimFault::CutoffStuck {
        no_more(
            args,
            "SIM FAULT cutoff-stuck takes no target: the cut-off serves both heaters.",
        )?;
        return Ok(SimCommand::Fault(kind, Sensor::Pla));
    }
    let target = match args.next() {
        None => Sensor::Pla,
        Some(word) => lookup(&SENSORS, word, Sensor::as_str)
            .ok_or(bad("SIM FAULT target must be pla, tca or amb."))?,
    };
    let heater_fault = matches!(kind, SimFault::HeaterOpen | SimFault::HeaterStuck);
    if heater_fault && target == Sensor::Amb {
        return Err(bad("Heater faults target pla or tca; amb has no heater."));
    }
    Ok(SimCommand::Fault(kind, target))
}

/// A required decimal argument, `bad-argument` with `text` if missing or malformed.
fn number(word: Option<&str>, text: &'static str) -> Result<f32, ProtoError> {
    word.and_then(crate::fixed::parse_decimal)
        .filter(|v| v.is_finite())
        .ok_or(bad(text))
}

/// `CONFIG [SET <name> <value> | RESET]` after the command word. The name and value are only
/// split here; the settings registry judges them.
fn parse_config<'a>(mut args: impl Iterator<Item = &'a str>) -> Result<ConfigCommand, ProtoError> {
    const USAGE: &str = "CONFIG takes nothing, SET <name> <value> or RESET.";
    let Some(sub) = args.next() else {
        return Ok(ConfigCommand::List);
    };
    if sub.eq_ignore_ascii_case("RESET") {
        no_args(args, "CONFIG RESET")?;
        return Ok(ConfigCommand::Reset);
    }
    if !sub.eq_ignore_ascii_case("SET") {
        return Err(bad(USAGE));
    }
    const NEEDS: &str = "CONFIG SET needs a setting name and a value, e.g. CONFIG SET lock_timeout_s 300; send CONFIG for the list.";
    let name = args.next().ok_or(bad(NEEDS))?;
    let value = args.next().ok_or(bad(NEEDS))?;
    no_more(args, "CONFIG SET takes one name and one value.")?;
    let name = Word::new(name).ok_or(bad(
        "CONFIG SET: no setting has so long a name; send CONFIG for the list.",
    ))?;
    let value = Word::new(value).ok_or(bad("CONFIG SET: the value is too long."))?;
    Ok(ConfigCommand::Set { name, value })
}

/// `HEAT <pla|tca> <power_w> <s>` after the command word (the bounds are checked by the
/// controller, [`crate::pulse`]). The words are gathered in one loop, so the word splitter is
/// inlined once, not once per argument (flash on small parts).
fn parse_heat<'a>(args: impl Iterator<Item = &'a str>) -> Result<Command, ProtoError> {
    const USAGE: &str = "HEAT needs a heater, a power in W and seconds, e.g. HEAT pla 0.8 10.";
    // Heater, power, seconds, and a slot that must stay empty.
    let mut w: [Option<&str>; 4] = [None; 4];
    for (slot, word) in w.iter_mut().zip(args) {
        *slot = Some(word);
    }
    if w[3].is_some() {
        return Err(bad(USAGE));
    }
    // The heaters' words are the sensors' (each heater has its thermistor): the sensor
    // lookup SIM FAULT uses serves, with amb refused.
    let heater = match w[0].and_then(|w| lookup(&SENSORS, w, Sensor::as_str)) {
        Some(Sensor::Pla) => Heater::Pla,
        Some(Sensor::Tca) => Heater::Tca,
        _ => return Err(bad(USAGE)),
    };
    Ok(Command::Heat {
        heater,
        power_w: number(w[1], USAGE)?,
        duration_s: number(w[2], USAGE)?,
    })
}

/// `SIM FAULT thermistor-drift <pla|tca|amb> <K/s>` after `thermistor-drift`: both are
/// required (a drift has no sensible default rate). Whether the rate is within the bench's
/// bound is decided by the bench.
fn parse_sim_drift<'a>(args: &mut impl Iterator<Item = &'a str>) -> Result<SimCommand, ProtoError> {
    const NEEDS: &str =
        "SIM FAULT thermistor-drift needs a sensor (pla, tca or amb) and a rate in K/s, e.g. SIM FAULT thermistor-drift tca -0.2.";
    let sensor = args
        .next()
        .and_then(|word| lookup(&SENSORS, word, Sensor::as_str))
        .ok_or(bad(NEEDS))?;
    let rate_k_per_s = number(args.next(), NEEDS)?;
    Ok(SimCommand::Drift(sensor, rate_k_per_s))
}

/// `MEASURED <radius_mm>`: one plain positive number of mm.
fn parse_measured<'a>(mut args: impl Iterator<Item = &'a str>) -> Result<Command, ProtoError> {
    let radius = args.next().ok_or(bad(
        "MEASURED needs the radius you measured in mm, e.g. MEASURED 38.2.",
    ))?;
    let radius_mm = crate::fixed::parse_decimal(radius).ok_or(bad(
        "MEASURED radius must be a plain number of mm, e.g. MEASURED 38.2.",
    ))?;
    if !radius_mm.is_finite() || radius_mm <= 0.0 {
        return Err(bad("MEASURED radius must be greater than 0 mm."));
    }
    no_more(args, "MEASURED takes one radius in mm.")?;
    Ok(Command::Measured { radius_mm })
}

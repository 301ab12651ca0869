//! Plant protocol 1: any outside model (a Python FEM, a recorded experiment, a rig's sensors)
//! drives the real controller tick by tick by answering [`Plant`]'s questions over text lines.
//!
//! This is the plant's protocol, not the controller's: it carries heater duties, time, bead
//! temperatures, supply and radius, and knows no command, phase or alarm. So it lives with the
//! plant, and this module is its one home: every line of it is written and parsed here, for
//! both sides (the rig's `RemotePlant` in `morphlink-host`, and [`serve`] for a plant). The
//! controller's own wire text stays in `morphlink::protocol` (`tests/wire_text.rs` exempts
//! exactly this file).
//!
//! Lines end in `\n`; a verb, then `key=value` tokens separated by single spaces. Unknown keys
//! are ignored by both sides, so either may add fields later.
//!
//! | from | line | meaning |
//! | --- | --- | --- |
//! | rig | `hello protocol=1 tick_s=<s>` | once, at start (`tick_s` over 0, at most [`STEP_MAX_S`]) |
//! | rig | `step dt_s=<s> pla_duty=<0..1> tca_duty=<0..1>` | hold these duties for `dt_s` (0 to [`STEP_MAX_S`]), then reply |
//! | rig | `set supply_v=<V>`, `set ambient_c=<°C>`, `set medium=<water\|air>` | a `SIM` change ([`SUPPLY_MAX_V`], [`AMBIENT_RANGE_C`]) |
//! | plant | `ok t_pla_c=<°C> t_tca_c=<°C> t_amb_c=<°C> supply_v=<V> radius_mm=<mm>` and optionally `r_pla_ohm=<Ω> r_tca_ohm=<Ω>` | to every line; the resistances (both or neither) are the heaters' true ones at this step, for a board that senses current |
//! | plant | `error: <text>` | refused; `error: unsupported ...` to a `set` it cannot do |
//!
//! ```text
//! > hello protocol=1 tick_s=0.1
//! < ok t_pla_c=22 t_tca_c=22 t_amb_c=22 supply_v=12 radius_mm=53.065346621112695 r_pla_ohm=30 r_tca_ohm=6.5
//! > step dt_s=0.1 pla_duty=0.8333333333333334 tca_duty=0
//! < ok t_pla_c=22.072693128353844 t_tca_c=22 t_amb_c=22 supply_v=12 radius_mm=53.06534662111271 r_pla_ohm=30.00665202700923 r_tca_ohm=6.5
//! > set medium=air
//! < error: unsupported medium
//! ```
//! (the lumped plant, `morph-plant`; the last reply is a plant that cannot change its medium).
//!
//! Numbers are written with Rust's shortest round-trip form, so a value crosses the pipe
//! exactly. Formatting goes into any [`core::fmt::Write`] and parsing reads a `&str`: the codec
//! is `no_std` and allocation-free; only [`serve`] (feature `std`) does I/O.

use crate::{Duties, Medium, Plant, Sample, SetError, Setting};
use core::fmt::{self, Write};

/// The plant protocol's version, sent in `hello`.
pub const PROTOCOL: u32 = 1;

/// Longest step (and control tick) a `hello` or `step` may ask for, s: a rig steps once per
/// control tick (0.1 s); a step far longer is a mistake, and the plant's work grows with it
/// (a `step dt_s=1e308` ran for good).
pub const STEP_MAX_S: f64 = 10.0;
/// Highest supply a `set supply_v` may ask for, V: above any board's heaters and their parts.
pub const SUPPLY_MAX_V: f64 = 60.0;
/// The surroundings a `set ambient_c` may ask for, °C: cold room to hot bath, a liquid medium
/// throughout.
pub const AMBIENT_RANGE_C: (f64, f64) = (-20.0, 100.0);

/// The word an `error:` reply starts with when a plant cannot make a [`Setting`].
pub const UNSUPPORTED: &str = "unsupported";

/// A line from the rig to the plant.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Request {
    /// `hello protocol=<n> tick_s=<s>`: once, at start.
    Hello {
        /// Protocol version the rig speaks.
        protocol: u32,
        /// The rig's control period, s (a hint: each `step` says its own `dt_s`).
        tick_s: f64,
    },
    /// `step dt_s=<s> pla_duty=<0..1> tca_duty=<0..1>`.
    Step {
        /// How long to hold the duties, s.
        dt_s: f64,
        /// The duties that reach the heaters.
        duty: Duties,
    },
    /// `set supply_v=<V>` / `set ambient_c=<°C>` / `set medium=<water|air>`.
    Set(Setting),
}

/// A line from the plant to the rig.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Reply<'a> {
    /// `ok t_pla_c= t_tca_c= t_amb_c= supply_v= radius_mm=`: what the link shows now.
    Ok(Sample),
    /// `error: <text>` (the text without the tag and the space after it).
    Error(&'a str),
}

impl Reply<'_> {
    /// `true` for `error: unsupported ...`, a plant's refusal of a [`Setting`].
    pub fn is_unsupported(&self) -> bool {
        matches!(self, Reply::Error(t) if t.split(' ').next() == Some(UNSUPPORTED))
    }
}

/// Why a line is not a valid plant-protocol line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ParseError {
    /// Nothing on the line.
    Empty,
    /// The first word is no verb of this side.
    UnknownVerb,
    /// A token after the verb has no `=`.
    NotKeyValue,
    /// A required key is missing.
    Missing(&'static str),
    /// A key's value is not a number in its range (or not a known word).
    BadValue(&'static str),
    /// The line starts with a space, not with its verb.
    LeadingSpace,
    /// A key is given twice: which value is meant is not said.
    RepeatedKey,
    /// A `set` line names more than one setting: each takes a line of its own.
    SeveralSettings,
}

impl fmt::Display for ParseError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            ParseError::Empty => write!(f, "empty line"),
            ParseError::UnknownVerb => write!(f, "unknown verb"),
            ParseError::NotKeyValue => write!(f, "a token is not key=value"),
            ParseError::Missing(k) => write!(f, "missing {k}="),
            ParseError::BadValue(k) => write!(f, "bad value for {k}="),
            ParseError::LeadingSpace => write!(f, "the line starts with a space, not its verb"),
            ParseError::RepeatedKey => write!(f, "a key is given twice"),
            ParseError::SeveralSettings => write!(f, "a set line takes one setting"),
        }
    }
}

const HELLO: &str = "hello";
const STEP: &str = "step";
const SET: &str = "set";
const OK: &str = "ok";
const ERROR_TAG: &str = "error:";

fn medium_str(m: Medium) -> &'static str {
    match m {
        Medium::Water => "water",
        Medium::Air => "air",
    }
}

/// Writes one request line, without its `\n`.
pub fn write_request(w: &mut impl Write, r: &Request) -> fmt::Result {
    match *r {
        Request::Hello { protocol, tick_s } => {
            write!(w, "{HELLO} protocol={protocol} tick_s={tick_s}")
        }
        Request::Step { dt_s, duty } => write!(
            w,
            "{STEP} dt_s={dt_s} pla_duty={} tca_duty={}",
            duty.pla, duty.tca
        ),
        Request::Set(Setting::SupplyV(v)) => write!(w, "{SET} supply_v={v}"),
        Request::Set(Setting::AmbientC(c)) => write!(w, "{SET} ambient_c={c}"),
        Request::Set(Setting::Medium(m)) => write!(w, "{SET} medium={}", medium_str(m)),
    }
}

/// Writes `ok ...` for `s`, without its `\n`.
pub fn write_ok(w: &mut impl Write, s: &Sample) -> fmt::Result {
    write!(
        w,
        "{OK} t_pla_c={} t_tca_c={} t_amb_c={} supply_v={} radius_mm={}",
        s.t_pla_c, s.t_tca_c, s.t_amb_c, s.supply_v, s.radius_mm
    )?;
    match s.heater_ohm {
        Some([pla, tca]) => write!(w, " r_pla_ohm={pla} r_tca_ohm={tca}"),
        None => Ok(()),
    }
}

/// Writes `error: <text>`, without its `\n`.
pub fn write_error(w: &mut impl Write, text: impl fmt::Display) -> fmt::Result {
    write!(w, "{ERROR_TAG} {text}")
}

/// Writes one reply line, without its `\n`.
pub fn write_reply(w: &mut impl Write, r: &Reply<'_>) -> fmt::Result {
    match r {
        Reply::Ok(s) => write_ok(w, s),
        Reply::Error(t) => write_error(w, t),
    }
}

/// The verb and the `key=value` pairs of a line (a trailing `\r` or `\n` ignored).
fn split(line: &str) -> Result<(&str, KeyValues<'_>), ParseError> {
    let line = line.trim_end_matches(['\r', '\n']);
    let (verb, rest) = line.split_once(' ').unwrap_or((line, ""));
    if verb.is_empty() {
        return Err(match line.is_empty() {
            true => ParseError::Empty,
            false => ParseError::LeadingSpace,
        });
    }
    let kv = KeyValues(rest);
    for (i, token) in kv.tokens().enumerate() {
        let Some((key, _)) = token.split_once('=') else {
            return Err(ParseError::NotKeyValue);
        };
        let again = |t: &str| t.split_once('=').is_some_and(|(k, _)| k == key);
        if kv.tokens().skip(i + 1).any(again) {
            return Err(ParseError::RepeatedKey);
        }
    }
    Ok((verb, kv))
}

/// The `key=value` tokens after a verb.
#[derive(Clone, Copy)]
struct KeyValues<'a>(&'a str);

impl<'a> KeyValues<'a> {
    fn tokens(self) -> impl Iterator<Item = &'a str> {
        self.0.split(' ').filter(|t| !t.is_empty())
    }

    /// The value of the `key=` token (a line gives each key once: [`split`]).
    fn get(self, key: &str) -> Option<&'a str> {
        self.tokens()
            .filter_map(|t| t.split_once('='))
            .find(|(k, _)| *k == key)
            .map(|(_, v)| v)
    }

    fn number(self, key: &'static str) -> Result<f64, ParseError> {
        let v = self.get(key).ok_or(ParseError::Missing(key))?;
        v.parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or(ParseError::BadValue(key))
    }

    fn within(self, key: &'static str, (lo, hi): (f64, f64)) -> Result<f64, ParseError> {
        let v = self.number(key)?;
        if (lo..=hi).contains(&v) {
            Ok(v)
        } else {
            Err(ParseError::BadValue(key))
        }
    }

    fn duty(self, key: &'static str) -> Result<f64, ParseError> {
        let d = self.number(key)?;
        if (0.0..=1.0).contains(&d) {
            Ok(d)
        } else {
            Err(ParseError::BadValue(key))
        }
    }
}

/// Parses a request line (the plant's side).
pub fn parse_request(line: &str) -> Result<Request, ParseError> {
    let (verb, kv) = split(line)?;
    match verb {
        HELLO => {
            let protocol = kv.get("protocol").ok_or(ParseError::Missing("protocol"))?;
            let protocol = protocol
                .parse()
                .map_err(|_| ParseError::BadValue("protocol"))?;
            let tick_s = kv.number("tick_s")?;
            if !(tick_s > 0.0 && tick_s <= STEP_MAX_S) {
                return Err(ParseError::BadValue("tick_s"));
            }
            Ok(Request::Hello { protocol, tick_s })
        }
        STEP => {
            let dt_s = kv.number("dt_s")?;
            if !(0.0..=STEP_MAX_S).contains(&dt_s) {
                return Err(ParseError::BadValue("dt_s"));
            }
            let duty = Duties {
                pla: kv.duty("pla_duty")?,
                tca: kv.duty("tca_duty")?,
            };
            Ok(Request::Step { dt_s, duty })
        }
        SET => {
            // The known key names the setting; a set line carries one.
            let known = |t: &&str| {
                t.split_once('=')
                    .is_some_and(|(k, _)| ["supply_v", "ambient_c", "medium"].contains(&k))
            };
            if kv.tokens().filter(known).count() > 1 {
                return Err(ParseError::SeveralSettings);
            }
            for token in kv.tokens() {
                let Some((key, _)) = token.split_once('=') else {
                    continue;
                };
                return Ok(Request::Set(match key {
                    "supply_v" => Setting::SupplyV(kv.within("supply_v", (0.0, SUPPLY_MAX_V))?),
                    "ambient_c" => Setting::AmbientC(kv.within("ambient_c", AMBIENT_RANGE_C)?),
                    "medium" => Setting::Medium(match kv.get("medium") {
                        Some("water") => Medium::Water,
                        Some("air") => Medium::Air,
                        _ => return Err(ParseError::BadValue("medium")),
                    }),
                    _ => continue,
                }));
            }
            Err(ParseError::Missing("supply_v, ambient_c or medium"))
        }
        _ => Err(ParseError::UnknownVerb),
    }
}

/// Parses a reply line (the rig's side).
pub fn parse_reply(line: &str) -> Result<Reply<'_>, ParseError> {
    let trimmed = line.trim_end_matches(['\r', '\n']);
    if let Some(text) = trimmed.strip_prefix(ERROR_TAG) {
        return Ok(Reply::Error(text.trim_start_matches(' ')));
    }
    let (verb, kv) = split(trimmed)?;
    if verb != OK {
        return Err(ParseError::UnknownVerb);
    }
    Ok(Reply::Ok(Sample {
        t_pla_c: kv.number("t_pla_c")?,
        t_tca_c: kv.number("t_tca_c")?,
        t_amb_c: kv.number("t_amb_c")?,
        supply_v: kv.number("supply_v")?,
        radius_mm: kv.number("radius_mm")?,
        heater_ohm: heater_ohm(kv)?,
    }))
}

/// The optional `r_pla_ohm=` and `r_tca_ohm=`: both, positive and finite, or neither (a plant
/// that reports none runs on a board without current sense).
fn heater_ohm(kv: KeyValues<'_>) -> Result<Option<[f64; 2]>, ParseError> {
    let ohm = |key| -> Result<Option<f64>, ParseError> {
        match kv.get(key) {
            None => Ok(None),
            Some(_) => kv
                .number(key)
                .ok()
                .filter(|r| *r > 0.0)
                .map(Some)
                .ok_or(ParseError::BadValue(key)),
        }
    };
    match (ohm("r_pla_ohm")?, ohm("r_tca_ohm")?) {
        (Some(pla), Some(tca)) => Ok(Some([pla, tca])),
        (None, None) => Ok(None),
        (None, Some(_)) => Err(ParseError::Missing("r_pla_ohm")),
        (Some(_), None) => Err(ParseError::Missing("r_tca_ohm")),
    }
}

/// Writes the plant's one reply line (without its `\n`) to the request `line`: steps or sets
/// `plant` as asked and answers `ok ...` with its sample, or `error: ...`. The whole plant side
/// of the protocol, for [`serve`] or a plant with its own I/O (`no_std`).
pub fn answer<P: Plant + ?Sized>(plant: &mut P, line: &str, w: &mut impl Write) -> fmt::Result {
    match parse_request(line) {
        Ok(Request::Hello { protocol, .. }) if protocol != PROTOCOL => write_error(
            w,
            format_args!(
                "{UNSUPPORTED} protocol={protocol}, this plant speaks protocol={PROTOCOL}"
            ),
        ),
        Ok(Request::Hello { .. }) => write_ok(w, &plant.sample()),
        Ok(Request::Step { dt_s, duty }) => {
            plant.step(dt_s, duty);
            write_ok(w, &plant.sample())
        }
        Ok(Request::Set(setting)) => match plant.set(setting) {
            Ok(()) => write_ok(w, &plant.sample()),
            Err(SetError::Unsupported) => {
                let what = match setting {
                    Setting::SupplyV(_) => "supply_v",
                    Setting::AmbientC(_) => "ambient_c",
                    Setting::Medium(_) => "medium",
                };
                write_error(w, format_args!("{UNSUPPORTED} {what}"))
            }
        },
        Err(e) => write_error(w, format_args!("{e}: `{}`", line.trim_end())),
    }
}

/// Answers `plant` over the protocol: one reply line to each request line of `input`, until
/// the end of `input` (then returns `Ok`). A line that is not a request gets `error: ...` and
/// the loop goes on; the rig decides what an error means. A `step` or `set` before a `hello`
/// of this protocol is refused: the plant does not yet know the rig speaks its protocol.
#[cfg(any(test, feature = "std"))]
pub fn serve<P: Plant + ?Sized>(
    plant: &mut P,
    input: impl std::io::BufRead,
    mut output: impl std::io::Write,
) -> std::io::Result<()> {
    let mut reply = std::string::String::new();
    let mut greeted = false;
    for line in input.lines() {
        let line = line?;
        reply.clear();
        match parse_request(&line) {
            Ok(Request::Hello { protocol, .. }) => greeted |= protocol == PROTOCOL,
            Ok(_) if !greeted => {
                let _ = write_error(
                    &mut reply,
                    format_args!("hello first: `hello protocol={PROTOCOL} tick_s=<s>`"),
                );
                reply.push('\n');
                output.write_all(reply.as_bytes())?;
                output.flush()?;
                continue;
            }
            _ => {}
        }
        let _ = answer(plant, &line, &mut reply);
        reply.push('\n');
        output.write_all(reply.as_bytes())?;
        output.flush()?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::{Lumped, LumpedSpec, Truth};
    use std::string::String;

    fn request(r: &Request) -> String {
        let mut s = String::new();
        write_request(&mut s, r).unwrap();
        s
    }

    fn reply(r: &Reply) -> String {
        let mut s = String::new();
        write_reply(&mut s, r).unwrap();
        s
    }

    const SAMPLE: Sample = Sample {
        t_pla_c: 61.234_567_890_123,
        t_tca_c: -3.5,
        t_amb_c: 22.0,
        supply_v: 11.999_999_999_9,
        radius_mm: 37.812_5,
        heater_ohm: Some([30.000_000_1, 6.51]),
    };

    #[test]
    fn requests_round_trip_exactly() {
        let cases = [
            Request::Hello {
                protocol: 1,
                tick_s: 0.1,
            },
            Request::Step {
                dt_s: 0.1,
                duty: Duties {
                    pla: 0.833_333_333_333_4,
                    tca: 1.0 / 3.0,
                },
            },
            Request::Set(Setting::SupplyV(5.25)),
            Request::Set(Setting::AmbientC(-5.0)),
            Request::Set(Setting::Medium(Medium::Air)),
            Request::Set(Setting::Medium(Medium::Water)),
        ];
        for r in cases {
            let line = request(&r);
            assert_eq!(parse_request(&line), Ok(r), "{line}");
        }
        assert_eq!(
            request(&Request::Hello {
                protocol: 1,
                tick_s: 0.1
            }),
            "hello protocol=1 tick_s=0.1"
        );
        assert_eq!(
            request(&Request::Step {
                dt_s: 0.1,
                duty: Duties { pla: 0.5, tca: 0.0 }
            }),
            "step dt_s=0.1 pla_duty=0.5 tca_duty=0"
        );
        assert_eq!(
            request(&Request::Set(Setting::Medium(Medium::Air))),
            "set medium=air"
        );
    }

    #[test]
    fn replies_round_trip_exactly() {
        let line = reply(&Reply::Ok(SAMPLE));
        assert_eq!(parse_reply(&line), Ok(Reply::Ok(SAMPLE)));
        assert_eq!(
            reply(&Reply::Ok(Sample {
                t_pla_c: 22.0,
                t_tca_c: 23.5,
                t_amb_c: 22.0,
                supply_v: 12.0,
                radius_mm: 46.25,
                heater_ohm: None,
            })),
            "ok t_pla_c=22 t_tca_c=23.5 t_amb_c=22 supply_v=12 radius_mm=46.25"
        );
        // The resistances: both or neither, positive.
        assert_eq!(
            parse_reply("ok t_pla_c=22 t_tca_c=23.5 t_amb_c=22 supply_v=12 radius_mm=46.25 r_tca_ohm=6.5 r_pla_ohm=30")
                .map(|r| match r { Reply::Ok(s) => s.heater_ohm, _ => None }),
            Ok(Some([30.0, 6.5]))
        );
        assert_eq!(
            parse_reply(
                "ok t_pla_c=22 t_tca_c=23.5 t_amb_c=22 supply_v=12 radius_mm=46.25 r_tca_ohm=6.5"
            ),
            Err(ParseError::Missing("r_pla_ohm"))
        );
        assert_eq!(
            parse_reply("ok t_pla_c=22 t_tca_c=23.5 t_amb_c=22 supply_v=12 radius_mm=46.25 r_pla_ohm=0 r_tca_ohm=6.5"),
            Err(ParseError::BadValue("r_pla_ohm"))
        );
        assert_eq!(reply(&Reply::Error("boom")), "error: boom");
        assert_eq!(parse_reply("error: boom\r\n"), Ok(Reply::Error("boom")));
        assert!(parse_reply("error: unsupported medium")
            .unwrap()
            .is_unsupported());
        assert!(!parse_reply("error: boom").unwrap().is_unsupported());
    }

    #[test]
    fn unknown_keys_are_ignored_and_order_is_free() {
        assert_eq!(
            parse_reply(
                "ok radius_mm=40 mesh=fine t_amb_c=20 t_tca_c=30 t_pla_c=50 supply_v=12 time_s=3"
            ),
            Ok(Reply::Ok(Sample {
                t_pla_c: 50.0,
                t_tca_c: 30.0,
                t_amb_c: 20.0,
                supply_v: 12.0,
                radius_mm: 40.0,
                heater_ohm: None,
            }))
        );
        assert_eq!(
            parse_request("step seq=7 dt_s=0.1 tca_duty=0 pla_duty=1"),
            Ok(Request::Step {
                dt_s: 0.1,
                duty: Duties { pla: 1.0, tca: 0.0 }
            })
        );
        assert_eq!(
            parse_request("hello protocol=1 tick_s=0.1 rig=morph-sim"),
            Ok(Request::Hello {
                protocol: 1,
                tick_s: 0.1
            })
        );
        assert_eq!(
            parse_request("set colour=red ambient_c=30"),
            Ok(Request::Set(Setting::AmbientC(30.0)))
        );
    }

    #[test]
    fn malformed_lines_are_refused() {
        use ParseError::*;
        let requests = [
            ("", Empty),
            ("jump dt_s=1", UnknownVerb),
            ("step dt_s=0.1 pla_duty=0.5", Missing("tca_duty")),
            (
                "step dt_s=0.1 pla_duty=1.5 tca_duty=0",
                BadValue("pla_duty"),
            ),
            ("step dt_s=-1 pla_duty=0 tca_duty=0", BadValue("dt_s")),
            ("step dt_s=NaN pla_duty=0 tca_duty=0", BadValue("dt_s")),
            ("step dt_s=1e308 pla_duty=1 tca_duty=1", BadValue("dt_s")),
            ("hello protocol=1 tick_s=0", BadValue("tick_s")),
            ("hello protocol=1 tick_s=-1", BadValue("tick_s")),
            ("set supply_v=-12", BadValue("supply_v")),
            ("set supply_v=1e308", BadValue("supply_v")),
            ("set ambient_c=-300", BadValue("ambient_c")),
            ("step dt_s=0.1 pla_duty tca_duty=0", NotKeyValue),
            ("hello protocol=one tick_s=0.1", BadValue("protocol")),
            ("hello tick_s=0.1", Missing("protocol")),
            ("set medium=oil", BadValue("medium")),
            ("set", Missing("supply_v, ambient_c or medium")),
            ("OK t_pla_c=1", UnknownVerb),
            (" hello protocol=1 tick_s=0.1", LeadingSpace),
            ("hello protocol=2 protocol=1 tick_s=0.1", RepeatedKey),
            (
                "step dt_s=0.1 pla_duty=0 tca_duty=0 pla_duty=1",
                RepeatedKey,
            ),
            ("set ambient_c=30 supply_v=5", SeveralSettings),
        ];
        for (line, e) in requests {
            assert_eq!(parse_request(line), Err(e), "{line:?}");
        }
        let replies = [
            ("", Empty),
            ("garbage", UnknownVerb),
            ("ok", Missing("t_pla_c")),
            (
                "ok t_pla_c=1 t_tca_c=2 t_amb_c=3 supply_v=12",
                Missing("radius_mm"),
            ),
            (
                "ok t_pla_c=hot t_tca_c=2 t_amb_c=3 supply_v=12 radius_mm=40",
                BadValue("t_pla_c"),
            ),
            (
                "ok t_pla_c=inf t_tca_c=2 t_amb_c=3 supply_v=12 radius_mm=40",
                BadValue("t_pla_c"),
            ),
            ("ok t_pla_c=1 junk", NotKeyValue),
        ];
        for (line, e) in replies {
            assert_eq!(parse_reply(line), Err(e), "{line:?}");
        }
    }

    /// A plant that refuses every setting.
    struct Fixed;
    impl Plant for Fixed {
        fn step(&mut self, _: f64, _: Duties) {}
        fn sample(&self) -> Sample {
            SAMPLE
        }
        fn truth(&self) -> Truth {
            Truth {
                time_s: 0.0,
                pla_c: 0.0,
                tca_c: 0.0,
                pla_w: 0.0,
                tca_w: 0.0,
            }
        }
        fn set(&mut self, _: Setting) -> Result<(), SetError> {
            Err(SetError::Unsupported)
        }
    }

    fn answered(plant: &mut impl Plant, line: &str) -> String {
        let mut s = String::new();
        answer(plant, line, &mut s).unwrap();
        s
    }

    #[test]
    fn a_plant_answers_every_line() {
        let spec = LumpedSpec {
            params: morphlink_model::LinkParams::DEFAULT,
            heater_ohm: [30.0, 6.5],
            heater_tcr_per_k: crate::lumped::HEATER_TCR_NOMINAL_PER_K,
            supply_v: 12.0,
            sensor_tau_s: [3.0; 3],
        };
        let mut remote = Lumped::new(spec);
        let mut local = Lumped::new(spec);
        let hello = answered(&mut remote, "hello protocol=1 tick_s=0.1");
        assert_eq!(parse_reply(&hello), Ok(Reply::Ok(local.sample())));
        for _ in 0..50 {
            let duty = Duties {
                pla: 0.8,
                tca: 0.05,
            };
            local.step(0.1, duty);
            let line = request(&Request::Step { dt_s: 0.1, duty });
            let got = answered(&mut remote, &line);
            assert_eq!(parse_reply(&got), Ok(Reply::Ok(local.sample())), "{got}");
        }
        let got = answered(&mut remote, "set supply_v=9");
        assert!(
            matches!(parse_reply(&got), Ok(Reply::Ok(s)) if s.supply_v == 9.0),
            "{got}"
        );
        assert_eq!(
            answered(&mut remote, "hello protocol=2 tick_s=0.1"),
            "error: unsupported protocol=2, this plant speaks protocol=1"
        );
        assert_eq!(
            answered(&mut remote, "step dt_s=0.1"),
            "error: missing pla_duty=: `step dt_s=0.1`"
        );
        assert_eq!(
            answered(&mut Fixed, "set medium=air"),
            "error: unsupported medium"
        );
        assert!(parse_reply(&answered(&mut Fixed, "set supply_v=1"))
            .unwrap()
            .is_unsupported());
    }

    #[test]
    fn serve_answers_each_line_until_end_of_input() {
        let input = b"hello protocol=1 tick_s=0.1\nstep dt_s=0.1 pla_duty=0 tca_duty=0\nnonsense\n";
        let mut out = std::vec::Vec::new();
        serve(&mut Fixed, &input[..], &mut out).unwrap();
        let text = String::from_utf8(out).unwrap();
        let lines: std::vec::Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 3, "{text}");
        assert_eq!(parse_reply(lines[0]), Ok(Reply::Ok(SAMPLE)));
        assert_eq!(parse_reply(lines[1]), Ok(Reply::Ok(SAMPLE)));
        assert_eq!(lines[2], "error: unknown verb: `nonsense`");
    }

    #[test]
    fn serve_refuses_a_step_or_set_before_a_hello_of_its_protocol() {
        let input = b"step dt_s=0.1 pla_duty=0 tca_duty=0\nset supply_v=5\n\
            hello protocol=2 tick_s=0.1\nstep dt_s=0.1 pla_duty=0 tca_duty=0\n\
            hello protocol=1 tick_s=0.1\nstep dt_s=0.1 pla_duty=0 tca_duty=0\n";
        let mut out = std::vec::Vec::new();
        serve(&mut Fixed, &input[..], &mut out).unwrap();
        let text = String::from_utf8(out).unwrap();
        let lines: std::vec::Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 6, "{text}");
        let first = "error: hello first: `hello protocol=1 tick_s=<s>`";
        assert_eq!([lines[0], lines[1], lines[3]], [first; 3], "{text}");
        assert!(
            lines[2].starts_with("error: unsupported protocol=2"),
            "{text}"
        );
        assert_eq!(parse_reply(lines[4]), Ok(Reply::Ok(SAMPLE)));
        assert_eq!(parse_reply(lines[5]), Ok(Reply::Ok(SAMPLE)));
    }
}

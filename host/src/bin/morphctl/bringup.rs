//! `morphctl bringup`: the checks before a new board's first morph, under the supervisor. At
//! rest the three thermistors must agree within [`REST_SPREAD_K`] and the supply must be in
//! the supervisor's range; then a short low-power `HEAT` pulse of each heater must warm its own
//! thermistor and not the other's (crossed wiring is named). Whatever happens, it ends with
//! ABORT and a STATUS showing both heaters off (the caller's `stop_heaters`).
//!
//! The judgement ([`judge`]) is a pure function of the readings, tested on its own; [`run`]
//! takes the readings.

use crate::link::{Link, LinkError, REPLY_TIMEOUT_S};
use morphlink::protocol::client::{classify, LineKind, Status};
use morphlink::pulse::max_power_w;
use morphlink::supervisor::{supply_in_range, SUPPLY_MAX_V, SUPPLY_MIN_V};
use morphlink::vocab::Heater;
use std::time::{Duration, Instant};

/// Largest spread of the three thermistors at rest, K: three parts of one batch in the same air
/// read within about 1 K (B3950 ±1 %); 3 K leaves room for a warm hand or a board regulator
/// beside the ambient one, while a wrong part or pull-up (tens of kelvin off) fails.
pub const REST_SPREAD_K: f64 = 3.0;
/// Length of each heater's pulse, s: its bead answers within a few seconds (measured rises
/// below, docs: docs/bringup.md "Bring-up"), and the pulse ends a second before the supervisor's
/// residual tests' verdict time for a dead heater (`HEATER_VERDICT_S`); crossed wires may trip
/// them sooner, and the tool then judges the rise it saw.
pub const PULSE_S: f64 = morphlink::supervisor::HEATER_VERDICT_S as f64 - 1.0;
/// Time after a pulse during which the rise is still followed, s: the beads lag their heater.
pub const AFTER_PULSE_S: f64 = 10.0;
/// Least rise of a heater's own thermistor, K. Measured at 20 % of the cap for 10 s
/// (tests/heat.rs): the PLA bead rises 15 K (lumped) and 8 K (hifi), the TCA bead 8 K and 3.4 K
/// (the [`PULSE_S`] pulses a little less: docs/bringup.md "Bring-up"); 1.5 K is far above the readings'
/// noise and well under the weakest healthy rise.
pub const MIN_OWN_RISE_K: f64 = 1.5;
/// The own thermistor must rise at least this many times more than the other heater's: the
/// cross rise measured is under a quarter of the own (PLA pulse: TCA +2 K of +15 K; TCA
/// pulse: PLA +0.8 K of +8 K).
pub const OWN_OVER_OTHER: f64 = 2.0;
/// Most the ambient thermistor may rise during a pulse, K: it should sit away from the link.
pub const MAX_AMBIENT_RISE_K: f64 = 1.0;
/// STATUS readings averaged for the rest check.
const REST_READINGS: usize = 5;
/// Poll interval, s of link time.
const POLL_S: f64 = 0.5;

/// The readings at rest: the mean of [`REST_READINGS`] STATUS polls.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rest {
    /// PLA, TCA and ambient thermistors, °C (NaN if any poll had no reading).
    pub temps_c: [f64; 3],
    /// Supply, V.
    pub supply_v: f64,
}

/// What one heater's pulse did: the peak rise of each thermistor above its reading before the
/// pulse, K (PLA, TCA, ambient), over the pulse and [`AFTER_PULSE_S`] after it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rise {
    /// PLA, TCA and ambient rise, K.
    pub k: [f64; 3],
}

/// One check's verdict.
#[derive(Clone, Debug, PartialEq)]
pub struct Check {
    /// Passed?
    pub ok: bool,
    /// What was checked and what was seen (and, on a failure, what to look at).
    pub text: String,
}

fn check(ok: bool, text: String) -> Check {
    Check { ok, text }
}

/// Judges the rest readings (and the pulses, if they ran).
pub fn judge(rest: &Rest, pulses: Option<(Rise, Rise)>) -> Vec<Check> {
    let mut out = Vec::new();
    let names = ["pla", "tca", "amb"];
    let t = rest.temps_c;
    let missing: Vec<&str> = (0..3)
        .filter(|&i| !t[i].is_finite())
        .map(|i| names[i])
        .collect();
    if missing.is_empty() {
        let spread = t.iter().fold(f64::NEG_INFINITY, |a, &b| a.max(b))
            - t.iter().fold(f64::INFINITY, |a, &b| a.min(b));
        out.push(check(
            spread <= REST_SPREAD_K,
            format!(
                "thermistors at rest: pla {:.2} °C, tca {:.2} °C, amb {:.2} °C, spread {spread:.2} K (at most {REST_SPREAD_K} K){}",
                t[0], t[1], t[2],
                if spread <= REST_SPREAD_K { "" } else { "; check the odd one's part (10 kΩ B3950), its pull-up and its wiring" }
            ),
        ));
    } else {
        out.push(check(
            false,
            format!(
                "thermistors at rest: no reading from {} (open or shorted: check the wiring and the divider)",
                missing.join(", ")
            ),
        ));
    }
    let v = rest.supply_v;
    let supply_ok = supply_in_range(v as f32);
    out.push(check(
        supply_ok,
        format!(
            "heater supply: {v:.2} V (in {SUPPLY_MIN_V}..{SUPPLY_MAX_V} V){}",
            if supply_ok { "" } else { "; check the supply and the sense divider (SUPPLY_MIN_V, SUPPLY_MAX_V; see docs/safety.md)" }
        ),
    ));
    let Some((pla, tca)) = pulses else {
        return out;
    };
    let own = |r: &Rise, h: usize| r.k[h];
    let other = |r: &Rise, h: usize| r.k[1 - h];
    let warms_own = |r: &Rise, h: usize| {
        own(r, h) >= MIN_OWN_RISE_K && own(r, h) >= OWN_OVER_OTHER * other(r, h).max(0.0)
    };
    let warms_other = |r: &Rise, h: usize| {
        other(r, h) >= MIN_OWN_RISE_K && other(r, h) >= OWN_OVER_OTHER * own(r, h).max(0.0)
    };
    // Both crossed: one swap explains both.
    if warms_other(&pla, 0) && warms_other(&tca, 1) {
        out.push(check(
            false,
            format!(
                "PLA and TCA swapped: the PLA heater warmed the tca thermistor ({:+.2} K, its own {:+.2} K) and the TCA heater the pla one ({:+.2} K, its own {:+.2} K); swap either the two heater outputs or the pla and tca thermistor inputs (one pair, not both)",
                pla.k[1], pla.k[0], tca.k[0], tca.k[1]
            ),
        ));
    } else {
        for (h, r, name, sensor, other_sensor) in [
            (0, &pla, "PLA", "pla", "tca"),
            (1, &tca, "TCA", "tca", "pla"),
        ] {
            let text = if warms_own(r, h) {
                format!(
                    "{name} heater warms its own thermistor: {sensor} {:+.2} K, {other_sensor} {:+.2} K",
                    own(r, h),
                    other(r, h)
                )
            } else if warms_other(r, h) {
                format!(
                    "{name} heater warms the {other_sensor} thermistor ({:+.2} K) more than its own {sensor} ({:+.2} K): the {sensor} thermistor is not beside the {name} heater, or its wire is on the {other_sensor} input",
                    other(r, h),
                    own(r, h)
                )
            } else if own(r, h) >= MIN_OWN_RISE_K {
                format!(
                    "{name} heater warms both thermistors alike ({sensor} {:+.2} K, {other_sensor} {:+.2} K): the thermistors are too close together or on the wrong parts",
                    own(r, h),
                    other(r, h)
                )
            } else {
                format!(
                    "{name} heater warms no thermistor ({sensor} {:+.2} K, {other_sensor} {:+.2} K; at least {MIN_OWN_RISE_K} K expected): heater open or unpowered, its MOSFET, or its thermistor not on it",
                    own(r, h),
                    other(r, h)
                )
            };
            out.push(check(warms_own(r, h), text));
        }
    }
    let amb = pla.k[2].max(tca.k[2]);
    out.push(check(
        amb <= MAX_AMBIENT_RISE_K,
        format!(
            "ambient thermistor stays put during the pulses: {amb:+.2} K (at most {MAX_AMBIENT_RISE_K} K){}",
            if amb <= MAX_AMBIENT_RISE_K { "" } else { "; move it away from the heaters" }
        ),
    ));
    out
}

/// Why bring-up stopped before judging.
#[derive(Debug)]
pub enum Stop {
    /// The device is not in a state to start (a morph runs, a fault is latched) or refused a
    /// pulse.
    Refused(String),
    /// The link failed.
    Link(LinkError),
}

impl From<LinkError> for Stop {
    fn from(e: LinkError) -> Stop {
        Stop::Link(e)
    }
}

/// One STATUS, parsed to its temperatures and supply; a line that is not a STATUS is refused.
fn poll(link: &mut Link, say: &mut dyn FnMut(&str)) -> Result<([f64; 3], f64, String), Stop> {
    let (_, st) = link.command("STATUS", REPLY_TIMEOUT_S, &mut |l| say(l))?;
    let s = Status::parse(&st).ok_or_else(|| Stop::Refused(format!("STATUS answered `{st}`")))?;
    let f = |v: Option<f32>| v.map_or(f64::NAN, |v| v.to_string().parse().unwrap_or(f64::NAN));
    Ok((s.temps_c.map(f), f(s.supply_v), st))
}

/// Runs the checks on `link` (link seconds pass `speed` times faster than host seconds);
/// `say` gets each line to print (events, progress). An alarm during a pulse ends that pulse
/// (its rise so far is judged) and the next runs once RESET is accepted.
pub fn run(link: &mut Link, speed: f64, say: &mut dyn FnMut(&str)) -> Result<Vec<Check>, Stop> {
    let wait = |s: f64| Duration::from_secs_f64(s / speed);
    let (_, _, first) = poll(link, say)?;
    let phase = morphlink_phase(&first);
    if phase != "idle" {
        return Err(Stop::Refused(format!(
            "the device is in phase {phase}, not idle: {}",
            if phase == "fault" {
                "send RESET once the fault has cleared"
            } else {
                "let the morph end or send ABORT"
            }
        )));
    }
    let mut sum = [0.0; 3];
    let mut supply = 0.0;
    for _ in 0..REST_READINGS {
        let (t, v, st) = poll(link, say)?;
        if let Some(s) = Status::parse(&st).filter(|s| s.phase != "idle") {
            return Err(Stop::Refused(format!(
                "the device left idle during the rest readings: phase {}, fault {}",
                s.phase, s.fault
            )));
        }
        for i in 0..3 {
            sum[i] += t[i];
        }
        supply += v;
        std::thread::sleep(wait(POLL_S));
    }
    let n = REST_READINGS as f64;
    let rest = Rest {
        temps_c: sum.map(|s| s / n),
        supply_v: supply / n,
    };
    let verdicts = judge(&rest, None);
    if verdicts.iter().any(|c| !c.ok) {
        // Not safe to heat: report what is wrong first.
        return Ok(verdicts);
    }
    let mut rises = Vec::new();
    for heater in [Heater::Pla, Heater::Tca] {
        let (before, _, _) = poll(link, say)?;
        let power_w = max_power_w(heater);
        let line = format!("HEAT {} {power_w} {PULSE_S}", heater.as_str());
        say(&format!("> {line}"));
        let (_, reply) = link.command(&line, REPLY_TIMEOUT_S, &mut |l| say(l))?;
        say(&format!("< {reply}"));
        if classify(&reply) != LineKind::Ok {
            return Err(Stop::Refused(format!("`{line}` was refused: {reply}")));
        }
        let mut peak = [f64::NEG_INFINITY; 3];
        let until = Instant::now() + wait(PULSE_S + AFTER_PULSE_S);
        let mut alarm = None;
        let mut tripped = false;
        while Instant::now() < until && !tripped {
            let (t, _, _) = poll(link, &mut |l| {
                if classify(l) == LineKind::Alarm {
                    alarm = Some(l.to_string());
                }
                say(l)
            })?;
            if alarm.take().is_some() {
                // The supervisor names a wiring fault within seconds too: the rise so far is
                // this tool's diagnosis, and the next pulse runs once RESET is accepted.
                tripped = true;
            }
            for i in 0..3 {
                peak[i] = peak[i].max(t[i] - before[i]);
            }
            std::thread::sleep(wait(POLL_S));
            if let Some(l) = link.recv(Duration::ZERO)? {
                say(&l);
                tripped |= classify(&l) == LineKind::Alarm;
            }
        }
        if tripped {
            reset_when_clear(link, speed, heater, say)?;
        }
        say(&format!(
            "{} pulse ({power_w} W, {PULSE_S} s): pla {:+.2} K, tca {:+.2} K, amb {:+.2} K",
            heater.as_str(),
            peak[0],
            peak[1],
            peak[2]
        ));
        rises.push(Rise { k: peak });
    }
    Ok(judge(&rest, Some((rises[0], rises[1]))))
}

/// After a trip during `heater`'s pulse: sends RESET until the device accepts it (its
/// condition has cleared once the link cools back), for at most [`AFTER_PULSE_S`] × 6 link
/// seconds, else stops.
fn reset_when_clear(
    link: &mut Link,
    speed: f64,
    heater: Heater,
    say: &mut dyn FnMut(&str),
) -> Result<(), Stop> {
    let until = Instant::now() + Duration::from_secs_f64(6.0 * AFTER_PULSE_S / speed);
    while Instant::now() < until {
        say("> RESET");
        let (_, reply) = link.command("RESET", REPLY_TIMEOUT_S, &mut |l| say(l))?;
        say(&format!("< {reply}"));
        if classify(&reply) == LineKind::Ok {
            return Ok(());
        }
        std::thread::sleep(Duration::from_secs_f64(1.0 / speed));
    }
    Err(Stop::Refused(format!(
        "the supervisor tripped during the {} pulse and RESET was refused since",
        heater.as_str()
    )))
}

/// The phase word of a STATUS line.
fn morphlink_phase(status: &str) -> String {
    Status::parse(status).map_or("?", |s| s.phase).to_string()
}

#[cfg(test)]
mod tests {
    use super::*;

    const REST: Rest = Rest {
        temps_c: [22.1, 21.9, 22.0],
        supply_v: 12.0,
    };
    /// Rises measured on the lumped link (tests/heat.rs): PLA pulse, TCA pulse.
    const HEALTHY: (Rise, Rise) = (
        Rise {
            k: [15.3, 2.0, 0.0],
        },
        Rise { k: [0.8, 8.1, 0.0] },
    );

    fn failed(c: &[Check]) -> Vec<&str> {
        c.iter()
            .filter(|c| !c.ok)
            .map(|c| c.text.as_str())
            .collect()
    }

    #[test]
    fn a_healthy_board_passes_every_check() {
        let c = judge(&REST, Some(HEALTHY));
        assert!(failed(&c).is_empty(), "{c:?}");
        assert_eq!(c.len(), 5);
        assert!(
            c[2].text
                .starts_with("PLA heater warms its own thermistor: pla +15.30 K"),
            "{c:?}"
        );
        // The hifi link's weaker, slower rises pass too.
        let hifi = (Rise { k: [8.3, 1.0, 0.0] }, Rise { k: [0.4, 3.4, 0.0] });
        assert!(failed(&judge(&REST, Some(hifi))).is_empty());
    }

    #[test]
    fn swapped_thermistors_are_named_as_one_swap() {
        let (p, t) = HEALTHY;
        let swap = |r: Rise| Rise {
            k: [r.k[1], r.k[0], r.k[2]],
        };
        let c = judge(&REST, Some((swap(p), swap(t))));
        let f = failed(&c);
        assert_eq!(f.len(), 1, "{c:?}");
        assert!(f[0].starts_with("PLA and TCA swapped"), "{f:?}");
        assert!(f[0].contains("one pair, not both"), "{f:?}");
    }

    #[test]
    fn a_dead_heater_a_misplaced_thermistor_and_a_warm_ambient_are_named() {
        let (p, t) = HEALTHY;
        let dead = Rise { k: [0.1, 0.0, 0.0] };
        let f = judge(&REST, Some((p, dead)));
        let f = failed(&f);
        assert_eq!(f.len(), 1);
        assert!(f[0].starts_with("TCA heater warms no thermistor"), "{f:?}");
        // The tca thermistor sits on the PLA heater: the PLA pulse warms both channels alike.
        let f = judge(
            &REST,
            Some((
                Rise {
                    k: [15.0, 14.0, 0.0],
                },
                t,
            )),
        );
        assert!(
            failed(&f)[0].starts_with("PLA heater warms both thermistors alike"),
            "{f:?}"
        );
        let f = judge(&REST, Some((Rise { k: [2.0, 9.0, 0.0] }, t)));
        assert!(
            failed(&f)[0]
                .starts_with("PLA heater warms the tca thermistor (+9.00 K) more than its own"),
            "{f:?}"
        );
        let f = judge(
            &REST,
            Some((
                Rise {
                    k: [15.0, 2.0, 3.0],
                },
                t,
            )),
        );
        assert!(
            failed(&f)[0].starts_with("ambient thermistor stays put during the pulses: +3.00 K"),
            "{f:?}"
        );
    }

    #[test]
    fn rest_readings_and_the_supply_are_checked_before_any_pulse() {
        let c = judge(&REST, None);
        assert_eq!(c.len(), 2);
        assert!(failed(&c).is_empty(), "{c:?}");
        let odd = Rest {
            temps_c: [22.0, 30.5, 22.1],
            ..REST
        };
        let f = judge(&odd, None);
        assert!(
            failed(&f)[0].contains("spread 8.50 K (at most 3 K)"),
            "{f:?}"
        );
        let open = Rest {
            temps_c: [22.0, f64::NAN, 22.1],
            ..REST
        };
        let f = judge(&open, None);
        assert!(failed(&f)[0].contains("no reading from tca"), "{f:?}");
        for v in [8.5, 15.5, f64::NAN] {
            let low = Rest {
                supply_v: v,
                ..REST
            };
            let f = judge(&low, None);
            assert!(failed(&f)[0].starts_with("heater supply:"), "{v}: {f:?}");
        }
    }
}

//! `HEAT <pla|tca> <power_w> <s>`, the bring-up pulse: bounded, supervised, ended by its clock,
//! ABORT and any fault; on the lumped and the hifi link alike.
mod common;
use common::{Bench, Link};
use morphlink::pulse::{max_power_w, HEAT_MAX_S};
use morphlink::vocab::Heater;

fn num(line: &str, key: &str) -> f64 {
    Bench::field(line, key)
        .and_then(|v| v.parse().ok())
        .unwrap_or(f64::NAN)
}

fn status(b: &mut Bench) -> String {
    b.send("STATUS")[0].clone()
}

/// Pulses `heater` at its cap for `s` seconds on `link`; returns each thermistor's rise, K,
/// over the pulse and 20 s after it, and the alarms seen.
fn pulse(link: Link, heater: &str, s: f64) -> ([f64; 2], Vec<String>) {
    let mut b = Bench::on(link);
    b.run_for(2.0);
    let st = status(&mut b);
    let t0 = [num(&st, "t_pla_c"), num(&st, "t_tca_c")];
    let cap = max_power_w(if heater == "pla" {
        Heater::Pla
    } else {
        Heater::Tca
    });
    let r = b.send(&format!("HEAT {heater} {cap} {s}"));
    assert_eq!(r.len(), 1);
    assert!(r[0] == "ok", "{r:?}");
    let mut peak = t0;
    let from = b.lines.len();
    let mut t = 0.0;
    while t < s + 20.0 {
        b.run_for(0.5);
        t += 0.5;
        let st = status(&mut b);
        peak[0] = peak[0].max(num(&st, "t_pla_c"));
        peak[1] = peak[1].max(num(&st, "t_tca_c"));
    }
    ([peak[0] - t0[0], peak[1] - t0[1]], b.alarms_since(from))
}

#[test]
fn a_pulse_at_the_cap_warms_its_own_thermistor_and_raises_no_false_alarm() {
    for link in [Link::Lumped, Link::Hifi] {
        for (heater, own, other) in [("pla", 0, 1), ("tca", 1, 0)] {
            let (rise, alarms) = pulse(link, heater, 10.0);
            assert!(alarms.is_empty(), "{link:?} {heater}: {alarms:?}");
            println!(
                "{link:?} HEAT {heater} at its cap for 10 s: PLA +{:.2} K, TCA +{:.2} K",
                rise[0], rise[1]
            );
            assert!(rise[own] >= 2.0, "{link:?} {heater}: own rise {rise:?}");
            assert!(rise[other] < rise[own] / 2.0, "{link:?} {heater}: {rise:?}");
        }
    }
}

#[test]
fn a_pulse_drives_one_heater_then_ends_on_its_clock_or_at_abort() {
    let mut b = Bench::new();
    b.run_for(1.0);
    assert_eq!(b.send("HEAT tca 0.3 2"), ["ok"]);
    b.run_for(1.0);
    let st = status(&mut b);
    assert_eq!(
        (num(&st, "p_pla_w"), num(&st, "p_tca_w")),
        (0.0, 0.3),
        "{st}"
    );
    assert!(st.starts_with("ok phase=idle "), "{st}");
    assert_eq!(b.rig.ctrl.heating(), Some(Heater::Tca));
    // MORPH waits for the pulse to end.
    let r = b.send("MORPH 38");
    assert!(
        r[0] == "error: busy a HEAT pulse runs; send ABORT first",
        "{r:?}"
    );
    b.run_for(1.5);
    let st = status(&mut b);
    assert_eq!(
        (num(&st, "p_pla_w"), num(&st, "p_tca_w")),
        (0.0, 0.0),
        "{st}"
    );
    assert_eq!(b.rig.ctrl.heating(), None);
    // ABORT ends one at once.
    assert!(b.send("HEAT pla 1 30")[0] == "ok");
    b.run_for(1.0);
    assert!(b.rig.ctrl.outputs().pla_duty > 0.0);
    assert_eq!(b.send("ABORT"), ["ok"]);
    assert_eq!(b.rig.ctrl.outputs().pla_duty, 0.0);
    b.run_for(1.0);
    assert_eq!(b.rig.ctrl.powers().pla_w, 0.0);
}

#[test]
fn bad_pulses_are_refused_and_change_nothing() {
    let mut b = Bench::new();
    b.run_for(1.0);
    for (line, want) in [
        (
            "HEAT pla 1.5 5",
            "error: out-of-range HEAT power must be above 0 and at most 20 % of the heater's cap (pla 1 W, tca 0.4 W), for more than 0 and at most 60 s.",
        ),
        (
            "HEAT tca 0.5 5",
            "error: out-of-range HEAT power must be above 0 and at most 20 % of the heater's cap (pla 1 W, tca 0.4 W), for more than 0 and at most 60 s.",
        ),
        (
            "HEAT tca 0 5",
            "error: out-of-range HEAT power must be above 0 and at most 20 % of the heater's cap (pla 1 W, tca 0.4 W), for more than 0 and at most 60 s.",
        ),
        (
            "HEAT pla 1 0",
            "error: out-of-range HEAT power must be above 0 and at most 20 % of the heater's cap (pla 1 W, tca 0.4 W), for more than 0 and at most 60 s.",
        ),
        ("HEAT pla 1 61", "error: out-of-range HEAT power must be above 0 and at most 20 % of the heater's cap (pla 1 W, tca 0.4 W), for more than 0 and at most 60 s."),
        ("HEAT amb 1 5", "error: bad-argument HEAT needs a heater"),
        ("HEAT pla", "error: bad-argument HEAT needs"),
        ("HEAT pla 1 5 x", "error: bad-argument HEAT needs"),
        ("HEAT pla x 5", "error: bad-argument HEAT needs"),
    ] {
        let r = b.send(line);
        assert_eq!(r.len(), 1, "{line}: {r:?}");
        assert!(r[0].starts_with(want), "{line}: {r:?}");
        assert_eq!(b.rig.ctrl.heating(), None, "{line}");
    }
    assert_eq!(HEAT_MAX_S, 60.0);
    // Not during a morph.
    assert_eq!(b.send("MORPH 38"), ["ok"]);
    b.run_for(0.5);
    let r = b.send("HEAT pla 1 5");
    assert!(r[0].starts_with("error: busy a morph is in phase"), "{r:?}");
}

#[test]
fn a_dead_heater_under_a_pulse_trips_the_supervisor_and_ends_the_pulse() {
    // Seen by its thermistor on the paper's wiring, by its current (within a tick or two,
    // before the pulse has heated) where the board senses it.
    for (sensing, alarm, within_s) in [
        (false, "alarm: heater-not-heating pla", 30.0),
        (true, "alarm: heater-open pla", 0.5),
    ] {
        let mut b = Bench::new();
        if !sensing {
            b = b.thermistors_only();
        }
        b.run_for(1.0);
        assert!(b.send("SIM FAULT heater-open pla")[0].starts_with("ok"));
        let from = b.lines.len();
        assert!(b.send("HEAT pla 1 60")[0] == "ok");
        assert!(
            b.run_until(within_s, |b| b.rig.ctrl.fault().is_some()),
            "no trip"
        );
        let alarms = b.alarms_since(from);
        assert!(alarms[0].starts_with(alarm), "{alarms:?}");
        assert_eq!(b.rig.ctrl.heating(), None);
        assert_eq!(b.rig.ctrl.outputs().pla_duty, 0.0);
        let r = b.send("HEAT pla 1 5");
        assert!(r[0].starts_with("error: fault-latched"), "{r:?}");
    }
}

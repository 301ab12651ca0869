//! Every safety trip injected in every phase on the simulated link: heaters off in the same tick,
//! latched, and RESET only once the condition has cleared. ABORT from every phase. Every check
//! runs with every morph strategy: the supervisor runs before the sequencer, whatever it asks.
mod common;
use common::Bench;
use morphlink::controller::Outputs;
use morphlink::protocol::{classify, LineKind};
use morphlink::vocab::Phase;

const ZERO: Outputs = Outputs {
    pla_duty: 0.0,
    tca_duty: 0.0,
};
const PHASES: [Phase; 5] = [
    Phase::Idle,
    Phase::Soften,
    Phase::Bend,
    Phase::Lock,
    Phase::Release,
];

/// Every MORPH mode.
const MODES: [&str; 5] = ["auto", "paper", "gated", "boost", "closed"];

/// A bench in `phase` of a morph to `target_mm` in `mode` (Idle: no morph started), a little
/// way in.
fn bench_in(phase: Phase, target_mm: f32, mode: &str) -> Bench {
    let mut b = Bench::new();
    if phase != Phase::Idle {
        assert_eq!(b.send(&format!("MORPH {target_mm} {mode}")), ["ok"]);
        assert!(
            b.run_until(300.0, |b| b.phase() == phase),
            "never reached {phase:?}: {:?}",
            b.lines
        );
        b.run_for(0.5);
        assert_eq!(b.phase(), phase);
    }
    b
}

/// Ticks until an alarm appears (within `max_s`); asserts the tick that raised it output zero
/// duties and returns the alarm line.
fn expect_alarm(b: &mut Bench, code: &str, max_s: f64) -> String {
    let end = b.rig.now_ms() + (max_s * 1000.0) as u64;
    while b.rig.now_ms() < end {
        let (out, ev) = b.tick();
        if let Some(a) = ev.iter().find(|l| classify(l) == LineKind::Alarm) {
            assert!(
                a.starts_with(&format!("alarm: {code} ")),
                "expected {code}, got {a}"
            );
            assert_eq!(
                out, ZERO,
                "the tripping tick must turn both heaters off: {a}"
            );
            assert_eq!(b.rig.ctrl.outputs(), ZERO);
            assert_eq!(b.phase(), Phase::Fault);
            return a.clone();
        }
    }
    panic!("no {code} alarm within {max_s} s; lines: {:?}", b.lines);
}

/// The fault stays latched: heaters stay off, MORPH is refused, STATUS names it.
fn assert_latched(b: &mut Bench, code: &str) {
    for _ in 0..20 {
        assert_eq!(b.tick().0, ZERO);
    }
    let r = b.send("MORPH 38");
    assert!(r[0].starts_with("error: fault-latched"), "{r:?}");
    let s = b.send("STATUS");
    assert_eq!(Bench::field(&s[0], "fault").as_deref(), Some(code), "{s:?}");
    assert_eq!(Bench::field(&s[0], "phase").as_deref(), Some("fault"));
    // ABORT keeps heaters off and does not clear the fault.
    assert_eq!(b.send("ABORT"), ["ok"]);
    assert_eq!(b.phase(), Phase::Fault);
}

/// RESET is refused while the condition holds, accepted once `clear` has removed it.
fn assert_reset_rules(b: &mut Bench, clear: &[&str], settle_s: f64) {
    let r = b.send("RESET");
    assert!(r[0].starts_with("error: fault-active"), "{r:?}");
    assert_eq!(b.phase(), Phase::Fault);
    for c in clear {
        assert!(b.send(c)[0].starts_with("ok"));
    }
    let mut ok = false;
    let end = b.rig.now_ms() + (settle_s * 1000.0) as u64;
    while b.rig.now_ms() < end {
        b.tick();
        let r = b.send("RESET");
        if r[0].starts_with("ok") {
            ok = true;
            break;
        }
        assert!(r[0].starts_with("error: fault-active"), "{r:?}");
    }
    assert!(ok, "RESET never accepted after clearing");
    assert_eq!(b.phase(), Phase::Idle);
}

#[test]
fn thermistor_open_and_short_trip_in_every_phase() {
    for mode in MODES {
        for phase in PHASES {
            for sensor in ["pla", "tca", "amb"] {
                for (kind, code) in [
                    ("thermistor-open", "thermistor-open"),
                    ("thermistor-short", "thermistor-short"),
                ] {
                    let mut b = bench_in(phase, 38.0, mode);
                    assert!(b.send(&format!("SIM FAULT {kind} {sensor}"))[0].starts_with("ok"));
                    let a = expect_alarm(&mut b, code, 1.0);
                    assert!(a.contains(sensor), "{a}");
                    assert_latched(&mut b, code);
                    assert_reset_rules(&mut b, &["SIM CLEAR"], 20.0);
                }
            }
        }
    }
}

#[test]
fn supply_out_of_range_trips_in_every_phase() {
    for mode in MODES {
        for phase in PHASES {
            for volts in ["5", "20"] {
                let mut b = bench_in(phase, 38.0, mode);
                assert!(b.send(&format!("SIM SUPPLY {volts}"))[0].starts_with("ok"));
                expect_alarm(&mut b, "supply-out-of-range", 0.3);
                assert_latched(&mut b, "supply-out-of-range");
                assert_reset_rules(&mut b, &["SIM SUPPLY 12"], 1.0);
            }
        }
    }
}

#[test]
fn stale_sensor_frames_trip_in_every_phase() {
    for mode in MODES {
        for phase in PHASES {
            let mut b = bench_in(phase, 38.0, mode);
            if b.rig.now_ms() < 1500 {
                b.run_for(1.5);
            }
            assert_eq!(b.phase(), phase);
            let now = b.rig.now_ms();
            // A frame sampled 1.5 s ago (the ADC task stalled): the controller must refuse it.
            let old = b.rig.inputs(now - 1500);
            let out = b.rig.ctrl.step(now, &old);
            assert_eq!(out, ZERO);
            assert_eq!(
                b.rig.ctrl.fault().map(|f| f.code.as_str()),
                Some("stale-sensor")
            );
            let mut alarm = None;
            b.rig.drain_events(&mut |l| alarm = Some(l.to_string()));
            assert!(alarm.unwrap().starts_with("alarm: stale-sensor"));
            // Fresh frames flow again (the rig samples at its own clock): RESET succeeds.
            assert_latched(&mut b, "stale-sensor");
            b.tick();
            assert!(b.send("RESET")[0].starts_with("ok"));
        }
    }
}

#[test]
fn a_dead_heater_trips_heater_not_heating_wherever_it_is_on() {
    for mode in MODES {
        // PLA heater: on in soften and bend. TCA: on in bend (and lock) at 1 W (target 35 mm).
        let paper_lock: &[(&str, Phase)] = if mode == "paper" {
            &[("tca", Phase::Lock)]
        } else {
            &[]
        };
        for (heater, phase) in [
            ("pla", Phase::Soften),
            ("pla", Phase::Bend),
            ("tca", Phase::Bend),
        ]
        .into_iter()
        .chain(paper_lock.iter().copied())
        {
            // boost's bend lasts about 2 s, too short for the 10 s heater check: a heater dying
            // there is caught by the next morph (see the next test).
            if mode == "boost" && phase == Phase::Bend {
                continue;
            }
            {
                let mut b = bench_in(phase, 35.0, mode);
                // Injecting at the start of the phase: re-enter it fresh for bend/lock.
                assert!(b.send(&format!("SIM FAULT heater-open {heater}"))[0].starts_with("ok"));
                let a = expect_alarm(&mut b, "heater-not-heating", 60.0);
                assert!(a.contains(heater), "{a}");
                assert_latched(&mut b, "heater-not-heating");
                // Nothing to wait for: the heaters are off; RESET is allowed once sensors are fine.
                assert!(b.send("SIM CLEAR")[0].starts_with("ok"));
                assert!(b.send("RESET")[0].starts_with("ok"));
            }
        }
    }
}

#[test]
fn a_dead_heater_where_it_is_off_or_dies_in_lock_is_caught_by_the_next_morph() {
    for mode in MODES {
        // A TCA that dies during lock cools too slowly to be told from a working one before the lock
        // ends (about 15 s); the PLA is freezing the shape by then, so the morph completes and the
        // next one trips in bend.
        let boost_bend: &[(Phase, &str)] = if mode == "boost" {
            &[(Phase::Bend, "pla"), (Phase::Bend, "tca")]
        } else {
            &[]
        };
        for (phase, heater) in [
            (Phase::Idle, "pla"),
            (Phase::Release, "pla"),
            (Phase::Lock, "tca"),
            (Phase::Idle, "tca"),
        ]
        .into_iter()
        .chain(boost_bend.iter().copied())
        {
            // paper's lock lasts 50 s: a TCA dying there trips in that morph (previous test).
            if mode == "paper" && phase == Phase::Lock {
                continue;
            }
            let mut b = bench_in(phase, 35.0, mode);
            assert!(b.send(&format!("SIM FAULT heater-open {heater}"))[0].starts_with("ok"));
            // paper's lock runs to 120 s after MORPH whatever the temperatures.
            let rest_s = if mode == "paper" { 120.0 } else { 30.0 };
            assert!(
                b.run_until(rest_s, |b| b.rig.ctrl.idle()),
                "{mode} {phase:?} {heater}: {:?}",
                b.lines
            );
            assert_eq!(b.tick().0, ZERO);
            assert_eq!(b.send(&format!("MORPH 35 {mode}")), ["ok"]);
            // paper switches the TCA on only 20 s after MORPH.
            let trip_s = if mode == "paper" { 60.0 } else { 30.0 };
            let a = expect_alarm(&mut b, "heater-not-heating", trip_s);
            assert!(a.contains(heater), "{a}");
        }
    }
}

#[test]
fn a_stuck_heater_trips_over_temperature_in_every_phase() {
    for mode in MODES {
        for phase in PHASES {
            for heater in ["pla", "tca"] {
                let mut b = bench_in(phase, 38.0, mode);
                assert!(b.send(&format!("SIM FAULT heater-stuck {heater}"))[0].starts_with("ok"));
                let a = expect_alarm(&mut b, "over-temperature", 120.0);
                assert!(a.contains(heater), "{a}");
                assert_latched(&mut b, "over-temperature");
                // Still hot: refused. After the MOSFET is replaced (SIM CLEAR) and the link cooled: ok.
                assert_reset_rules(&mut b, &["SIM CLEAR"], 120.0);
            }
        }
    }
}

#[test]
fn freezing_surroundings_trip_under_temperature() {
    for mode in MODES {
        let mut b = bench_in(Phase::Idle, 38.0, mode);
        assert!(b.send("SIM AMBIENT -5")[0].starts_with("ok"));
        expect_alarm(&mut b, "under-temperature", 30.0);
        assert_latched(&mut b, "under-temperature");
        assert_reset_rules(&mut b, &["SIM AMBIENT 22"], 60.0);
    }
}

#[test]
fn a_lock_that_cannot_cool_ends_in_phase_timeout() {
    // paper ends lock on time, not temperature (see the next test for boost: its lock starts
    // before the silicone is warm, so the rod does cool below 45 °C before the bath warms it).
    for mode in ["auto", "gated", "closed"] {
        let mut b = bench_in(Phase::Lock, 38.0, mode);
        // 46 °C water: the PLA can never fall below the 45 °C rigid threshold.
        assert!(b.send("SIM AMBIENT 46")[0].starts_with("ok"));
        let a = expect_alarm(&mut b, "phase-timeout", 700.0);
        assert!(a.contains("lock"), "{a}");
        assert_latched(&mut b, "phase-timeout");
    }
}

#[test]
fn a_morph_in_a_bath_too_warm_to_lock_ends_in_phase_timeout() {
    for mode in ["auto", "gated", "boost", "closed"] {
        let mut b = Bench::new();
        // 46 °C water from the start, the link at its temperature: the PLA can never read rigid.
        assert!(b.send("SIM AMBIENT 46")[0].starts_with("ok"));
        b.run_for(120.0);
        assert_eq!(b.send(&format!("MORPH 38 {mode}")), ["ok"]);
        let a = expect_alarm(&mut b, "phase-timeout", 900.0);
        assert!(a.contains("lock"), "{mode}: {a}");
        assert_latched(&mut b, "phase-timeout");
    }
}

#[test]
fn abort_in_every_phase_turns_both_heaters_off_at_once() {
    for mode in MODES {
        for phase in PHASES {
            let mut b = bench_in(phase, 38.0, mode);
            assert_eq!(b.send("ABORT"), ["ok"]);
            assert_eq!(b.rig.ctrl.outputs(), ZERO, "{phase:?}");
            assert_eq!(b.phase(), Phase::Idle);
            for _ in 0..10 {
                assert_eq!(b.tick().0, ZERO);
            }
            let s = b.send("STATUS");
            assert_eq!(Bench::field(&s[0], "phase").as_deref(), Some("idle"));
            assert_eq!(Bench::field(&s[0], "p_tca_w").as_deref(), Some("0.000"));
            // And a new morph may start.
            assert_eq!(b.send("MORPH 40"), ["ok"]);
        }
    }
}

#[test]
fn a_stalled_controller_cannot_leave_a_heater_on() {
    for phase in [Phase::Soften, Phase::Bend, Phase::Lock] {
        let mut b = bench_in(phase, 35.0, "auto");
        let before = b.rig.applied();
        assert!(
            before.pla_duty > 0.0 || before.tca_duty > 0.0,
            "{phase:?}: a heater is on"
        );
        // The control loop stops: the output stage holds the duties for the watchdog's 1 s
        // (counted from the last step, one tick ago)...
        let held_ticks =
            morphlink::heater::CommandWatchdog::DEFAULT_MAX_AGE_MS / morphlink::controller::TICK_MS;
        for _ in 0..held_ticks - 1 {
            b.rig.stalled_tick();
        }
        assert_eq!(
            b.rig.applied(),
            before,
            "{phase:?}: held within the watchdog's age"
        );
        // ...and then drops both to zero, and the link gets no more heat.
        b.rig.stalled_tick();
        assert_eq!(b.rig.applied(), ZERO, "{phase:?}");
        b.rig.stalled_tick();
        assert_eq!(b.rig.powers_w(), [0.0, 0.0], "{phase:?}");
    }
}

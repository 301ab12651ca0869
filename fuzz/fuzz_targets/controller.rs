//! The controller's two inputs, interleaved: `handle_line` with arbitrary (and nearly valid)
//! lines, `step` with arbitrary ADC counts (and plausible ones) at arbitrary times. Whatever
//! arrives: no panic; duties finite and in [0, 1], both 0 whenever `fault()` is Some; every
//! reply and event line fits an `OutLine`; every command line gets exactly one final reply,
//! last; and whatever CONFIG SET, TUNE and MEASURED did, the calibration keeps TUNE's share
//! rule and its power scale inside its bounds.
#![no_main]

use arbitrary::Arbitrary;
use libfuzzer_sys::fuzz_target;
use morphlink::controller::{Config, Controller, Inputs, Outputs};
use morphlink::electrical::CurrentCounts;

use morphlink::protocol::{classify, parse_line, Command, LineKind, OutLine};

/// Lines the fuzzer can pick by number, so it reaches morphs and faults quickly.
const KNOWN: &[&str] = &[
    "STATUS",
    "ABORT",
    "RESET",
    "VERSION",
    "RANGE",
    "TABLE",
    "HELP",
    "STATS",
    "MORPH",
    "TUNE",
    "SAVE",
    "CONFIG",
    "CONFIG RESET",
    "HEAT pla 1 60",
    "HEAT tca 0.4 30",
    "MEASURED",
];
const MODES: &[&str] = &["", " auto", " paper", " gated", " boost", " closed", " x"];

#[derive(Arbitrary, Debug)]
enum Op {
    /// Any text as a command line.
    Line(String),
    /// A known command word.
    Known(u8),
    /// `MORPH <radius> <mode>`, the radius in 0.01 mm (so the reachable range is often hit).
    Morph { radius_cmm: u16, mode: u8 },
    /// A tick after `dt_ms` with raw counts.
    /// With any current readings (on, off per heater), or none (no current sense).
    Step {
        dt_ms: u16,
        thermistor_counts: [u32; 3],
        supply_counts: u32,
        sample_lag_ms: u16,
        current: Option<([u32; 2], [u32; 2])>,
    },
    /// A tick after `dt_ms` with counts for these temperatures (°C) and supply (dV).
    Plausible {
        dt_ms: u16,
        temps_c: [i8; 3],
        supply_dv: u8,
        ticks: u8,
    },
    /// `CONFIG SET <setting> <value>`, the setting by number, the value in thousandths.
    ConfigSet { setting: u8, value_milli: i32 },
    /// `MEASURED <radius>`, the radius in 0.01 mm.
    Measured { radius_cmm: u16 },
    /// The clock jumps to any time (also backwards).
    Jump(u64),
}

/// The names of every setting, in `CONFIG`'s order.
fn setting_names() -> Vec<&'static str> {
    let mut v = Vec::new();
    morphlink::settings::Settings::DEFAULT.for_each(|spec, _| v.push(spec.name));
    v
}

/// What no command may break: the calibration's rises in line with the model (TUNE's rule,
/// which CONFIG SET is held to) and the table's power scale within its bounds.
fn check_calibration(c: &Controller) {
    let cal = c.calibration();
    assert!(cal.share_rule().is_ok(), "{:?}", cal.share_rule());
    let (lo, hi) = morphlink::calibration::POWER_SCALE_RANGE;
    assert!(
        (lo..=hi).contains(&cal.power_scale()),
        "{}",
        cal.power_scale()
    );
}

fn check_outputs(c: &Controller, o: Outputs) {
    for d in [o.pla_duty, o.tca_duty] {
        assert!(
            d.is_finite() && (0.0..=1.0).contains(&d),
            "duty {d} in {o:?}"
        );
    }
    if c.fault().is_some() {
        assert_eq!((o.pla_duty, o.tca_duty), (0.0, 0.0), "faulted with {o:?}");
        assert!(!o.supply_on, "faulted with the supply connected: {o:?}");
    }
    assert_eq!(c.outputs(), o);
}

fn line(c: &mut Controller, now_ms: u64, text: &str) {
    let mut lines: Vec<String> = Vec::new();
    let sim = c.handle_line(now_ms, text, &mut |l| lines.push(l.to_string()));
    for l in &lines {
        assert!(l.len() <= OutLine::new().capacity(), "{l}");
    }
    let expects_reply = match parse_line(text) {
        Ok(None) => false,
        Ok(Some(Command::Sim(_))) => {
            assert!(sim.is_some());
            false
        }
        _ => true,
    };
    let finals = lines.iter().filter(|l| classify(l).is_final()).count();
    if expects_reply {
        assert_eq!(finals, 1, "`{text}` got {lines:?}");
        assert!(classify(lines.last().unwrap()).is_final(), "{lines:?}");
    } else {
        assert!(lines.is_empty(), "`{text}` got {lines:?}");
    }
    check_outputs(c, c.outputs());
}

fuzz_target!(|ops: Vec<Op>| {
    let cfg = Config::DEFAULT;
    let mut c = Controller::new(cfg);
    let mut now_ms: u64 = 0;
    let names = setting_names();
    for op in ops {
        match op {
            Op::Line(text) => line(&mut c, now_ms, &text),
            Op::Known(i) => line(&mut c, now_ms, KNOWN[i as usize % KNOWN.len()]),
            Op::Morph { radius_cmm, mode } => {
                let m = MODES[mode as usize % MODES.len()];
                let radius_mm = radius_cmm as f32 / 100.0;
                line(&mut c, now_ms, &format!("MORPH {radius_mm}{m}"));
            }
            Op::Step {
                dt_ms,
                thermistor_counts,
                supply_counts,
                sample_lag_ms,
                current,
            } => {
                now_ms = now_ms.wrapping_add(dt_ms as u64);
                let inputs = Inputs {
                    thermistor_counts,
                    supply_counts,
                    sample_ms: now_ms.wrapping_sub(sample_lag_ms as u64),
                    current: current.map(|(on, off)| CurrentCounts { on, off }),
                };
                let o = c.step(now_ms, &inputs);
                check_outputs(&c, o);
            }
            Op::Plausible {
                dt_ms,
                temps_c,
                supply_dv,
                ticks,
            } => {
                let inputs = |now_ms| Inputs {
                    thermistor_counts: temps_c.map(|t| cfg.thermistor.counts_for_temp(t as f32)),
                    supply_counts: cfg.supply.counts(supply_dv as f32 / 10.0),
                    sample_ms: now_ms,
                    current: None,
                };
                for _ in 0..=ticks.min(64) {
                    now_ms = now_ms.wrapping_add(dt_ms as u64);
                    let o = c.step(now_ms, &inputs(now_ms));
                    check_outputs(&c, o);
                }
            }
            Op::ConfigSet {
                setting,
                value_milli,
            } => {
                let name = names[setting as usize % names.len()];
                let v = value_milli as f64 / 1000.0;
                line(&mut c, now_ms, &format!("CONFIG SET {name} {v}"));
            }
            Op::Measured { radius_cmm } => {
                line(
                    &mut c,
                    now_ms,
                    &format!("MEASURED {}", radius_cmm as f32 / 100.0),
                );
            }
            Op::Jump(t) => now_ms = t,
        }
        check_calibration(&c);
        while let Some(l) = c.pop_event_line() {
            assert!(
                matches!(
                    classify(&l),
                    LineKind::Event | LineKind::Done | LineKind::Alarm
                ),
                "{l}"
            );
        }
    }
});

//! The morph strategies on the simulated link: each reaches the nominal targets, the model
//! strategies stay inside the temperature limits over a mismatch ensemble and its worst corners,
//! and `closed` stays accurate where the link differs from its model.
use morphlink::protocol::Mode;
use morphlink::supervisor::{FaultCode, PLA_LIMITS, TCA_LIMITS};
use morphlink::table;
use morphlink_sim::ensemble::{run_morph, Mismatch, Outcome};

/// Targets spread over the reachable range, ends 0.2 mm inside.
fn targets(n: usize) -> Vec<f32> {
    let (min, max) = table::range_mm();
    (0..n)
        .map(|i| (min + 0.2) + (max - min - 0.4) * i as f32 / (n - 1) as f32)
        .collect()
}

#[test]
fn every_thermistor_strategy_reaches_the_nominal_targets_within_two_percent() {
    for mode in [Mode::Auto, Mode::Gated, Mode::Boost, Mode::Closed] {
        for t in targets(5) {
            let r = run_morph(Mismatch::NONE.plant(), t, mode);
            println!(
                "{:>6} {t:.2} mm: {:+.2} % in {:.1} s",
                mode.as_str(),
                r.error_pct,
                r.time_s
            );
            assert_eq!(r.outcome, Outcome::Done, "{mode:?} {t}");
            assert!(r.error_pct.abs() < 2.0, "{mode:?} {t}: {r:?}");
        }
    }
}

/// The corners of the ensemble that heat the most: weak convection (or air), high supply, low
/// heater resistance, warm surroundings, a slow thermistor.
fn hot_corners() -> Vec<Mismatch> {
    let mut v = Vec::new();
    for air in [false, true] {
        for tau in [2.0, 6.0] {
            v.push(Mismatch {
                air,
                h_scale: 0.7,
                ambient_c: 30.0,
                supply_v: 13.2,
                heater_scale: [0.9, 0.9],
                sensor_tau_s: tau,
                sensor_noise_c: 0.2,
                ..Mismatch::NONE
            });
        }
    }
    v
}

#[test]
fn boost_and_closed_never_exceed_the_temperature_limits() {
    let mut links = hot_corners();
    links.extend((0..16).map(|i| Mismatch::draw(99, i)));
    for mode in [Mode::Boost, Mode::Closed] {
        for m in &links {
            for t in targets(3) {
                let r = run_morph(m.plant(), t, mode);
                assert!(
                    r.outcome != Outcome::Fault(FaultCode::OverTemperature),
                    "{mode:?} {t} {m:?}: {r:?}"
                );
                assert!(
                    r.max_true_c[0] < PLA_LIMITS.max_c as f64
                        && r.max_true_c[1] < TCA_LIMITS.max_c as f64,
                    "{mode:?} {t} {m:?}: {r:?}"
                );
            }
        }
    }
}

#[test]
fn closed_stays_within_two_percent_where_the_water_link_differs_from_its_model() {
    for h_scale in [0.7, 1.3] {
        for ambient_c in [15.0, 30.0] {
            for (supply_v, ohm) in [(10.8, 1.1), (13.2, 0.9)] {
                let m = Mismatch {
                    h_scale,
                    ambient_c,
                    supply_v,
                    heater_scale: [ohm, ohm],
                    ..Mismatch::NONE
                };
                // Not the smallest radii: in 30 °C water with weak convection the TCA held that
                // hot keeps the PLA above 45 °C and no strategy can lock (phase-timeout).
                for t in [34.0, 39.6, 46.2] {
                    let r = run_morph(m.plant(), t, Mode::Closed);
                    assert_eq!(r.outcome, Outcome::Done, "{t} {m:?}");
                    assert!(r.error_pct.abs() < 2.0, "{t} {m:?}: {r:?}");
                }
            }
        }
    }
}

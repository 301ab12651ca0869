//! No setting, TUNE or MEASURED can make a link unsafe: the limits hold for the rod and the
//! TCA themselves (their true mean temperatures, from the plant), not only for the beads
//! beside them, on both plants. Each test is a reproduction of a way in which a setting, a
//! tune or a report used to reach past a limit (docs/safety.md, "The parts' limits").

#[macro_use]
mod common;
use common::{Bench, Link};
use morphlink::protocol::{classify, LineKind};
use morphlink::settings::Settings;
use morphlink::supervisor::{PLA_LIMITS, TCA_LIMITS};
use morphlink::tune::TuneStep;

/// The top of a setting's range as `CONFIG` prints it.
fn top(name: &str) -> String {
    let (_, spec) = Settings::DEFAULT.find(name).expect("a setting");
    format!("{:.1}", spec.max - 0.04)
}

/// `link` in water, or in still air (`SIM MEDIUM air`).
fn bench(link: Link, air: bool) -> Bench {
    let mut b = Bench::on(link);
    if air {
        assert!(b.send("SIM MEDIUM air")[0].starts_with("ok"));
    }
    b.run_for(2.0);
    b
}

/// Sends `lines`, asserting each is accepted.
fn set(b: &mut Bench, lines: &[&str]) {
    for l in lines {
        let r = b.send(l);
        assert!(r[0].starts_with("ok"), "{l}: {r:?}");
    }
}

/// Runs a morph to its end; returns the true peaks (rod, TCA), °C, and its alarms.
fn morph(b: &mut Bench, radius_mm: f32, mode: &str) -> ([f64; 2], Vec<String>) {
    let from = b.lines.len();
    let (_, peaks) = b.morph_peaks(radius_mm, mode);
    (peaks, b.alarms_since(from))
}

fn assert_under_limits(what: &str, peaks: [f64; 2]) {
    assert!(
        peaks[0] < PLA_LIMITS.max_c as f64 && peaks[1] < TCA_LIMITS.max_c as f64,
        "{what}: true rod {:.1} °C, TCA {:.1} °C",
        peaks[0],
        peaks[1]
    );
}

/// The hottest corners of the settings that steer a heater (the PLA target at its top, the
/// model's convection at either end) keep the true rod and TCA under their limits in every
/// strategy, in water and in still air, with no alarm but a phase timeout (a strategy that
/// cannot get there in still air). Before: a 110 °C PLA target took the hifi rod to 138 °C,
/// with 200 W/(m² K) to 151 °C; gated in still air took it to 131–139 °C at the defaults.
fn the_hottest_settings_keep_the_true_parts_under_their_limits(link: Link) {
    let target = format!("CONFIG SET pla_soft_target_c {}", top("pla_soft_target_c"));
    for air in [false, true] {
        for corner in [
            vec![target.clone()],
            vec![
                target.clone(),
                "CONFIG SET convection_w_m2k 200".to_string(),
            ],
        ] {
            for (mode, r) in [("closed", 33.0), ("closed", 38.0), ("gated", 33.0)] {
                let mut b = bench(link, air);
                let lines: Vec<&str> = corner.iter().map(String::as_str).collect();
                set(&mut b, &lines);
                let (peaks, alarms) = morph(&mut b, r, mode);
                let what = format!("{link:?} air={air} {corner:?} {mode} {r}");
                assert_under_limits(&what, peaks);
                assert!(
                    alarms.iter().all(|a| a.starts_with("alarm: phase-timeout")),
                    "{what}: {alarms:?}"
                );
            }
        }
    }
}

/// Eight believable MEASURED reports that each say the link came out looser than `done` said
/// (33 mm morphs reported as 36 mm) cannot walk the TCA's aim past what its ceiling allows:
/// the morph after them keeps the true TCA under its limit in still air. Before: the aim reached the 110 °C cap and the still-air TCA sat at
/// 120–126 °C.
fn measured_reports_cannot_walk_the_tca_past_its_limit(link: Link) {
    let mut b = bench(link, true);
    let mut tripped = false;
    for _ in 0..8 {
        let (_, alarms) = morph(&mut b, 33.0, "closed");
        if !alarms.is_empty() {
            tripped = true;
            break;
        }
        let r = b.send("MEASURED 36");
        assert!(
            r[0].starts_with("ok") || r[0].starts_with("error: out-of-range"),
            "{r:?}"
        );
    }
    b.run_for(300.0);
    if tripped {
        let r = b.send("RESET");
        assert!(r[0].starts_with("ok"), "{r:?}");
    }
    let (peaks, alarms) = morph(&mut b, 33.0, "closed");
    assert_under_limits(&format!("{link:?} after eight reports"), peaks);
    assert!(
        alarms.iter().all(|a| a.starts_with("alarm: phase-timeout")),
        "{alarms:?}"
    );
}

/// A report after a `paper` morph that would scale the table past the TCA heater's cap is
/// refused (`MORPH 33 paper`, `MEASURED 37.7` set a power scale of 1.808), and the next
/// paper morph in still air keeps the true TCA under its limit (it reached 130.3 °C).
fn a_power_report_cannot_scale_the_table_past_the_heater_cap(link: Link) {
    let mut b = bench(link, true);
    let (_, alarms) = morph(&mut b, 33.0, "paper");
    assert!(alarms.is_empty(), "{alarms:?}");
    let r = b.send("MEASURED 37.7");
    assert!(r[0].starts_with("error: out-of-range"), "{r:?}");
    assert!(r[0].contains("power"), "{r:?}");
    b.run_for(300.0);
    let (peaks, alarms) = morph(&mut b, 33.0, "paper");
    assert_under_limits(&format!("{link:?} paper after the report"), peaks);
    assert!(alarms.is_empty(), "{alarms:?}");
}

/// A tune with the bath stepping 8 K mid-tune (`SIM AMBIENT`) fails, naming the ambient, and
/// changes nothing: the step read as heater rise gave a wrong model with `done`.
fn a_tune_in_a_moving_bath_fails_and_changes_nothing(link: Link) {
    let mut b = bench(link, false);
    let before = b.rig.ctrl.calibration();
    assert!(b.send("TUNE")[0].starts_with("ok"));
    b.run_for(60.0);
    assert!(b.send("SIM AMBIENT 30")[0].starts_with("ok"));
    assert!(b.run_until(200.0, |b| !b.rig.ctrl.tuning()));
    let failed = b
        .lines
        .iter()
        .find(|l| l.starts_with("event: tune failed"))
        .cloned()
        .unwrap_or_else(|| panic!("{:?}", b.lines));
    assert!(failed.contains("ambient moved"), "{failed}");
    assert!(!b.lines.iter().any(|l| l.starts_with("event: tune done")));
    assert_eq!(b.rig.ctrl.calibration(), before);
}

/// A PLA heater stuck on through the PLA step (a MOSFET failed short) ends the tune without
/// `done` and with the calibration as it was, and SAVE is refused while its fault is latched:
/// the wrong fit used to end `done` with the still-air model, alarm afterwards, and SAVE kept
/// it.
fn a_tune_with_a_stuck_heater_changes_nothing_and_cannot_be_saved(link: Link) {
    let mut b = bench(link, false);
    b.rig.boot_storage(None);
    let before = b.rig.ctrl.calibration();
    assert!(b.send("TUNE")[0].starts_with("ok"));
    assert!(b.run_to_tune_step(TuneStep::Pla));
    assert!(b.send("SIM FAULT heater-stuck pla")[0].starts_with("ok"));
    assert!(b.run_until(200.0, |b| !b.rig.ctrl.tuning()));
    b.run_for(30.0);
    assert!(
        !b.lines.iter().any(|l| l.starts_with("event: tune done")),
        "{:?}",
        b.lines
    );
    assert_eq!(b.rig.ctrl.calibration(), before);
    let fault_seen = b.lines.iter().any(|l| classify(l) == LineKind::Alarm);
    if fault_seen {
        let r = b.send("SAVE");
        assert!(r[0].starts_with("error: fault-latched"), "{r:?}");
    }
    assert!(
        fault_seen
            || b.lines
                .iter()
                .any(|l| l.starts_with("event: tune failed pla reached its cap")),
        "{:?}",
        b.lines
    );
}

/// A report for a morph made before a TUNE or a CONFIG RESET no longer describes the link:
/// refused, saying why.
fn a_report_for_a_morph_under_an_older_calibration_is_refused(link: Link) {
    let mut b = bench(link, false);
    let (_, alarms) = morph(&mut b, 38.0, "closed");
    assert!(alarms.is_empty(), "{alarms:?}");
    assert!(b.send("CONFIG RESET")[0].starts_with("ok"));
    let r = b.send("MEASURED 38.5");
    assert!(
        r[0].starts_with("error: no-finished-morph") && r[0].contains("calibration"),
        "{r:?}"
    );
}

on_both_links!(
    the_hottest_settings_keep_the_true_parts_under_their_limits,
    measured_reports_cannot_walk_the_tca_past_its_limit,
    a_power_report_cannot_scale_the_table_past_the_heater_cap,
    a_tune_in_a_moving_bath_fails_and_changes_nothing,
    a_tune_with_a_stuck_heater_changes_nothing_and_cannot_be_saved,
    a_report_for_a_morph_under_an_older_calibration_is_refused,
);

/// Every end of every range `CONFIG` prints is accepted by `CONFIG SET` (ranges are rounded
/// inwards): `pla_rise_k_per_w`'s printed ends were refused.
#[test]
fn every_printed_range_end_is_accepted() {
    let mut b = Bench::new();
    b.run_for(1.0);
    let rows: Vec<String> = b
        .send("CONFIG")
        .into_iter()
        .filter(|l| l.contains(" range="))
        .collect();
    assert!(rows.len() > 10, "{rows:?}");
    for row in rows {
        let body = row.strip_prefix("data: ").unwrap();
        let name = body.split('=').next().unwrap();
        let range = Bench::field(body, "range").unwrap();
        let (lo, hi) = range.split_once("..").unwrap();
        for v in [lo, hi] {
            let r = b.send(&format!("CONFIG SET {name} {v}"));
            assert!(r[0].starts_with("ok"), "{name} {v}: {r:?}");
            assert!(b.send("CONFIG RESET")[0].starts_with("ok"));
        }
    }
}

/// CONFIG SET of the model's convection is held to TUNE's rule: one that puts a rise at
/// 0.28× the model's (10 W/(m² K) with water's rises) is refused, naming the range the live
/// rises allow, and changes nothing; CONFIG prints that range.
#[test]
fn config_set_holds_the_calibration_to_tunes_rule() {
    let mut b = Bench::new();
    let before = b.rig.ctrl.calibration();
    let r = b.send("CONFIG SET convection_w_m2k 10");
    let range = "10.714..200.000";
    assert!(
        r[0].starts_with("error: out-of-range convection_w_m2k=10.000") && r[0].contains(range),
        "{r:?}"
    );
    assert_eq!(b.rig.ctrl.calibration(), before);
    let row = b.send("CONFIG");
    assert!(
        row.iter()
            .any(|l| l.contains("convection_w_m2k=") && l.contains(&format!("range={range}"))),
        "{row:?}"
    );
}

/// STATUS shows the PLA target the morph runs with, not the compiled-in one.
#[test]
fn status_reports_the_live_pla_target() {
    let mut b = Bench::new();
    b.run_for(1.0);
    set(&mut b, &["CONFIG SET pla_soft_target_c 80"]);
    assert_eq!(b.send("MORPH 38 closed"), ["ok"]);
    b.run_for(2.0);
    let s = b.send("STATUS");
    assert_eq!(
        Bench::field(&s[0], "pla_target_c").as_deref(),
        Some("80.00"),
        "{s:?}"
    );
}

/// HEAT's minute is per heater over a window, not per command: a second minute straight
/// after the first is refused, saying what is left (twelve chained minutes softened a
/// still-air rod); MEASURED is refused while a pulse runs, as CONFIG SET is.
#[test]
fn chained_heat_pulses_are_bounded_over_a_window() {
    let mut b = Bench::new();
    b.run_for(1.0);
    assert_eq!(b.send("HEAT pla 1 60"), ["ok"]);
    assert!(b.send("MEASURED 38")[0].starts_with("error: busy"));
    b.run_for(61.0);
    let r = b.send("HEAT pla 1 60");
    assert!(r[0].starts_with("error: busy pla has "), "{r:?}");
    assert_eq!(b.send("HEAT tca 0.4 10"), ["ok"]);
}

/// A tune that trips prints its alarm first, then `tune failed safety trip (see the alarm)`.
#[test]
fn a_tripped_tune_reports_its_alarm_first() {
    let mut b = Bench::new();
    b.run_for(1.0);
    assert!(b.send("TUNE")[0].starts_with("ok"));
    b.run_for(10.0);
    assert!(b.send("SIM FAULT thermistor-open tca")[0].starts_with("ok"));
    b.run_for(5.0);
    let alarm = b.lines.iter().position(|l| classify(l) == LineKind::Alarm);
    let failed = b
        .lines
        .iter()
        .position(|l| l.starts_with("event: tune failed safety trip"));
    assert!(
        matches!((alarm, failed), (Some(a), Some(f)) if a < f),
        "{:?}",
        b.lines
    );
}

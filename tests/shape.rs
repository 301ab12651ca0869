//! The link's shape read from the TCA at rest (docs/shape.md), on both plants: after the link
//! as built and one measured morph, the next morph's rest reads its radius within its stated
//! uncertainty where the TCA's resistance carries its strain (hifi), and says it has no shape
//! where it does not (lumped), never a wrong one; a MEASURED that contradicts a reading is
//! refused with both figures; STATUS carries the reading; a board without current sense says
//! so; no alarm on the way.
#[macro_use]
mod common;
use common::{Bench, Link};
use morphlink::controller::{Config, Controller};
use morphlink_sim::rig::SimFlash;

on_both_links!(
    after_one_measured_morph_the_next_rest_reads_the_radius_or_says_why_not,
    a_board_without_current_sense_says_it_has_no_shape_after_a_morph,
);

/// The number after `key=` in `line`.
fn number(line: &str, key: &str) -> f64 {
    Bench::field(line, key)
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no {key} in {line}"))
}

fn after_one_measured_morph_the_next_rest_reads_the_radius_or_says_why_not(link: Link) {
    let mut b = Bench::on(link);
    // As built: the rest is the anchor, and nobody asked for its shape.
    assert!(b.run_until(120.0, |b| b.rig.ctrl.rest_shape().anchor().is_some()));
    assert!(!b.lines.iter().any(|l| l.starts_with("event: shape")));
    b.morph(34.8, "auto");
    b.run_for(60.0);
    let measured = format!("MEASURED {:.2}", b.rig.radius_mm());
    assert!(b.send(&measured)[0].starts_with("ok "));
    // One known shape besides the as-built one teaches the gauge; this rest has none yet.
    assert_eq!(
        b.rest_until_shape(1300.0),
        "event: shape none reason=no-gauge"
    );
    assert!(b.rig.ctrl.calibration().gauge().is_some());
    let from = b.lines.len();
    b.morph(42.0, "auto");
    let line = b.rest_until_shape(1300.0);
    let truth_mm = b.rig.radius_mm();
    println!("{link:?}: {line} (truth {truth_mm:.2} mm)");
    match link {
        Link::Hifi => {
            let (mm, sigma) = (number(&line, "radius_mm"), number(&line, "sigma_mm"));
            assert!(
                (mm - truth_mm).abs() <= 3.0 * sigma,
                "{line}: truth {truth_mm}"
            );
            assert!(sigma < 0.05 * mm, "{line}");
            // Agreeing with the estimate, it was folded in as a MEASURED would be. A caliper's
            // MEASURED that contradicts it by more than both uncertainties is refused with both
            // figures, changing nothing; one that agrees still counts.
            assert_eq!(Bench::field(&line, "learnt").as_deref(), Some("1"));
            let status = b.send("STATUS")[0].clone();
            assert_eq!(
                Bench::field(&status, "shape_mm"),
                Bench::field(&line, "radius_mm")
            );
            assert_eq!(
                Bench::field(&status, "shape_sigma_mm"),
                Bench::field(&line, "sigma_mm")
            );
            let cal = b.rig.ctrl.calibration();
            let wrong = format!("MEASURED {:.2}", truth_mm * 1.12);
            let reply = b.send(&wrong);
            assert!(
                reply[0].starts_with("error: out-of-range measured ")
                    && reply[0].contains(&format!(
                        "contradicts the rest-shape reading {mm:.2} ± {sigma:.2} mm"
                    )),
                "{reply:?}"
            );
            assert_eq!(b.rig.ctrl.calibration(), cal);
            let measured = format!("MEASURED {truth_mm:.2}");
            assert!(
                b.send(&measured)[0].starts_with("ok "),
                "{:?}",
                b.lines.last()
            );
        }
        // Its TCA's resistance follows its temperature alone: no shape, not a wrong one.
        Link::Lumped => assert_eq!(line, "event: shape none reason=weak-gauge"),
    }
    assert_eq!(b.alarms_since(from), Vec::<String>::new());
}

fn a_board_without_current_sense_says_it_has_no_shape_after_a_morph(link: Link) {
    let mut b = Bench::on(link).thermistors_only();
    b.run_for(60.0);
    assert!(!b.lines.iter().any(|l| l.starts_with("event: shape")));
    b.morph(40.0, "auto");
    assert_eq!(
        b.rest_until_shape(5.0),
        "event: shape none reason=no-current-sense"
    );
}

/// `MEASURED` the link's true radius now, as a user with a caliper would, a minute after `done`.
fn measure(b: &mut Bench) -> f64 {
    b.run_for(60.0);
    let truth_mm = b.rig.radius_mm();
    let r = b.send(&format!("MEASURED {truth_mm:.2}"));
    assert!(r[0].starts_with("ok "), "{r:?}");
    truth_mm
}

/// SAVE keeps the gauge (the calibration's `tca_strain_k_m` and `tca_strain_sd_share`): after a
/// reset with the link left bent, its first rest is not taken as built, the next morph's rest
/// says `no-anchor` rather than a shape read against a wrong anchor, and once that morph is
/// measured the one after it reads its radius within three sigmas: one caliper after a reset,
/// not two (hifi: its TCA carries a strain term).
#[test]
fn a_saved_gauge_reads_again_after_a_reset_once_one_measured_morph_anchors_it() {
    let mut b = Bench::on(Link::Hifi);
    b.rig.boot_storage(Some(SimFlash::new()));
    assert!(b.run_until(120.0, |b| b.rig.ctrl.rest_shape().anchor().is_some()));
    b.morph(34.8, "auto");
    measure(&mut b);
    assert_eq!(
        b.rest_until_shape(1300.0),
        "event: shape none reason=no-gauge"
    );
    let gauge = b.rig.ctrl.calibration().gauge().expect("a gauge learnt");
    assert!(b.send("SAVE")[0].starts_with("ok saved"));
    // Left bent at 42 mm, the board resets: a new controller on the same link, the settings
    // from flash.
    b.morph(42.0, "auto");
    let flash = b.rig.flash().cloned();
    b.rig.ctrl = Controller::new(Config::DEFAULT);
    b.rig.boot_storage(flash);
    let g = b.rig.ctrl.calibration().gauge().expect("the gauge saved");
    assert!((g.0 / gauge.0 - 1.0).abs() < 1e-6 && (g.1 / gauge.1 - 1.0).abs() < 1e-3);
    let from = b.lines.len();
    b.run_for(400.0);
    assert!(b.rig.ctrl.rest_shape().anchor().is_none());
    b.morph(38.0, "auto");
    assert_eq!(
        b.rest_until_shape(1300.0),
        "event: shape none reason=no-anchor"
    );
    measure(&mut b);
    assert!(b.rig.ctrl.rest_shape().anchor().is_some());
    b.morph(45.0, "auto");
    let line = b.rest_until_shape(1300.0);
    let truth_mm = b.rig.radius_mm();
    let (mm, sigma) = (number(&line, "radius_mm"), number(&line, "sigma_mm"));
    println!("after a reset: {line} (truth {truth_mm:.2} mm)");
    assert!(
        (mm - truth_mm).abs() <= 3.0 * sigma,
        "{line}: truth {truth_mm}"
    );
    assert_eq!(b.alarms_since(from), Vec::<String>::new());
}

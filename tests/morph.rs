//! Whole morphs on the simulated link with nominal parameters: the lumped link (the controller's
//! own equations) held to the controller's accuracy, the hifi link (different physics) measured.
mod common;
use common::Bench;
use morphlink::protocol::{classify, LineKind};
use morphlink::supervisor::{PLA_LIMITS, TCA_LIMITS};
use morphlink::table;
use morphlink::vocab::Phase;

/// Targets spread over the reachable range, ends included (0.2 mm inside).
fn targets() -> Vec<f32> {
    let (min, max) = table::range_mm();
    (0..7)
        .map(|i| (min + 0.2) + (max - min - 0.4) * i as f32 / 6.0)
        .collect()
}

/// After a morph to `target` that ended: asserts its phases came in order, lets the TCA cool
/// fully (spring-back included, 60 s) and returns the `done` event's radius estimate, the
/// final true radius (mm) and its error (%).
fn phases_then_settle(b: &mut Bench, target: f32) -> (f32, f32, f32) {
    assert_eq!(
        b.phases(),
        ["soften", "bend", "lock", "release"],
        "target {target}"
    );
    let done = b
        .lines
        .iter()
        .find(|l| classify(l) == LineKind::Done)
        .expect("done event");
    let estimate: f32 = Bench::field(done, "radius_mm").unwrap().parse().unwrap();
    b.run_for(60.0);
    let r = b.rig.radius_mm() as f32;
    (estimate, r, (r - target) / target * 100.0)
}

#[test]
fn auto_morphs_reach_every_target_within_two_percent_with_phases_in_order() {
    for target in targets() {
        let mut b = Bench::new();
        let t = b.morph(target, "auto");
        let (estimate, r, err) = phases_then_settle(&mut b, target);
        println!("target {target:.2} mm: final {r:.2} mm ({err:+.2} %), estimate {estimate:.2} mm, {t:.1} s");
        assert!(
            err.abs() < 2.0,
            "target {target} mm ended at {r} mm ({err:+.2} %)"
        );
        assert!(
            (estimate - r).abs() / r < 0.03,
            "estimate {estimate} vs {r}"
        );
    }
}

#[test]
fn paper_mode_takes_the_papers_time_and_reaches_the_target() {
    let mut b = Bench::new();
    let target = 38.0;
    let t = b.morph(target, "paper");
    assert!((t - 122.0).abs() < 0.5, "paper morph took {t} s");
    assert_eq!(b.phases(), ["soften", "bend", "lock", "release"]);
    b.run_for(60.0);
    let r = b.rig.radius_mm() as f32;
    println!("paper mode: {r:.2} mm for {target} mm");
    // The paper's protocol drops the PLA heat without compensating the TCA: it lands farther.
    assert!(
        (r - target).abs() / target < 0.05,
        "paper mode ended at {r} mm"
    );
}

#[test]
fn a_second_morph_starts_from_the_first_ones_shape() {
    let mut b = Bench::new();
    let (min, max) = table::range_mm();
    for target in [min + 1.0, max - 1.0, (min + max) / 2.0] {
        b.morph(target, "auto");
        b.run_for(60.0);
        let r = b.rig.radius_mm() as f32;
        assert!((r - target).abs() / target < 0.02, "target {target}: {r}");
    }
}

#[test]
fn morph_while_busy_or_out_of_range_is_refused_and_changes_nothing() {
    let mut b = Bench::new();
    let (min, max) = table::range_mm();
    let r = b.send(&format!("MORPH {}", max + 5.0));
    assert_eq!(r.len(), 1);
    assert!(r[0].starts_with("error: out-of-range reachable="), "{r:?}");
    // The ends rounded inward, so that each printed end is taken.
    let (lo, hi) = (
        morphlink::fixed::Fixed::up2(min),
        morphlink::fixed::Fixed::down2(max),
    );
    assert!(r[0].contains(&format!("{lo}..{hi}")), "{r:?}");
    assert!(b.rig.ctrl.idle());
    assert_eq!(b.send("MORPH 38"), ["ok"]);
    b.run_for(1.0);
    let r = b.send("MORPH 40");
    assert!(r[0].starts_with("error: busy"), "{r:?}");
    let status = b.send("STATUS");
    assert_eq!(
        Bench::field(&status[0], "target_mm").as_deref(),
        Some("38.00")
    );
}

/// The accuracy the project claims for an uncalibrated `closed` (`auto`) morph on a link it was
/// not built from, %: the hifi ensemble's water p95 |error| (docs/strategies.md, "High-fidelity
/// plant"), rounded up. The nominal hifi link is one of those links, so each of its morphs
/// lands inside it; a regression past the ensemble's claim fails, and a better controller keeps
/// it. The calibrated claim (2 % after TUNE and measured morphs) is held by
/// `tests/tune.rs` (`measured_morphs_reduce_the_error_on_a_mismatched_link`, both plants).
const UNCALIBRATED_HIFI_ERROR_PCT: f32 = 11.0;

#[test]
fn auto_morphs_on_the_hifi_link_end_within_the_limits_and_their_error_is_measured() {
    for target in targets() {
        let mut b = Bench::hifi();
        let (t, peak_c) = b.morph_peaks(target, "auto");
        // Nothing runs away, whatever the outcome.
        assert!(
            peak_c[0] < PLA_LIMITS.max_c as f64 && peak_c[1] < TCA_LIMITS.max_c as f64,
            "target {target}: peaks {peak_c:?} °C"
        );
        // The wrap heated the rod through its transition.
        assert!(peak_c[0] > 60.0, "target {target}: peaks {peak_c:?} °C");
        // No false alarm: supervisor v2's heater check follows the hifi link's lagging beads
        // (before it, every target below 36 mm tripped heater-not-heating on the TCA at 10.2 s).
        assert!(
            b.alarms_since(0).is_empty(),
            "target {target}: {:?}",
            b.lines
        );
        let (estimate, r, err) = phases_then_settle(&mut b, target);
        println!(
            "hifi target {target:.2} mm: final {r:.2} mm ({err:+.2} %), estimate {estimate:.2} mm, \
             {t:.1} s, peaks {:.1} / {:.1} °C",
            peak_c[0], peak_c[1]
        );
        assert!(
            err.abs() < UNCALIBRATED_HIFI_ERROR_PCT,
            "target {target} mm ended at {r} mm ({err:+.2} %)"
        );
    }
}

/// How fast the true radius moves, mm/s, over the last second of bend of a `closed` morph to
/// `target_mm` on `b` (ticked until lock begins).
fn flow_when_bend_ends_mm_s(b: &mut Bench, target_mm: f32) -> f64 {
    assert_eq!(b.send(&format!("MORPH {target_mm} closed")), ["ok"]);
    assert!(b.run_until(300.0, |b| b.phase() != Phase::Soften));
    // The true radius a second apart through bend: the last pair within a second of lock.
    let mut last = (b.rig.radius_mm(), b.rig.radius_mm());
    let mut ticks = 0;
    while b.phase() == Phase::Bend {
        b.tick();
        ticks += 1;
        if ticks % 10 == 0 {
            last = (last.1, b.rig.radius_mm());
        }
    }
    assert_eq!(b.phase(), Phase::Lock, "{:?}", b.lines);
    (last.1 - last.0).abs()
}

/// `closed` ends bend on the hifi links only once the rod has all but stopped flowing: bend
/// waits for the PLA thermistor to slow under `CLOSED_PLA_SETTLED_K_PER_S`. With the observer's
/// own 0.6 K/s the rod on these drawn links (the calibration chart's, compiled-in calibration)
/// was still moving 0.04–0.08 mm/s when bend ended; now under 0.02 mm/s.
#[test]
fn on_drawn_hifi_links_closed_bend_ends_once_the_rod_has_stopped_flowing() {
    for draw in [15, 30, 11] {
        let target = 42.92f32;
        let rate = flow_when_bend_ends_mm_s(&mut Bench::hifi_draw(20261122, draw), target);
        println!("hifi draw {draw} {target:.2} mm: radius moving {rate:.3} mm/s when bend ended");
        assert!(
            rate < 0.02,
            "draw {draw}: bend ended with the rod moving {rate:.3} mm/s"
        );
    }
}

/// The same after `TUNE`, where the observer's PLA estimate agrees with its thermistor: an
/// agreement counts only if the observer has not lowered its estimate by more than the
/// agreement band within the last few seconds (`CLOSED_PLA_AGREE_K`, `CLOSED_PLA_CORRECTED_S`).
/// These draws' beads lag their rods by some 10 s; the observer caught up with them late in
/// bend, its heater then heated the rod further, and bend ended on the fresh agreement with the
/// rod flowing 0.9–1.7 mm/s (draw 15 ended 9 % loose; docs/calibration.md). Now under
/// 0.25 mm/s.
#[test]
fn after_tune_on_drawn_hifi_links_closed_bend_ends_once_the_rod_has_stopped_flowing() {
    for draw in [15, 5, 12] {
        let target = 42.92f32;
        // TUNE on the link, then the morph on a copy of it at rest with what TUNE learnt.
        let mut tuned = Bench::hifi_draw(20261122, draw);
        let end = tuned.tune_to_end();
        assert!(end.starts_with("event: tune done"), "draw {draw}: {end}");
        let cal = tuned.rig.ctrl.calibration();
        let mut b = Bench::hifi_draw(20261122, draw);
        b.rig
            .ctrl
            .set_calibration(cal)
            .expect("TUNE's own calibration");
        let rate = flow_when_bend_ends_mm_s(&mut b, target);
        println!("hifi draw {draw} {target:.2} mm after TUNE: radius moving {rate:.3} mm/s when bend ended");
        assert!(
            rate < 0.25,
            "draw {draw}: bend ended with the rod moving {rate:.3} mm/s"
        );
    }
}

/// Still air, 34 mm: the TCA's hold keeps the rod above the 50 °C lock temperature, and `auto`
/// used to hold the TCA on for ten minutes, then time out. It now ends lock once the PLA has
/// stalled cool enough for the shape to hold (`CLOSED_LOCK_STALL_MAX_C`): on the lumped link
/// within 2 % (the controller's own equations), on the hifi link within its known tight bias
/// (README: −8 % at 38 mm in water), with no creep over the next ten minutes.
#[test]
fn auto_morphs_to_34_mm_in_still_air_on_both_links() {
    for (name, mut b, max_err_pct) in [("lumped", Bench::new(), 2.0), ("hifi", Bench::hifi(), 10.0)]
    {
        assert!(b.send("SIM MEDIUM air")[0].starts_with("ok"), "{name}");
        let t = b.morph(34.0, "auto");
        assert!(b.alarms().is_empty(), "{name}: {:?}", b.alarms());
        let (estimate, r, err) = phases_then_settle(&mut b, 34.0);
        println!("{name}: 34 mm in still air: {t:.0} s, final {r:.2} mm ({err:+.2} %), estimate {estimate:.2}");
        assert!(t < 300.0, "{name}: {t} s");
        assert!(err.abs() < max_err_pct, "{name}: {r} mm ({err:+.2} %)");
        // Released warm, the rod cools on: the shape must not creep later (the hifi rod is
        // viscoelastic). 600 s after `done` it is where it was at 60 s.
        b.run_for(540.0);
        let later = b.rig.radius_mm() as f32;
        assert!(
            (later - r).abs() < 0.05,
            "{name}: {r} mm at 60 s, {later} mm at 600 s"
        );
        assert_eq!(b.rig.ctrl.powers().pla_w + b.rig.ctrl.powers().tca_w, 0.0);
    }
}

/// The lumped link in still air at 27 °C, `lines` sent, settled there for 25 minutes: the
/// TCA holding 32.92 mm keeps its PLA over the 58 °C it must cool under.
fn in_still_air_at_27(lines: &[&str]) -> Bench {
    let mut b = Bench::new();
    for l in ["SIM MEDIUM air", "SIM AMBIENT 27"].iter().chain(lines) {
        assert!(b.send(l)[0].starts_with("ok"), "{l}");
    }
    b.run_for(1500.0);
    b
}

/// How a lock went: the TCA's target when lock began and the lowest it was held at, °C (as
/// STATUS prints them), lock's length, s, and the lines from MORPH on.
struct Lock {
    held_c: f32,
    lowest_c: f32,
    lock_s: f64,
    lines: Vec<String>,
}

/// Runs `MORPH radius_mm auto` on `b` to its end, reading the TCA's target every tick of lock.
fn lock_of(b: &mut Bench, radius_mm: f32) -> Lock {
    let target_c = |b: &mut Bench| -> f32 {
        let s = b.send("STATUS");
        Bench::field(&s[0], "tca_target_c").map_or(f32::NAN, |v| v.parse().unwrap_or(f32::NAN))
    };
    let from = b.lines.len();
    assert_eq!(b.send(&format!("MORPH {radius_mm} auto")), ["ok"]);
    assert!(b.run_until(300.0, |b| b.phase() == Phase::Lock));
    let (held_c, t0) = (target_c(b), b.rig.now_ms());
    let mut lowest_c = held_c;
    while b.phase() == Phase::Lock {
        lowest_c = lowest_c.min(target_c(b));
        b.tick();
    }
    let lock_s = (b.rig.now_ms() - t0) as f64 / 1000.0;
    assert!(b.run_until(60.0, |b| !b.rig.ctrl.busy()));
    Lock {
        held_c,
        lowest_c,
        lock_s,
        lines: b.lines[from..].to_vec(),
    }
}

/// Holds that `lines` hold exactly one alarm, the lock's too-warm one, and the heaters are off.
fn ended_too_warm(b: &Bench, lines: &[String]) {
    let alarms: Vec<_> = lines.iter().filter(|l| l.starts_with("alarm:")).collect();
    assert_eq!(alarms.len(), 1, "{lines:?}");
    assert!(
        alarms[0].starts_with("alarm: phase-timeout phase lock did not finish: pla stays at ")
            && alarms[0]
                .contains("too warm to hold this radius here; morph larger or cool the link"),
        "{alarms:?}"
    );
    assert_eq!(b.rig.ctrl.powers().pla_w + b.rig.ctrl.powers().tca_w, 0.0);
}

/// A lock whose PLA the TCA's own heat keeps too warm to turn rigid (still air at 27 °C: the
/// TCA holding 32.92 mm keeps the PLA over the 58 °C the rod must cool under to hold the shape)
/// eases the TCA's hold, by at most `CLOSED_LOCK_EASE_MAX_K` in all, until the PLA cools, and
/// the morph ends `done` near its target with no alarm.
#[test]
fn a_lock_the_tcas_heat_keeps_too_warm_eases_its_hold_and_finishes() {
    use morphlink::strategy::closed::CLOSED_LOCK_EASE_MAX_K;
    let mut b = in_still_air_at_27(&[]);
    let lock = lock_of(&mut b, 32.92);
    assert!(
        !lock.lines.iter().any(|l| l.starts_with("alarm:"))
            && lock.lines.iter().any(|l| l.starts_with("event: done")),
        "{:?}",
        lock.lines
    );
    let eased_k = lock.held_c - lock.lowest_c;
    // STATUS prints the target to 0.01 K.
    assert!(
        eased_k > 0.0 && eased_k <= CLOSED_LOCK_EASE_MAX_K + 0.02,
        "eased {eased_k} K"
    );
    b.run_for(60.0);
    let radius_mm = b.rig.plant().sample().radius_mm;
    assert!((radius_mm - 32.92).abs() < 0.03 * 32.92, "{radius_mm} mm");
}

/// A lock that no easing lets finish (the hifi link of draw 1 in 30 °C still air, whose PLA
/// bead still settles over the line with the TCA's hold eased by all of
/// `CLOSED_LOCK_EASE_MAX_K`) ends once the cap is spent, before the lock timeout, with both
/// heaters off and an alarm that names the PLA's reading and what to do.
#[test]
fn a_lock_no_easing_lets_finish_ends_with_its_reason_once_the_cap_is_spent() {
    use morphlink::strategy::closed::CLOSED_LOCK_EASE_MAX_K;
    let mut b = Bench::hifi_draw(20261122, 1);
    let lock = lock_of(&mut b, 32.92);
    ended_too_warm(&b, &lock.lines);
    let eased_k = lock.held_c - lock.lowest_c;
    assert!(
        (eased_k - CLOSED_LOCK_EASE_MAX_K).abs() <= 0.02,
        "eased {eased_k} K"
    );
    assert!(
        lock.lock_s < morphlink::sequencer::LOCK_TIMEOUT_S as f64,
        "the lock ran {} s",
        lock.lock_s
    );
}

/// In surroundings too warm for the stall rule (40 °C still air: only a bare PLA reading under
/// the rigid threshold ends lock there), a lock too warm to end is not eased, which could not
/// end it: it ends within five minutes of lock, not at the ten-minute timeout, with its alarm.
#[test]
fn a_lock_too_warm_to_finish_in_warm_surroundings_ends_early_and_says_why() {
    let mut b = Bench::new();
    for l in ["SIM MEDIUM air", "SIM AMBIENT 40"] {
        assert!(b.send(l)[0].starts_with("ok"), "{l}");
    }
    b.run_for(1500.0);
    let lock = lock_of(&mut b, 32.92);
    ended_too_warm(&b, &lock.lines);
    assert_eq!(lock.lowest_c, lock.held_c, "eased in warm surroundings");
    assert!(lock.lock_s < 300.0, "the lock ran {} s", lock.lock_s);
}

/// A lock the clock ends (here a 60 s `lock_timeout_s`, before `closed` can judge the same
/// too-warm lock) says the same: how warm the PLA stayed and what to do, naming the timeout.
#[test]
fn a_lock_the_clock_ends_names_how_warm_the_pla_stayed() {
    let mut b = in_still_air_at_27(&["CONFIG SET lock_timeout_s 60"]);
    let from = b.lines.len();
    b.morph(32.92, "auto");
    let alarms = b.alarms_since(from);
    assert_eq!(alarms.len(), 1, "{alarms:?}");
    let reading: f32 = alarms[0]
        .strip_prefix("alarm: phase-timeout phase lock did not finish: pla stays at ")
        .and_then(|r| r.split(' ').next())
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("{alarms:?}"));
    assert!(reading > 58.0, "{reading}");
    assert!(alarms[0].contains("(LOCK_TIMEOUT_S, "), "{alarms:?}");
    assert_eq!(b.rig.ctrl.powers().pla_w + b.rig.ctrl.powers().tca_w, 0.0);
}

/// A TCA that its 2 W cap holds short of its target ends bend there, and the morph finishes:
/// hifi draw 3 (water, 10.95 V supply) at 32.92 mm, whose TCA thermistor rose 0.05 K/s for the
/// whole bend (the silicone warming) 1.5 K short of its target, once timed out in bend with the
/// rod long settled (docs/strategies.md, "Morphs in a row").
#[test]
fn a_tca_its_cap_holds_short_of_target_ends_bend_and_the_morph_finishes() {
    let mut b = Bench::hifi_draw(20261122, 3);
    let t = b.morph(32.92, "auto");
    assert!(b.alarms().is_empty(), "{:?}", b.alarms());
    assert!(
        b.lines.iter().any(|l| l.starts_with("event: done")),
        "{:?}",
        b.lines
    );
    assert!(t < 100.0, "{t} s");
}

/// A morph sent the moment the last one reports `done` (a warm link) rests, heaters off, until
/// the link has cooled to the rest its model starts from, says so (`event: phase rest`), and
/// then lands within 0.5 percentage points of the same morph from rest, on both plants. Before:
/// on hifi `MORPH 44.4` straight after `MORPH 39.6` softened for 1.5 s, bent for 1.6 s and
/// ended at 36.36 mm (−18.1 %, against −6.5 % from rest). The ensemble's measure is
/// `cargo xtask warm` (docs/strategies.md, "Morphs in a row").
#[test]
fn a_morph_from_a_warm_link_rests_first_and_lands_as_from_rest() {
    for link in [common::Link::Lumped, common::Link::Hifi] {
        let settled_error_pct = |b: &mut Bench, target: f32| {
            b.morph(target, "auto");
            b.run_for(60.0);
            (b.rig.radius_mm() as f32 - target) / target * 100.0
        };
        let mut rested = Bench::on(link);
        let from_rest = settled_error_pct(&mut rested, 44.4);
        let mut warm = Bench::on(link);
        warm.morph(39.6, "auto");
        let n = warm.lines.len();
        let after_warm = settled_error_pct(&mut warm, 44.4);
        assert_eq!(
            warm.phases()[4..],
            ["rest", "soften", "bend", "lock", "release"],
            "{link:?}: {:?}",
            &warm.lines[n..]
        );
        assert!(warm.alarms_since(0).is_empty(), "{:?}", warm.lines);
        println!("{link:?}: 44.4 mm from rest {from_rest:+.2} %, after 39.6 mm {after_warm:+.2} %");
        assert!(
            after_warm.abs() <= from_rest.abs() + 0.5,
            "{link:?}: after a morph {after_warm:+.2} %, from rest {from_rest:+.2} %"
        );
    }
}

/// A morph whose own estimate ends away from its target says by how much in `done`: in a 40 °C
/// bath the PLA's heat keeps the TCA above a loose radius's target, so the rod locks tighter.
#[test]
fn a_done_that_missed_its_target_says_by_how_much() {
    let mut b = Bench::new();
    assert_eq!(b.send("SIM AMBIENT 40"), ["ok t_amb_c=40.00"]);
    b.run_for(300.0);
    b.morph(46.0, "auto");
    let done = b
        .lines
        .iter()
        .find(|l| classify(l) == LineKind::Done)
        .expect("done");
    let estimate: f32 = Bench::field(done, "radius_mm").unwrap().parse().unwrap();
    let missed: f32 = Bench::field(done, "missed_mm")
        .unwrap_or_else(|| panic!("{done}"))
        .parse()
        .unwrap();
    assert!((missed - (estimate - 46.0)).abs() < 0.011, "{done}");
    assert!(missed.abs() > 0.01 * 46.0, "{done}");
    // A morph that lands says nothing more.
    let mut b = Bench::new();
    b.morph(40.0, "auto");
    let done = b
        .lines
        .iter()
        .find(|l| classify(l) == LineKind::Done)
        .unwrap();
    assert_eq!(Bench::field(done, "missed_mm"), None, "{done}");
}

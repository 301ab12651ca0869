//! Several links on one board and one supply (`morphlink::links`, docs/multilink.md): one link
//! behaves exactly as the controller alone; under a budget no tick passes it and no PWM period
//! passes the supply's current limit; a fault on one link stops that link only; bad input is
//! refused and changes nothing.

use morphlink::bench::{Bench, Noise};
use morphlink::controller::{Config, Controller, TICK_MS};
use morphlink::links::{LinkOutputs, Links};
use morphlink::vocab::Phase;
use morphlink_plant::hifi::{Grid, Hifi, HifiSpec};
use morphlink_plant::Lumped;
use morphlink_sim::{LinkSetup, MultiRig, SharedSupply};

/// `plants` on one stiff bench supply of `limit_a`, booted.
fn on_supply<P: morphlink_plant::Plant>(
    plants: impl IntoIterator<Item = P>,
    noise: Noise,
    limit_a: f64,
) -> MultiRig<P> {
    let supply = SharedSupply {
        limit_a,
        ..SharedSupply::STIFF
    };
    let mut rig = MultiRig::new(plants, noise, supply);
    rig.boot(1000);
    rig
}

/// Four nominal lumped links on a bench supply of `limit_a`.
fn four(limit_a: f64) -> MultiRig<Lumped> {
    let plants = (0..4).map(|_| LinkSetup::NOMINAL.lumped());
    on_supply(plants, LinkSetup::NOMINAL.noise(), limit_a)
}

/// Four nominal lumped links on a 3 A bench supply, `supply_limit_a 3` and a budget of
/// `budget_w` (W).
fn four_under(budget_w: f64) -> MultiRig<Lumped> {
    let mut rig = four(3.0);
    for l in [
        "CONFIG SET supply_limit_a 3".to_string(),
        format!("CONFIG SET supply_budget_w {budget_w}"),
    ] {
        assert!(say(&mut rig, &l)[0].starts_with("ok"), "{l}");
    }
    rig
}

/// Holds that every alarm in `events` is link 2's and links 1, 3 and 4 ended `done`.
fn only_link_2_stopped(events: &[String], what: &str) {
    let alarms: Vec<_> = events.iter().filter(|e| e.contains("alarm:")).collect();
    assert!(!alarms.is_empty(), "{what}: no alarm");
    assert!(
        alarms.iter().all(|a| a.starts_with("@2 ")),
        "{what}: another link alarmed: {alarms:?}"
    );
    for k in [1, 3, 4] {
        assert!(
            events
                .iter()
                .any(|e| e.starts_with(&format!("@{k} event: done"))),
            "{what}: link {k} did not finish: {events:?}"
        );
    }
}

/// The reply lines to `line`.
fn say<P: morphlink_plant::Plant>(rig: &mut MultiRig<P>, line: &str) -> Vec<String> {
    let mut v = Vec::new();
    rig.handle_line(line, &mut |l: &str| v.push(l.to_string()));
    v
}

/// Runs until every link is idle (at most `max_s`), collecting event lines; checks `each`
/// after every tick.
fn run_until_idle<P: morphlink_plant::Plant>(
    rig: &mut MultiRig<P>,
    max_s: u64,
    mut each: impl FnMut(&MultiRig<P>),
) -> Vec<String> {
    let mut events = Vec::new();
    for _ in 0..max_s * 1000 / TICK_MS {
        rig.tick();
        rig.drain_events(&mut |l: &str| events.push(l.to_string()));
        each(rig);
        if rig.links.idle() {
            break;
        }
    }
    events
}

#[test]
fn one_link_behaves_exactly_as_the_controller_alone() {
    let cfg = Config::DEFAULT;
    let noise = Noise::NOMINAL;
    let mut alone = Controller::new(cfg);
    let mut links: Links<1> = Links::new(cfg, 1);
    let mut a = Bench::new(LinkSetup::NOMINAL.lumped(), cfg, noise);
    let mut b = Bench::new(LinkSetup::NOMINAL.lumped(), cfg, noise);
    let script = [
        (5, "MORPH 38"),
        (30, "STATUS"),
        (40, "HELP"),
        (50, "CONFIG"),
        (60, "RANGE"),
        (70, "MORPH 40"),
        (80, "bogus"),
        (90, "@1 STATUS"),
        (400, "ABORT"),
        (410, "MORPH 45 gated"),
    ];
    let mut out = [LinkOutputs::default()];
    for tick in 0..3000u64 {
        let now = tick * TICK_MS;
        for (at, line) in script {
            if at == tick && line != "@1 STATUS" {
                let (mut ra, mut rb) = (Vec::new(), Vec::new());
                alone.handle_line(now, line, &mut |l: &str| ra.push(l.to_string()));
                links.handle_line(now, line, &mut |l: &str| rb.push(l.to_string()));
                assert_eq!(ra, rb, "{line}");
            }
        }
        let (ia, ib) = (a.inputs(now), b.inputs(now));
        assert_eq!(ia, ib);
        let oa = alone.step(now, &ia);
        links.step(now, &[ib], &mut out);
        assert_eq!(oa, out[0].out, "tick {tick}");
        assert_eq!(out[0].phase, [0.0, 0.0]);
        a.drive(now, oa);
        b.drive(now, out[0].out);
        a.run(now, TICK_MS as f64 / 1000.0);
        b.run(now, TICK_MS as f64 / 1000.0);
        loop {
            let (ea, eb) = (alone.pop_event_line(), links.pop_event_line());
            assert_eq!(ea, eb);
            if ea.is_none() {
                break;
            }
        }
    }
    // The address of the one link is accepted and means it.
    let mut r = Vec::new();
    links.handle_line(300_000, "@1 STATUS", &mut |l: &str| r.push(l.to_string()));
    let mut s = Vec::new();
    alone.handle_line(300_000, "STATUS", &mut |l: &str| s.push(l.to_string()));
    assert_eq!(r, s);
}

#[test]
fn under_a_budget_no_tick_passes_it_no_period_passes_the_current_limit_and_every_link_finishes() {
    for (budget_w, limit_a) in [(5.0, 3.0), (8.0, 3.0), (12.0, 2.5)] {
        let mut rig = four(limit_a);
        assert!(
            say(&mut rig, &format!("CONFIG SET supply_limit_a {limit_a}"))[0].starts_with("ok")
        );
        assert!(
            say(&mut rig, &format!("CONFIG SET supply_budget_w {budget_w}"))[0].starts_with("ok")
        );
        assert_eq!(say(&mut rig, "GAIT 34 38 42 46"), ["ok"]);
        let (mut max_w, mut max_a) = (0.0f64, 0.0f64);
        let events = run_until_idle(&mut rig, 1500, |r| {
            max_w = max_w.max(r.last.reckoned_w);
            max_a = max_a.max(r.last.demand_a);
        });
        assert!(
            max_w <= budget_w + 1e-3,
            "{budget_w} W: a tick reckoned {max_w} W"
        );
        assert!(
            max_a <= limit_a + 1e-3,
            "{limit_a} A: a period drew {max_a} A"
        );
        for k in 1..=4 {
            let done = events
                .iter()
                .any(|e| e.starts_with(&format!("@{k} event: done")));
            assert!(done, "{budget_w} W: link {k} not done: {events:?}");
        }
        assert!(
            !events.iter().any(|e| e.contains("alarm:")),
            "{budget_w} W: {events:?}"
        );
        // A budget this small cannot soften four links at once: some morph waited.
        assert!(events.iter().any(|e| e.contains("event: queued")));
    }
}

#[test]
fn a_fault_on_one_link_stops_it_and_the_others_finish() {
    for fault in [
        "SIM FAULT heater-open pla",
        "SIM FAULT heater-stuck tca",
        "SIM FAULT thermistor-open pla",
        "SIM FAULT thermistor-short tca",
        "SIM FAULT thermistor-stuck pla",
    ] {
        let mut rig = four(3.0);
        say(&mut rig, "CONFIG SET supply_limit_a 3");
        say(&mut rig, "CONFIG SET supply_budget_w 12");
        assert_eq!(say(&mut rig, "GAIT 34 38 42 46"), ["ok"]);
        for _ in 0..20 {
            rig.tick();
        }
        let r = say(&mut rig, &format!("@2 {fault}"));
        assert!(r[0].starts_with("ok"), "{fault}: {r:?}");
        let events = run_until_idle(&mut rig, 1500, |_| {});
        only_link_2_stopped(&events, fault);
        assert_eq!(rig.links.link(1).phase(), Phase::Fault, "{fault}");
        assert!(
            !rig.links.link(1).outputs().supply_on,
            "{fault}: link 2's cut-off closed"
        );
    }
}

/// Four nominal hifi links on a bench supply of `limit_a`.
fn four_hifi(limit_a: f64) -> MultiRig<Hifi> {
    let spec = HifiSpec::nominal(LinkSetup::NOMINAL.params, Grid::Reduced).unwrap();
    let plant = Hifi::new(spec).unwrap();
    on_supply(
        (0..4).map(|_| plant.clone()),
        LinkSetup::NOMINAL.noise(),
        limit_a,
    )
}

/// On a 3 A supply with `budget_w` (W; `None`: no budget), `GAIT 34 38 42 46`; two seconds in,
/// link 2's TCA MOSFET shorts and its cut-off does not open: 1.8 A flow through it for good.
/// Runs until every link is idle (at most `max_s`) and holds that link 2 named its short; the
/// event lines.
fn short_behind_a_stuck_cut_off<P: morphlink_plant::Plant>(
    rig: &mut MultiRig<P>,
    budget_w: Option<u32>,
    max_s: u64,
) -> Vec<String> {
    say(rig, "CONFIG SET supply_limit_a 3");
    if let Some(w) = budget_w {
        assert!(say(rig, &format!("CONFIG SET supply_budget_w {w}"))[0].starts_with("ok"));
    }
    assert_eq!(say(rig, "GAIT 34 38 42 46"), ["ok"]);
    for _ in 0..20 {
        rig.tick();
    }
    assert!(say(rig, "@2 SIM FAULT cutoff-stuck")[0].starts_with("ok"));
    assert!(say(rig, "@2 SIM FAULT heater-stuck tca")[0].starts_with("ok"));
    let events = run_until_idle(rig, max_s, |_| {});
    assert!(
        events
            .iter()
            .any(|a| a.starts_with("@2 alarm: heater-short tca")),
        "{events:?}"
    );
    events
}

#[test]
fn a_short_behind_a_stuck_cut_off_is_a_load_the_others_are_scheduled_around() {
    // Link 2's TCA MOSFET shorts in soften and its cut-off does not open: 1.8 A flow through
    // it for good. No power budget, a 3 A supply: the others' heaters must fit in what is left
    // (docs/multilink.md, "A fault on one link"), so none of them reads less heat than it
    // asked and alarms for it.
    fn run<P: morphlink_plant::Plant>(mut rig: MultiRig<P>, plant: &str) {
        let events = short_behind_a_stuck_cut_off(&mut rig, None, 1500);
        only_link_2_stopped(&events, plant);
    }
    run(four(3.0), "lumped");
    // The first four water links of the hifi ensemble (`cargo xtask gait`'s), the noise of the
    // first: on these a link beside the short read less heat than it asked.
    let seed = 20_261_122;
    let mut plants = Vec::new();
    let mut noise = None;
    for d in 0.. {
        if plants.len() == 4 {
            break;
        }
        let (spec, n) = morphlink_sim::ensemble::hifi_draw(seed, d).unwrap();
        if spec.medium == morphlink_plant::Medium::Water {
            plants.push(Hifi::new(spec).unwrap());
            noise.get_or_insert(n);
        }
    }
    run(on_supply(plants, noise.unwrap(), 3.0), "hifi draws");
}

/// The same short under an 8 W budget: its 1.8 A (some 22 W) is more than the budget holds
/// beside the running links' reserves, so once link 2 has named its cut-off failed every other
/// link stops at once with the same alarm, heaters off, the queued one too; none starves into a
/// bare phase timeout.
#[test]
fn a_stray_the_budget_cannot_hold_stops_every_link_and_each_says_why() {
    let mut rig = four(3.0);
    let events = short_behind_a_stuck_cut_off(&mut rig, Some(8), 60);
    for k in [1, 3, 4] {
        let alarms: Vec<&String> = events
            .iter()
            .filter(|e| e.starts_with(&format!("@{k} alarm:")))
            .collect();
        assert!(
            alarms.len() == 1 && alarms[0].contains("alarm: cutoff-failed "),
            "link {k}: {events:?}"
        );
        assert_eq!(rig.links.link(k - 1).phase(), Phase::Fault, "link {k}");
        let p = rig.links.link(k - 1).powers();
        assert_eq!(p.pla_w + p.tca_w, 0.0, "link {k}");
    }
}

#[test]
fn a_shared_fault_stops_every_link_and_each_says_why() {
    for (sim, code) in [
        // The shared supply falls below what the heaters are rated for.
        ("@1 SIM SUPPLY 7", "supply-out-of-range"),
        // The one ambient bead opens, injected through any link: every link reads it.
        ("@3 SIM FAULT thermistor-open amb", "thermistor-open"),
    ] {
        let mut rig = four(10.0);
        assert_eq!(say(&mut rig, "GAIT 34 38 42 46"), ["ok"]);
        for _ in 0..20 {
            rig.tick();
        }
        assert!(say(&mut rig, sim)[0].starts_with("ok"), "{sim}");
        let events = run_until_idle(&mut rig, 60, |_| {});
        every_link_stopped_by(&rig, &events, code);
    }
}

/// Holds that every one of four links raised `code`'s alarm and stands faulted, heaters off
/// and its supply cut.
fn every_link_stopped_by<P: morphlink_plant::Plant>(
    rig: &MultiRig<P>,
    events: &[String],
    code: &str,
) {
    for k in 1..=4 {
        assert!(
            events
                .iter()
                .any(|e| e.starts_with(&format!("@{k} alarm: {code}"))),
            "link {k}: {events:?}"
        );
        assert_eq!(rig.links.link(k - 1).phase(), Phase::Fault);
        let o = rig.links.outputs(k - 1).out;
        assert_eq!((o.pla_duty, o.tca_duty, o.supply_on), (0.0, 0.0, false));
    }
}

#[test]
fn bad_input_is_refused_with_a_clear_error_and_changes_nothing() {
    let mut rig = four(3.0);
    let before = say(&mut rig, "LINKS");
    for (line, starts) in [
        (
            "@5 STATUS",
            "error: out-of-range no link 5; this board has links 1 to 4",
        ),
        ("@0 STATUS", "error: bad-argument"),
        ("@x MORPH 38", "error: bad-argument"),
        ("@2", "error: bad-argument"),
        (
            "GAIT 38 40",
            "error: bad-argument GAIT took 2 radii; this board has 4 links",
        ),
        ("GAIT 38 40 42 46 50", "error: bad-argument"),
        ("GAIT 38 40 42 999", "error: out-of-range"),
        (
            "CONFIG SET supply_budget_w 0",
            "error: out-of-range supply_budget_w takes",
        ),
        (
            "CONFIG SET supply_budget_w nan",
            "error: out-of-range supply_budget_w takes",
        ),
        (
            "CONFIG SET supply_budget_w 0.5",
            "error: out-of-range supply_budget_w 0.50 W is too small",
        ),
        (
            "CONFIG SET supply_limit_a 1",
            "error: out-of-range supply_limit_a 1.00 A is too small",
        ),
        (
            "CONFIG SET supply_limit_a -1",
            "error: out-of-range supply_limit_a takes",
        ),
        ("@* SIM STATE", "error: bad-argument"),
        ("LINKS 2", "error: bad-argument"),
        // One address, plain digits: no sign, no leading zero, never a second address.
        ("@01 STATUS", "error: bad-argument A link address is"),
        ("@+2 STATUS", "error: bad-argument A link address is"),
        (
            "@18446744073709551617 STATUS",
            "error: bad-argument A link address is",
        ),
        ("@2 @3 RANGE", "error: bad-argument One address per line"),
        // The board's own commands take no address.
        (
            "@2 GAIT 40 40 40 40",
            "error: bad-argument GAIT, LINKS and the supply's",
        ),
        (
            "@* LINKS",
            "error: bad-argument GAIT, LINKS and the supply's",
        ),
        (
            "@2 CONFIG SET supply_budget_w 8",
            "error: bad-argument GAIT, LINKS",
        ),
        // A GAIT's mode comes last, once.
        (
            "GAIT 34 38 paper 42 46",
            "error: bad-argument GAIT takes one radius",
        ),
        (
            "GAIT paper 34 38 42 46",
            "error: bad-argument GAIT takes one radius",
        ),
        (
            "GAIT 34 38 42 46 paper closed",
            "error: bad-argument GAIT takes one radius",
        ),
    ] {
        let r = say(&mut rig, line);
        assert_eq!(r.len(), 1, "{line}: {r:?}");
        assert!(r[0].starts_with(starts), "{line}: {r:?}");
    }
    assert_eq!(
        say(&mut rig, "LINKS"),
        before,
        "a refusal changed something"
    );
    assert!(rig.links.idle());
    // A budget raised past what the supply gives at its limit is refused.
    say(&mut rig, "CONFIG SET supply_limit_a 2");
    let r = say(&mut rig, "CONFIG SET supply_budget_w 30");
    assert!(
        r[0].starts_with(
            "error: out-of-range supply_budget_w 30.00 W is more than the supply gives"
        ),
        "{r:?}"
    );
    // Lowered under what running morphs hold: refused; raised while they run: taken.
    say(&mut rig, "CONFIG SET supply_limit_a 3");
    say(&mut rig, "CONFIG SET supply_budget_w 12");
    say(&mut rig, "GAIT 34 38 42 46");
    for _ in 0..30 {
        rig.tick();
    }
    let r = say(&mut rig, "CONFIG SET supply_budget_w 4");
    assert!(
        r[0].starts_with("error: busy supply_budget_w 4.00 W is less than"),
        "{r:?}"
    );
    assert_eq!(rig.links.budget().budget_w, 12.0);
    assert_eq!(
        say(&mut rig, "CONFIG SET supply_budget_w 20"),
        ["ok supply_budget_w=20.00 saved=no"]
    );
    // A link whose thermistor is missing refuses its morph; the GAIT starts nothing.
    let mut rig = four(3.0);
    say(&mut rig, "@3 SIM FAULT thermistor-open pla");
    for _ in 0..20 {
        rig.tick();
    }
    let r = say(&mut rig, "GAIT 34 38 42 46");
    assert!(r[0].starts_with("error: fault-latched"), "{r:?}");
    assert!(r[0].ends_with("(link 3; no link was started)"), "{r:?}");
    assert!(rig.links.idle());
}

/// Every least or most value a refusal prints is itself taken: the budget's and the limit's
/// least, the range's ends.
#[test]
fn the_least_a_refusal_names_is_taken() {
    let mut rig = four(3.0);
    let value_after = |r: &str, key: &str| -> String {
        let at = r.find(key).unwrap_or_else(|| panic!("{key} in {r}")) + key.len();
        r[at..]
            .split([' ', '.'])
            .take(2)
            .collect::<Vec<_>>()
            .join(".")
    };
    for (name, unit) in [("supply_budget_w", "W"), ("supply_limit_a", "A")] {
        let r = say(&mut rig, &format!("CONFIG SET {name} 0.5"));
        let least = value_after(&r[0], "the least that works is ");
        let ok = say(&mut rig, &format!("CONFIG SET {name} {least}"));
        assert!(ok[0].starts_with("ok"), "{r:?} then {least} {unit}: {ok:?}");
    }
    say(&mut rig, "CONFIG SET supply_limit_a 20");
    say(&mut rig, "CONFIG SET supply_budget_w 100");
    let r = say(&mut rig, "RANGE");
    let (min, max) = (value_after(&r[0], "min_mm="), value_after(&r[0], "max_mm="));
    for radius in [min, max] {
        let line = format!("MORPH {radius}");
        assert_eq!(say(&mut rig, &line), ["ok"], "{r:?}: {line}");
        assert_eq!(say(&mut rig, "ABORT"), ["ok"]);
        for _ in 0..10 {
            rig.tick();
        }
        say(&mut rig, "RESET");
    }
}

/// A TUNE or HEAT holds fixed powers from its first tick, ahead of every morph: under a
/// budget it starts only where those fit beside the running links' reserves, so it never
/// starves a running morph; and a link whose MORPH is queued refuses both (the queue would
/// drop its morph).
#[test]
fn a_tune_or_heat_never_takes_a_running_morphs_reserve() {
    let mut rig = four_under(4.5);
    assert_eq!(say(&mut rig, "@1 MORPH 34"), ["ok"]);
    for _ in 0..3 {
        rig.tick();
    }
    for line in ["@2 HEAT pla 1 60", "@3 TUNE"] {
        let r = say(&mut rig, line);
        assert!(r[0].starts_with("error: busy"), "{line}: {r:?}");
        assert!(r[0].contains("W free beside the running"), "{line}: {r:?}");
    }
    // A small HEAT that fits beside the reserve is taken.
    assert!(say(&mut rig, "@4 HEAT tca 0.1 5")[0].starts_with("ok"));
    assert_eq!(say(&mut rig, "@2 MORPH 46"), ["ok"]);
    assert!(rig.links.queued(1));
    for line in ["@2 TUNE", "@2 HEAT pla 0.2 5"] {
        let r = say(&mut rig, line);
        assert!(
            r[0].starts_with("error: busy this link's last MORPH waits"),
            "{line}: {r:?}"
        );
    }
    let events = run_until_idle(&mut rig, 900, |_| {});
    assert!(!events.iter().any(|e| e.contains("alarm:")), "{events:?}");
    for k in [1, 2] {
        assert!(
            events
                .iter()
                .any(|e| e.starts_with(&format!("@{k} event: done"))),
            "link {k}: {events:?}"
        );
    }
}

/// A link that faults while its morph waits in the queue drops that morph at once and says
/// why: after the user clears the fault and sends RESET, nothing starts by itself.
#[test]
fn a_fault_drops_its_links_queued_morph_at_once() {
    let mut rig = four_under(5.0);
    assert_eq!(say(&mut rig, "@1 MORPH 34"), ["ok"]);
    assert_eq!(say(&mut rig, "@2 MORPH 46"), ["ok"]);
    assert!(rig.links.queued(1));
    assert!(say(&mut rig, "@2 SIM FAULT heater-open tca")[0].starts_with("ok"));
    let mut events = Vec::new();
    for _ in 0..20 {
        rig.tick();
        rig.drain_events(&mut |l: &str| events.push(l.to_string()));
    }
    assert!(!rig.links.queued(1), "{events:?}");
    assert!(
        events
            .iter()
            .any(|e| e.starts_with("@2 event: queued-morph dropped (error: fault-latched")),
        "{events:?}"
    );
    assert!(say(&mut rig, "@2 SIM CLEAR")[0].starts_with("ok"));
    for _ in 0..20 {
        rig.tick();
    }
    say(&mut rig, "@2 RESET");
    let events = run_until_idle(&mut rig, 900, |_| {});
    assert!(
        !events.iter().any(|e| e.starts_with("@2 event: phase")),
        "link 2 started by itself: {events:?}"
    );
}

/// A queued morph never waits for good: a budget lowered under what it needs is refused, and
/// one that cannot start with every link idle (here a current limit taken while the TCA ran
/// hot, which a cold TCA passes) is dropped with the reason.
#[test]
fn a_queued_morph_never_waits_for_good() {
    let mut rig = four_under(4.5);
    assert_eq!(say(&mut rig, "@1 MORPH 46"), ["ok"]);
    assert_eq!(say(&mut rig, "@2 MORPH 34"), ["ok"]);
    assert!(rig.links.queued(1));
    let r = say(&mut rig, "CONFIG SET supply_budget_w 3");
    assert!(
        r[0].starts_with(
            "error: busy supply_budget_w 3.00 W is less than the morph queued on link 2"
        ),
        "{r:?}"
    );
    assert_eq!(rig.links.budget().budget_w, 4.5);
    let events = run_until_idle(&mut rig, 900, |_| {});
    assert!(
        events.iter().any(|e| e.starts_with("@2 event: done")),
        "{events:?}"
    );

    // A limit taken while a low-resistance TCA ran hot (its resistance read higher than its
    // nominal one and its cold one): once cold that TCA draws more than the limit, so a morph
    // queued on it never starts even on an idle board; it is dropped and says why.
    let low = LinkSetup {
        heater_ohm: [
            LinkSetup::NOMINAL.heater_ohm[0],
            0.9 * LinkSetup::NOMINAL.heater_ohm[1],
        ],
        ..LinkSetup::NOMINAL
    };
    let plants = (0..4).map(|k| if k == 1 { low } else { LinkSetup::NOMINAL }.lumped());
    let mut rig = on_supply(plants, LinkSetup::NOMINAL.noise(), 3.0);
    say(&mut rig, "CONFIG SET supply_limit_a 3");
    assert_eq!(say(&mut rig, "@2 MORPH 34"), ["ok"]);
    for _ in 0..200 {
        rig.tick();
    }
    let r = say(&mut rig, "CONFIG SET supply_limit_a 0.5");
    let least = r[0]
        .split("the least that works is ")
        .nth(1)
        .and_then(|t| t.split(' ').next())
        .unwrap_or_else(|| panic!("{r:?}"))
        .to_string();
    assert!(say(&mut rig, &format!("CONFIG SET supply_limit_a {least}"))[0].starts_with("ok"));
    run_until_idle(&mut rig, 900, |_| {});
    for _ in 0..1200 {
        rig.tick();
    }
    assert_eq!(say(&mut rig, "@2 MORPH 40"), ["ok"]);
    let events = run_until_idle(&mut rig, 10, |_| {});
    assert!(
        events.iter().any(|e| e.starts_with(
            "@2 event: queued-morph dropped (error: out-of-range the supply cannot start this morph with every link idle"
        )),
        "{events:?}"
    );
    assert!(rig.links.idle());

    // A limit lowered under a budget it cannot give is refused.
    let mut rig = four_under(30.0);
    let r = say(&mut rig, "CONFIG SET supply_limit_a 2");
    assert!(
        r[0].starts_with("error: out-of-range supply_limit_a 2.00 A gives"),
        "{r:?}"
    );
    assert_eq!(rig.links.budget().limit_a, 3.0);
}

#[test]
fn an_unaddressed_abort_stops_every_link_and_empties_the_queue() {
    let mut rig = four_under(5.0);
    assert_eq!(say(&mut rig, "GAIT 34 38 42 46"), ["ok"]);
    for _ in 0..30 {
        rig.tick();
    }
    assert!((0..4).any(|k| rig.links.queued(k)));
    assert_eq!(say(&mut rig, "ABORT"), ["ok"]);
    for k in 0..4 {
        assert!(!rig.links.queued(k));
        let o = rig.links.outputs(k).out;
        assert_eq!((o.pla_duty, o.tca_duty), (0.0, 0.0));
    }
    assert!(rig.links.idle());
}

/// A bench supply whose own current limit is under `supply_limit_a` (the default, which never
/// binds) sags inside the pulses the scheduler lets overlap: the links see it in their
/// on-currents, every link stops with `supply-out-of-range` and an event names the setting, and
/// no link ends `done` at a radius the sag made. With the setting at the supply's limit the same
/// gait finishes with no alarm.
#[test]
fn a_supply_weaker_than_its_setting_stops_every_link_and_says_what_to_set() {
    let mut rig = four(2.0);
    say(&mut rig, "CONFIG SET supply_budget_w 8");
    assert_eq!(say(&mut rig, "GAIT 34 38 42 46"), ["ok"]);
    let events = run_until_idle(&mut rig, 600, |_| {});
    assert!(
        events.iter().any(|e| e.contains("event: supply sags to",)
            && e.contains("supply_limit_a=20.00; set supply_limit_a to it (docs/multilink.md)")),
        "{events:?}"
    );
    every_link_stopped_by(&rig, &events, "supply-out-of-range");
    assert!(
        !events.iter().any(|e| e.contains("event: done")),
        "{events:?}"
    );
    assert!(
        !events.iter().any(|e| e.contains("heater-resistance")),
        "{events:?}"
    );

    gait_finishes(&mut four(2.0), 2.0, 8.0);
}

/// A GAIT under a budget that cannot start every link starts the tightest bend (the longest
/// morph) first and queues the loosest, wherever each stands in the line; links asking the
/// same keep their order.
#[test]
fn a_gait_starts_its_longest_morph_first_and_queues_the_shortest() {
    for (gait, first, last) in [
        ("GAIT 46 42 38 34", 4, 1),
        ("GAIT 34 38 42 46", 1, 4),
        ("GAIT 42 34 46 38", 2, 3),
    ] {
        let mut rig = four(3.0);
        say(&mut rig, "CONFIG SET supply_budget_w 5");
        assert_eq!(say(&mut rig, gait), ["ok"], "{gait}");
        let mut events = Vec::new();
        rig.drain_events(&mut |l: &str| events.push(l.to_string()));
        let softens: Vec<_> = events
            .iter()
            .filter(|e| e.contains("event: phase soften"))
            .collect();
        assert!(
            softens[0].starts_with(&format!("@{first} ")),
            "{gait}: {events:?}"
        );
        assert!(rig.links.queued(last - 1), "{gait}: {events:?}");
    }
    // Equal asks keep the link order.
    let mut rig = four(3.0);
    say(&mut rig, "CONFIG SET supply_budget_w 5");
    assert_eq!(say(&mut rig, "GAIT 40 40 40 40"), ["ok"]);
    assert!(!rig.links.queued(0) && rig.links.queued(3));
}

#[test]
fn four_hifi_links_under_8_w_finish_within_the_budget() {
    let max_w = gait_finishes(&mut four_hifi(3.0), 3.0, 8.0);
    assert!(max_w <= 8.0 + 1e-3, "{max_w}");
}

/// Under one soften's worth, the least budget under which each morph of the gait starts on an
/// idle board (every link waits its turn), each link's bend still ends and every link is done:
/// a TCA the allowance holds short of its target counts as stalled whatever the allowance's
/// milliwatts of tick-to-tick movement.
#[test]
fn four_hifi_links_under_one_softens_worth_finish() {
    let mut rig = four_hifi(3.0);
    let least_w = [34.0, 38.0, 42.0, 46.0]
        .iter()
        .enumerate()
        .filter_map(|(k, &r)| rig.links.soften_reserve_w(k, r))
        .map(|r| morphlink::budget::least_budget_w(r, 4))
        .fold(0.0f32, f32::max);
    let budget_w = (least_w * 100.0).ceil() / 100.0;
    let max_w = gait_finishes(&mut rig, 3.0, budget_w as f64);
    assert!(max_w <= budget_w as f64 + 1e-3, "{max_w}");
}

/// In still air a rod held at 1.3 times what keeps it soft takes minutes to soften: a soften
/// under a budget is admitted with, and never cut below, what softens it within half its
/// timeout, so four still-air links under 8 W all soften in time instead of the youngest
/// meeting the soften timeout on their reserves while the oldest take the rest.
#[test]
fn still_air_softens_under_a_budget_in_time() {
    let mut rig = four_hifi(3.0);
    for l in [
        "@1 SIM MEDIUM air",
        "@2 SIM MEDIUM air",
        "@3 SIM MEDIUM air",
        "@4 SIM MEDIUM air",
        "@* CONFIG SET convection_w_m2k 20",
    ] {
        assert!(say(&mut rig, l).last().unwrap().starts_with("ok"), "{l}");
    }
    // The still-air model's rises, as a still-air TUNE sets them.
    let cal = rig.links.link(0).calibration();
    let r = cal.model_resistances();
    for (name, v) in [
        ("pla_rise_k_per_w", r.r_pp),
        ("tca_rise_k_per_w", r.r_tt),
        ("pla_to_tca_k_per_w", r.r_tp),
        ("tca_to_pla_k_per_w", r.r_tp),
    ] {
        let l = format!("@* CONFIG SET {name} {v:.2}");
        assert!(say(&mut rig, &l).last().unwrap().starts_with("ok"), "{l}");
    }
    let max_w = gait_finishes(&mut rig, 3.0, 8.0);
    assert!(max_w <= 8.0 + 1e-3, "{max_w}");
}

/// Sets `supply_limit_a` and `supply_budget_w`, runs `GAIT 34 38 42 46` and holds that every
/// link ends `done` with no alarm; returns the highest summed power any tick reckoned, W.
fn gait_finishes<P: morphlink_plant::Plant>(
    rig: &mut MultiRig<P>,
    limit_a: f64,
    budget_w: f64,
) -> f64 {
    say(rig, &format!("CONFIG SET supply_limit_a {limit_a}"));
    say(rig, &format!("CONFIG SET supply_budget_w {budget_w}"));
    assert_eq!(say(rig, "GAIT 34 38 42 46"), ["ok"]);
    let mut max_w = 0.0f64;
    let events = run_until_idle(rig, 1500, |r| max_w = max_w.max(r.last.reckoned_w));
    assert!(!events.iter().any(|e| e.contains("alarm:")), "{events:?}");
    assert_eq!(
        events.iter().filter(|e| e.contains("event: done")).count(),
        4,
        "{events:?}"
    );
    max_w
}

/// The supply's settings a SAVE kept come back at boot when `CONFIG SET` would take them; a
/// record of another format, or one outside what the links allow now, leaves the defaults,
/// and an event says which.
#[test]
fn the_supply_settings_kept_by_save_come_back_only_if_still_in_range() {
    use morphlink::budget::SupplyBudget;
    let rig = four_under(8.0);
    let kept = rig
        .links
        .board_record(0)
        .expect("link 1's SAVE carries the supply");
    assert!(rig.links.board_record(1).is_none(), "only with link 1's");
    // A boot with `stored`: the supply's settings and the board's events.
    let boot = |stored: Result<Option<&[u8]>, ()>| {
        let mut r = four(3.0);
        r.links.load_board(stored);
        let mut e = Vec::new();
        r.drain_events(&mut |l: &str| e.push(l.to_string()));
        (r.links.budget(), e.join("\n"))
    };
    let (back, e) = boot(Ok(Some(&kept)));
    assert_eq!((back.budget_w, back.limit_a), (8.0, 3.0));
    assert!(
        e.contains("event: config supply loaded supply_budget_w=8.00 supply_limit_a=3.00"),
        "{e}"
    );
    // Too small a budget for any soften: refused, the defaults stay.
    let tiny = SupplyBudget {
        budget_w: 0.5,
        limit_a: 3.0,
    }
    .to_bytes();
    let (back, e) = boot(Ok(Some(&tiny)));
    assert_eq!(back, SupplyBudget::UNLIMITED);
    assert!(
        e.contains("event: config supply defaults reason=out-of-range"),
        "{e}"
    );
    let (back, e) = boot(Ok(Some(&kept[..4])));
    assert_eq!(back, SupplyBudget::UNLIMITED);
    assert!(e.contains("reason=format"), "{e}");
    assert!(boot(Ok(None)).1.contains("reason=absent"));
    assert!(boot(Err(())).1.contains("reason=flash-error"));
}

/// SAVE writes flash, which stalls the CPU: on several links it is refused while any link
/// heats or waits for the budget, and under `@*` (each link's SAVE is its own), changing
/// nothing.
#[test]
fn save_waits_for_every_link_and_is_not_sent_to_all_at_once() {
    let mut rig = four(20.0);
    let each = say(&mut rig, "@* SAVE");
    assert_eq!(each.len(), 1, "{each:?}");
    assert!(
        each[0].starts_with("error: bad-argument SAVE one link at a time"),
        "{each:?}"
    );
    say(&mut rig, "@2 MORPH 38");
    assert!(!rig.links.idle());
    let busy = say(&mut rig, "@3 SAVE");
    assert!(
        busy[0].starts_with("error: busy SAVE waits until every link is idle"),
        "{busy:?}"
    );
    say(&mut rig, "ABORT");
    // Idle again: the link's own answer (this rig keeps no flash).
    let idle = say(&mut rig, "@3 SAVE");
    assert!(!idle[0].contains("waits until every link"), "{idle:?}");
}

/// Four idle links read by hand (their probe pulses' currents at `scale` of what each heater's
/// resistance draws, per link and heater) for `ticks` ticks from `*now_ms`.
fn idle_frames(links: &mut Links<4>, now_ms: &mut u64, ticks: u32, scale: [[f32; 2]; 4]) {
    use morphlink::controller::{Inputs, OVERSAMPLE};
    use morphlink::electrical::{CurrentCounts, ShuntSense};
    let cfg = Config::DEFAULT;
    let one = ShuntSense {
        full_scale_counts: 4095,
        ..cfg.shunt
    };
    let ohm = [cfg.pla_heater.resistance_ohm, cfg.tca_heater.resistance_ohm];
    let mut out = [LinkOutputs::default(); 4];
    for _ in 0..ticks {
        // A live reading moves by its noise: a few hundredths of a kelvin.
        let jitter = 0.02 * (*now_ms / TICK_MS % 3) as f32;
        let inputs = scale.map(|s| Inputs {
            thermistor_counts: [22.0, 22.0, 22.0]
                .map(|t| cfg.thermistor.counts_for_temp(t + jitter)),
            supply_counts: cfg.supply.counts(12.0),
            sample_ms: *now_ms,
            current: Some(CurrentCounts {
                on: [0, 1].map(|i| one.counts(s[i] * 12.0 / ohm[i]) * OVERSAMPLE),
                off: [0, 0],
            }),
        });
        links.step(*now_ms, &inputs, &mut out);
        *now_ms += TICK_MS;
    }
}

/// One heater whose current falls is that heater's resistance, judged on its own link; only two
/// or more falling at once are the supply's, and then every link stops.
#[test]
fn one_heater_reading_low_is_its_own_and_two_at_once_are_the_supplys() {
    let fine = [[1.0; 2]; 4];
    let mut links: Links<4> = Links::new(Config::DEFAULT, 4);
    let mut now_ms = 0;
    idle_frames(&mut links, &mut now_ms, 30, fine);
    // Link 2's PLA heater reads 25 % high, still in its range: nobody alarms.
    let mut one_high = fine;
    one_high[1][0] = 0.8;
    idle_frames(&mut links, &mut now_ms, 10, one_high);
    assert!((0..4).all(|k| links.link(k).fault().is_none()));
    // ...then 67 % high, out of range: its own link names it, the others go on.
    one_high[1][0] = 0.6;
    idle_frames(&mut links, &mut now_ms, 5, one_high);
    let f = links.link(1).fault().expect("link 2 faulted");
    assert_eq!(f.code.as_str(), "heater-resistance");
    assert!([0, 2, 3].iter().all(|&k| links.link(k).fault().is_none()));
    // Two heaters on other links reading low at once: the supply sags, every link stops.
    let mut two_low = fine;
    two_low[0][1] = 0.6;
    two_low[2][1] = 0.6;
    idle_frames(&mut links, &mut now_ms, 1, two_low);
    assert!([0, 2, 3].iter().all(|&k| links.link(k).fault().is_none()));
    idle_frames(&mut links, &mut now_ms, 1, two_low);
    for k in [0, 2, 3] {
        let f = links.link(k).fault().expect("stopped");
        assert_eq!(f.code.as_str(), "supply-out-of-range", "link {}", k + 1);
        assert!((f.value - 7.2).abs() < 0.3, "{}", f.value);
    }
}

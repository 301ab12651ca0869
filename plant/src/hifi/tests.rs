//! The hifi plant's tests: coarse grids so each stays within a few seconds in debug builds.

use super::*;
use crate::lumped::{Lumped, LumpedSpec};
use crate::{Duties, Medium, Plant, Setting};
use morphlink_model::mechanics::radius_mm;
use morphlink_model::table::power_of_entry_w;
use morphlink_model::LinkParams;

const DT_S: f64 = 0.1;

fn spec(rings: usize) -> HifiSpec {
    HifiSpec::nominal(LinkParams::DEFAULT, Grid::Rings(rings)).unwrap()
}

fn link(rings: usize) -> Hifi {
    Hifi::new(spec(rings)).unwrap()
}

fn run(h: &mut Hifi, secs: f64, duty: Duties) {
    for _ in 0..(secs / DT_S).round() as usize {
        h.step(DT_S, duty);
    }
}

/// Duty that gives `w` watts in the nominal wrap at the nominal supply.
fn pla_duty(w: f64) -> f64 {
    w * spec::HEATER_OHM_NOMINAL[0] / (spec::SUPPLY_NOMINAL_V * spec::SUPPLY_NOMINAL_V)
}

/// Duty that gives `w` watts in the TCA at its reference resistance.
fn tca_duty(w: f64) -> f64 {
    w * spec::HEATER_OHM_NOMINAL[1] / (spec::SUPPLY_NOMINAL_V * spec::SUPPLY_NOMINAL_V)
}

/// The paper's morph (Fig. 8) at TCA power `tca_w`: PLA 4 W to 20 s, 1.5 W to 70 s, off; TCA
/// on from 20 s to 120 s; then `rest_s` with both off.
fn morph(h: &mut Hifi, tca_w: f64, rest_s: f64) {
    let n = ((120.0 + rest_s) / DT_S).round() as usize;
    for k in 0..n {
        let t = k as f64 * DT_S;
        let pla = if t < 20.0 {
            pla_duty(4.0)
        } else if t < 70.0 {
            pla_duty(1.5)
        } else {
            0.0
        };
        let tca = if (20.0..120.0).contains(&t) {
            tca_duty(tca_w)
        } else {
            0.0
        };
        h.step(DT_S, Duties { pla, tca });
    }
}

#[test]
fn at_steady_state_the_power_in_leaves_through_the_rim_and_transients_conserve_heat() {
    for grid in [Grid::Rings(8), Grid::ReducedRings(8)] {
        energy_balance(grid);
    }
}

fn energy_balance(grid: Grid) {
    let mut h = Hifi::new(HifiSpec::nominal(LinkParams::DEFAULT, grid).unwrap()).unwrap();
    let amb = h.spec().ambient_c;
    let duty = Duties {
        pla: pla_duty(1.5),
        tca: tca_duty(0.5),
    };
    // Heat balance over a transient: what went in is stored or left through the rim.
    let (mut e_in, mut e_out) = (0.0, 0.0);
    for _ in 0..300 {
        h.step(DT_S, duty);
        let t = h.truth();
        e_in += (t.pla_w + t.tca_w) * DT_S;
        e_out += h.section().rim_power_w(amb) * DT_S;
    }
    let stored = h.section().stored_j(amb);
    assert!(
        (stored + e_out - e_in).abs() < 2e-3 * e_in,
        "in {e_in} J, stored {stored} J, out {e_out} J"
    );
    // Long steps to the steady state: power in = convective power out.
    for _ in 0..200 {
        h.step(20.0, duty);
    }
    let t = h.truth();
    let out = h.section().rim_power_w(amb);
    let p_in = t.pla_w + t.tca_w;
    assert!((out - p_in).abs() < 1e-3 * p_in, "in {p_in} W, out {out} W");
}

#[test]
fn beads_lag_their_heaters_and_read_below_the_heater_means() {
    let mut h = link(10);
    let amb = h.spec().ambient_c;
    let pos = h.spec().beads.map(|b| b.position_m);
    run(
        &mut h,
        2.0,
        Duties {
            pla: pla_duty(4.0),
            tca: tca_duty(1.0),
        },
    );
    // The bead trails the silicone it sits in: a lag from its own heat capacity.
    for (i, p) in pos.iter().take(2).enumerate() {
        let local = h.section().at_c(p.unwrap());
        let bead = h.bead_true_c()[i];
        assert!(
            bead - amb < 0.8 * (local - amb),
            "bead {i}: {bead} vs local {local}"
        );
    }
    run(
        &mut h,
        28.0,
        Duties {
            pla: pla_duty(4.0),
            tca: tca_duty(1.0),
        },
    );
    let s = h.sample();
    let t = h.truth();
    assert!(
        s.t_pla_c < t.pla_c - 2.0,
        "PLA bead {} rod {}",
        s.t_pla_c,
        t.pla_c
    );
    assert!(
        s.t_tca_c < t.tca_c - 2.0,
        "TCA bead {} TCA {}",
        s.t_tca_c,
        t.tca_c
    );
    // Self-heating: the ambient bead in the medium reads a little above it (0.1–0.3 K).
    let rise = h.bead_true_c()[2] - amb;
    assert!(rise > 0.05 && rise < 0.4, "self-heating {rise} K");
}

#[test]
fn apparent_readings_follow_the_beads_own_r25_and_beta() {
    let mut s = spec(8);
    let nominal = s.beads[0];
    let b = bead::Bead { temp_c: 60.0 };
    assert!((b.apparent_c(&nominal) - 60.0).abs() < 1e-9);
    // A bead with R25 1 % high reads cold: about 0.2–0.3 K near 25 °C.
    s.beads[0].r25_ohm *= 1.01;
    let cold = bead::Bead { temp_c: 25.0 }.apparent_c(&s.beads[0]);
    assert!(cold < 25.0 - 0.15 && cold > 25.0 - 0.4, "{cold}");
    // A Beta 1 % high reads true at 25 °C and hot below... cold above it.
    let mut hb = nominal;
    hb.beta_k *= 1.01;
    assert!((bead::Bead { temp_c: 25.0 }.apparent_c(&hb) - 25.0).abs() < 1e-9);
    assert!(bead::Bead { temp_c: 80.0 }.apparent_c(&hb) > 80.0 + 0.3);
}

#[test]
fn pla_modulus_goes_glassy_to_rubbery_through_tg_and_the_field_is_nonuniform() {
    let s = spec(10);
    let pla = s.pla;
    let e = |t: f64| pla::modulus_pa(&pla, t);
    assert!((e(25.0) / spec::PLA_E_GLASSY_PA - 1.0).abs() < 1e-3);
    assert!((e(95.0) / spec::PLA_E_RUBBERY_PA - 1.0).abs() < 1e-3);
    let mid = (spec::PLA_E_GLASSY_PA * spec::PLA_E_RUBBERY_PA).sqrt();
    assert!((e(pla.tg_c) / mid - 1.0).abs() < 1e-9);
    assert!(e(pla.tg_c - 5.0) > 10.0 * e(pla.tg_c + 5.0));
    // Heating: the rod's cells cross Tg at different times (the wrap heats the surface).
    let mut h = Hifi::new(s).unwrap();
    let b_cold = h.pla_stiffness_nm2();
    let mut spread_seen: f64 = 1.0;
    for _ in 0..200 {
        h.step(
            DT_S,
            Duties {
                pla: pla_duty(4.0),
                tca: 0.0,
            },
        );
        let m = h.pla_moduli_pa();
        let (lo, hi) = m
            .iter()
            .fold((f64::MAX, 0.0f64), |(lo, hi), &x| (lo.min(x), hi.max(x)));
        spread_seen = spread_seen.max(hi / lo);
    }
    assert!(spread_seen > 100.0, "largest modulus spread {spread_seen}");
    let b_hot = h.pla_stiffness_nm2();
    assert!(b_hot < 2e-3 * b_cold, "cold {b_cold} hot {b_hot}");
}

#[test]
fn pla_relaxes_fast_above_tg_and_creeps_slowly_when_cold() {
    let p = spec(8).pla;
    let tau = |t: f64| pla::relaxation_time_s(&p, t);
    assert!((tau(p.tg_c) - p.tau_at_tg_s).abs() < 1e-9);
    assert!(tau(p.tg_c + 15.0) < 0.5, "{}", tau(p.tg_c + 15.0));
    assert!(tau(22.0) > 1e4 && tau(22.0) < 1e7, "{}", tau(22.0));
    assert!(tau(40.0) < tau(30.0) && tau(30.0) < tau(22.0));
    // A cold rod held at another curvature creeps toward it: a little in an hour, more in
    // a day, never all at once.
    let mut h = link(8);
    let k0 = h.rod().frozen_per_m()[0];
    let field = h.section().field_c().to_vec();
    let mut rod = h.rod().clone();
    rod.relax(&p, &field, k0 + 10.0, 3600.0);
    let hour = rod.frozen_per_m()[0] - k0;
    rod.relax(&p, &field, k0 + 10.0, 86400.0);
    let day = rod.frozen_per_m()[0] - k0;
    assert!(hour > 0.01 && hour < 1.0, "{hour}");
    assert!(day > 3.0 * hour && day < 10.0, "{day}");
    // Through the plant: a locked link creeps toward its soft equilibrium by long steps.
    let r0 = h.sample().radius_mm;
    morph(&mut h, 1.0, 60.0);
    let locked = h.sample().radius_mm;
    for _ in 0..48 {
        h.step(3600.0, Duties::default());
    }
    let later = h.sample().radius_mm;
    assert!(
        (later - locked) * (r0 - locked) > 0.0
            && (later - locked).abs() < 0.5 * (r0 - locked).abs(),
        "start {r0} locked {locked} after two days {later}"
    );
}

#[test]
fn a_morph_leaves_a_persistent_new_radius_after_release() {
    let mut h = link(10);
    let r0 = h.sample().radius_mm;
    morph(&mut h, 1.0, 60.0);
    let r1 = h.sample().radius_mm;
    eprintln!(
        "paper morph at 1 W: {r0:.2} mm -> {r1:.2} mm (table: {:.2} mm)",
        radius_mm(&LinkParams::DEFAULT, 1.0)
    );
    assert!(r1 < 0.9 * r0, "start {r0} after morph {r1}");
    run(&mut h, 60.0, Duties::default());
    let r2 = h.sample().radius_mm;
    assert!((r2 - r1).abs() < 1e-3 * r1, "{r1} then {r2}");
    // History: a second, gentler morph starts from the first's frozen shape and lands
    // elsewhere.
    morph(&mut h, 0.3, 60.0);
    let r3 = h.sample().radius_mm;
    assert!(r3 > r1 * 1.05, "first {r1} second {r3}");
}

#[test]
fn the_link_is_pre_bent_and_returns_to_its_pre_bend_not_straight() {
    let mut h = link(8);
    let r0 = h.sample().radius_mm;
    assert!(
        r0.is_finite() && r0 > 0.0 && r0 < 500.0,
        "pre-bend radius {r0}"
    );
    // The silicone's own rest curvature is part of it.
    let mut flat = spec(8);
    flat.silicone_rest_per_m = 0.0;
    let r_flat = Hifi::new(flat).unwrap().sample().radius_mm;
    assert!(
        r_flat > r0 * 1.02,
        "rest curvature adds bend: {r_flat} vs {r0}"
    );
    // A morph bends it; softening again with the TCA off lets it spring back toward the
    // pre-bend, not to straight. (It does not get all the way back: the wrap's heat warms the
    // TCA, which pushes while the rod freezes again.)
    morph(&mut h, 1.0, 60.0);
    let bent = h.sample().radius_mm;
    run(
        &mut h,
        40.0,
        Duties {
            pla: pla_duty(3.0),
            tca: 0.0,
        },
    );
    run(&mut h, 120.0, Duties::default());
    let back = h.sample().radius_mm;
    assert!(
        back > bent * 1.05 && back < r0 * 1.02,
        "pre-bend {r0}, bent {bent}, back {back}"
    );
    assert!(back < 0.2 * r_flat.max(r0) * 10.0, "never straight: {back}");
}

#[test]
fn tca_force_curves_differ_on_heating_and_cooling() {
    let s = spec(8).tca;
    let mut tca = tca::Tca::at_rest(&s, 20.0);
    let push_at = |tca: &tca::Tca, t: f64| tca.push_n(&s, t, 1e-3);
    let mut up = Vec::new();
    for i in 0..=60 {
        let t = 20.0 + i as f64;
        tca.update(&s, t, 0.0);
        up.push(push_at(&tca, t));
    }
    let mut down = vec![0.0; 61];
    for i in (0..=60).rev() {
        let t = 20.0 + i as f64;
        tca.update(&s, t, 0.0);
        down[i] = push_at(&tca, t);
    }
    // At 50 °C the cooling branch pushes harder, by the stroke of the play's 3 K.
    let k = s.law.spring_rate_n_per_m(50.0);
    let gap = down[30] - up[30];
    let expect = k * (tca::free_stroke_m(&s, 51.5) - tca::free_stroke_m(&s, 48.5));
    assert!(
        gap > 0.0 && (gap - expect).abs() < 0.05 * expect,
        "{gap} vs {expect}"
    );
    // Loop closed: the branches meet at the ends.
    assert!((down[60] - up[60]).abs() < 1e-12);
}

#[test]
fn tca_creeps_slowly_and_its_resistance_follows_its_temperature() {
    let s = spec(8).tca;
    let mut tca = tca::Tca::at_rest(&s, 22.0);
    tca.update(&s, 90.0, 0.0);
    let fresh = tca.stroke_m(&s);
    tca.update(&s, 90.0, 10.0);
    let ten = tca.stroke_m(&s);
    for _ in 0..100 {
        tca.update(&s, 90.0, 10.0);
    }
    let long = tca.stroke_m(&s);
    assert!(
        ten < fresh && fresh - ten < 0.1 * (fresh - long),
        "{fresh} {ten} {long}"
    );
    assert!(fresh - long > 0.5 * s.creep_fraction * (fresh - tca::free_stroke_m(&s, 22.0)));
    assert!(tca::resistance_ohm(&s, 100.0, 0.0) > 1.1 * tca::resistance_ohm(&s, 22.0, 0.0));
    // Through the plant: the same duty delivers less power as the TCA warms.
    let mut h = link(8);
    let d = Duties {
        pla: 0.0,
        tca: tca_duty(1.0),
    };
    h.step(DT_S, d);
    let p0 = h.truth().tca_w;
    run(&mut h, 60.0, d);
    let p1 = h.truth().tca_w;
    assert!(p1 < 0.97 * p0, "{p0} W then {p1} W");
}

#[test]
fn hifi_tca_rises_more_slowly_than_the_lumped_network() {
    // Same link, same constant power (no R(T) so the watts are equal).
    let p = LinkParams::DEFAULT;
    let mut s = HifiSpec::nominal(p, Grid::Reduced).unwrap();
    s.tca.tcr_per_k = 0.0;
    s.pla_heater_tcr_per_k = 0.0;
    let mut h = Hifi::new(s).unwrap();
    let mut l = Lumped::new(LumpedSpec {
        params: p,
        heater_ohm: spec::HEATER_OHM_NOMINAL,
        heater_tcr_per_k: [0.0; 2],
        supply_v: spec::SUPPLY_NOMINAL_V,
        sensor_tau_s: [3.0; 3],
    });
    let d = Duties {
        pla: 0.0,
        tca: tca_duty(1.0),
    };
    let amb = p.surroundings.ambient_c;
    let mut k = 0;
    for t_s in [5.0, 10.0, 20.0] {
        while (k as f64) * DT_S < t_s - 1e-9 {
            h.step(DT_S, d);
            l.step(DT_S, d);
            k += 1;
        }
        let (rh, rl) = (h.truth().tca_c - amb, l.truth().tca_c - amb);
        let ratio = rl / rh;
        eprintln!("{t_s} s: lumped {rl:.2} K, hifi {rh:.2} K, ratio {ratio:.3}");
        assert!(
            ratio > 1.1 && ratio < 1.6,
            "{t_s} s: lumped {rl} K hifi {rh} K ({ratio})"
        );
    }
}

#[test]
fn reduced_and_full_grids_agree_over_heating_and_cooling() {
    let p = LinkParams::DEFAULT;
    let mut full = Hifi::new(HifiSpec::nominal(p, Grid::Full).unwrap()).unwrap();
    let mut red = Hifi::new(HifiSpec::nominal(p, Grid::Reduced).unwrap()).unwrap();
    let amb = p.surroundings.ambient_c;
    let d_on = Duties {
        pla: pla_duty(4.0),
        tca: tca_duty(1.0),
    };
    // Series of PLA bead, TCA bead, rod mean, TCA mean: full and reduced.
    let (mut a, mut b) = (vec![Vec::new(); 4], vec![Vec::new(); 4]);
    for k in 0..300 {
        let d = if k < 200 { d_on } else { Duties::default() };
        full.step(DT_S, d);
        red.step(DT_S, d);
        for (series, h) in [(&mut a, &full), (&mut b, &red)] {
            let (s, t) = (h.sample(), h.truth());
            for (v, x) in series
                .iter_mut()
                .zip([s.t_pla_c, s.t_tca_c, t.pla_c, t.tca_c])
            {
                v.push(x - amb);
            }
        }
    }
    // Largest difference over the run relative to the quantity's largest rise.
    let mut worst: f64 = 0.0;
    for (x, y) in a.iter().zip(&b) {
        let peak = x.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let diff = x
            .iter()
            .zip(y)
            .fold(0.0f64, |m, (u, v)| m.max((u - v).abs()));
        worst = worst.max(diff / peak);
    }
    eprintln!(
        "reduced ({} modes) vs full: worst {worst:.2e} of the peak rise",
        red.section().rom_order().unwrap_or(0)
    );
    assert!(worst < 0.02, "worst relative difference {worst}");
    assert!(red.section().rom_order().is_some() && full.section().rom_order().is_none());
    // And a whole morph lands at the same radius.
    morph(&mut full, 1.0, 10.0);
    morph(&mut red, 1.0, 10.0);
    let (a, b) = (full.sample().radius_mm, red.sample().radius_mm);
    eprintln!("morph at 1 W: full {a:.3} mm, reduced {b:.3} mm");
    assert!((a - b).abs() < 0.005 * a, "full {a} mm reduced {b} mm");
}

#[test]
fn draws_are_reproducible_and_the_table_misses_by_about_one_percent() {
    let p = LinkParams::DEFAULT;
    let a = HifiSpec::draw(p, Grid::Rings(8), 7, 3).unwrap();
    let b = HifiSpec::draw(p, Grid::Rings(8), 7, 3).unwrap();
    assert_eq!(a, b);
    assert_ne!(a, HifiSpec::draw(p, Grid::Rings(8), 7, 4).unwrap());
    let powers: Vec<f64> = (0..p.table_entries)
        .map(|i| power_of_entry_w(&p, i))
        .collect();
    let (mut sq, mut n, mut worst) = (0.0, 0.0, 0.0f64);
    let mut air = 0;
    for i in 0..40 {
        let s = HifiSpec::draw(p, Grid::Rings(8), 11, i).unwrap();
        assert!((spec::TG_RANGE_C.0..=spec::TG_RANGE_C.1).contains(&s.pla.tg_c));
        let e = s.silicone_e_pa;
        assert!((spec::SILICONE_E_RANGE_PA.0..=spec::SILICONE_E_RANGE_PA.1).contains(&e));
        assert!((10.8..=13.2).contains(&s.supply_v));
        air += (s.medium == Medium::Air) as usize;
        let truth = s.steady_radii_mm(&powers).unwrap();
        for (pw, r) in powers.iter().zip(truth) {
            let miss = radius_mm(&p, *pw) / r - 1.0;
            sq += miss * miss;
            n += 1.0;
            worst = worst.max(miss.abs());
        }
    }
    let rms = (sq / n).sqrt();
    eprintln!("table miss over 40 links: RMS {rms:.4}, worst {worst:.4}, {air} in air");
    assert!(rms > 0.005 && rms < 0.015, "RMS miss {rms}");
    assert!(worst < 0.03, "worst miss {worst}");
    assert!(air < 12, "{air} of 40 in air");
}

#[test]
fn medium_and_ambient_settings_change_the_link() {
    let mut water = link(8);
    let mut air = link(8);
    air.set(Setting::Medium(Medium::Air)).unwrap();
    let d = Duties {
        pla: 0.0,
        tca: tca_duty(0.5),
    };
    run(&mut water, 30.0, d);
    run(&mut air, 30.0, d);
    assert!(air.truth().tca_c > water.truth().tca_c + 1.0);
    let mut warm = link(8);
    warm.set(Setting::AmbientC(30.0)).unwrap();
    warm.set(Setting::SupplyV(11.0)).unwrap();
    run(&mut warm, 120.0, Duties::default());
    assert!((warm.sample().t_amb_c - 30.0).abs() < 0.5);
    assert!((warm.truth().pla_c - 30.0).abs() < 1.0);
    assert_eq!(warm.sample().supply_v, 11.0);
}

/// Cost per simulated second at the 0.1 s tick, full and reduced grids: run with
/// `cargo test -p morphlink-plant --features hifi --release -- --ignored --nocapture cost`.
#[test]
#[ignore]
fn cost_per_simulated_second() {
    let p = LinkParams::DEFAULT;
    for grid in [Grid::Full, Grid::Reduced] {
        let t0 = std::time::Instant::now();
        let mut h = Hifi::new(HifiSpec::nominal(p, grid).unwrap()).unwrap();
        let build = t0.elapsed().as_secs_f64();
        let r0 = h.sample().radius_mm;
        let t1 = std::time::Instant::now();
        morph(&mut h, 1.0, 60.0);
        let run = t1.elapsed().as_secs_f64();
        println!(
            "{grid:?}: paper morph at 1 W from {r0:.2} mm to {:.2} mm (table {:.2} mm)",
            h.sample().radius_mm,
            radius_mm(&p, 1.0)
        );
        println!(
            "{grid:?}: {} rings, {} cells: build {:.1} ms, {:.2} ms per simulated s, a 180 s morph {:.0} ms",
            grid.rings(),
            h.section().grid().cells(),
            build * 1e3,
            run / 180.0 * 1e3,
            run * 1e3
        );
    }
}

#[test]
fn the_heaters_resistances_follow_their_temperatures_and_the_tca_its_strain() {
    let mut h = link(8);
    let [pla0, tca0] = h.sample().heater_ohm.unwrap();
    assert_eq!([pla0, tca0], h.heater_ohm_now());
    let d = Duties {
        pla: 0.6,
        tca: tca_duty(1.0),
    };
    for _ in 0..600 {
        h.step(0.1, d);
    }
    let t = h.truth();
    let [pla, tca] = h.sample().heater_ohm.unwrap();
    let s = h.spec();
    // The wrap: only its small coefficient over the rod's rise.
    let want_pla =
        s.pla_heater_ohm * (1.0 + s.pla_heater_tcr_per_k * (t.pla_c - spec::TCA_R_REF_C));
    assert!(
        (pla - want_pla).abs() < 1e-9 && pla > pla0,
        "{pla} {want_pla}"
    );
    // The TCA: its temperature term and its strain term, the bend shortening the coil.
    let strain = h.tca_strain();
    assert!(strain < 0.0, "a tighter bend shortens the coil: {strain}");
    let want_tca = s.tca.r_ref_ohm
        * (1.0 + s.tca.tcr_per_k * (t.tca_c - spec::TCA_R_REF_C) + s.tca.gauge * strain);
    assert!((tca - want_tca).abs() < 1e-9, "{tca} {want_tca}");
    // Power is duty x V^2 / R at the resistance of the step's start.
    assert!(t.tca_w < tca_duty(1.0) * s.supply_v * s.supply_v / tca0);
}

//! The controller on the high-fidelity plant (`cargo test -p morphlink-sim --features hifi`): a
//! link not built from the controller's own equations. These hold that the rig drives it to an
//! outcome within the plant's limits; the outcomes and errors they print are the measurement the
//! lumped plant cannot give (docs/plant.md, "The controller on the hifi link"). The morph and
//! safety suites (`tests/morph.rs`, `tests/safety.rs`) run on the nominal hifi link too and
//! assert its measured false alarms and radius errors; these stay for `run_morph_on` over a
//! `Rig<Hifi>` and for drawn links.
#![cfg(feature = "hifi")]

use morphlink::bench::Noise;
use morphlink::protocol::Mode;
use morphlink_model::LinkParams;
use morphlink_plant::hifi::{Grid, Hifi, HifiSpec};
use morphlink_sim::ensemble::{run_morph_on, Outcome};
use morphlink_sim::Rig;

fn rig(spec: HifiSpec) -> Rig<Hifi> {
    Rig::with_plant(Hifi::new(spec).unwrap(), Noise::NOMINAL)
}

#[test]
fn the_rig_drives_the_nominal_hifi_link_to_an_outcome() {
    let spec = HifiSpec::nominal(LinkParams::DEFAULT, Grid::Reduced).unwrap();
    for mode in [Mode::Paper, Mode::Gated, Mode::Closed] {
        let r = run_morph_on(rig(spec), 38.0, mode, &mut |_| {});
        eprintln!("{mode:?}: {r:?}");
        assert!(
            matches!(r.outcome, Outcome::Done | Outcome::Fault(_)),
            "{r:?}"
        );
        // The wrap heated the rod, and nothing ran away.
        assert!(r.max_true_c[0] > 60.0, "{r:?}");
        assert!(r.max_true_c[0] < 150.0 && r.max_true_c[1] < 150.0, "{r:?}");
        if r.outcome == Outcome::Done {
            assert!(r.error_pct.abs() < 25.0, "{r:?}");
        }
    }
}

#[test]
fn the_rig_drives_drawn_hifi_links_to_an_outcome() {
    for i in 0..3 {
        let spec = HifiSpec::draw(LinkParams::DEFAULT, Grid::Reduced, 42, i).unwrap();
        let r = run_morph_on(rig(spec), 40.0, Mode::Gated, &mut |_| {});
        eprintln!(
            "draw {i} ({:?}, h x{:.2}, {:.1} C): {r:?}",
            spec.medium, spec.h_scale, spec.ambient_c
        );
        assert!(
            matches!(r.outcome, Outcome::Done | Outcome::Fault(_)),
            "{r:?}"
        );
        assert!(r.max_true_c[0] < 150.0 && r.max_true_c[1] < 150.0, "{r:?}");
    }
}

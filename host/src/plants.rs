//! The in-process plants a shell can pick by name (`morph-sim --plant`, `morph-plant --plant`).
//!
//! The one place that maps a name to a plant.

use morphlink_plant::hifi::{Grid, Hifi, HifiSpec};
use morphlink_plant::Plant;
use morphlink_sim::LinkSetup;

/// An in-process plant, by name.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum PlantKind {
    /// The lumped link (`morphlink_plant::Lumped`): the nominal link of `morph-sim`.
    Lumped,
    /// The high-fidelity link (`morphlink_plant::hifi`) of the same parameters, on the full
    /// finite-volume grid: structurally different from the controller's model.
    Hifi,
}

/// The plant `kind` for the nominal link `setup`, or why it cannot be had.
pub fn in_process(kind: PlantKind, setup: &LinkSetup) -> Result<Box<dyn Plant>, String> {
    match kind {
        PlantKind::Lumped => Ok(Box::new(setup.lumped())),
        PlantKind::Hifi => {
            let spec = HifiSpec::nominal(setup.params, Grid::Full)
                .map_err(|e| format!("the hifi plant cannot be built: {e}"))?;
            let plant =
                Hifi::new(spec).map_err(|e| format!("the hifi plant cannot be built: {e}"))?;
            Ok(Box::new(plant))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn both_plants_are_built_in_and_start_at_rest() {
        let p = in_process(PlantKind::Lumped, &LinkSetup::NOMINAL).unwrap();
        assert_eq!(p.sample(), LinkSetup::NOMINAL.lumped().sample());
        let h = in_process(PlantKind::Hifi, &LinkSetup::NOMINAL).unwrap();
        let (s, amb) = (h.sample(), LinkSetup::NOMINAL.params.surroundings.ambient_c);
        // At rest every bead reads the ambient (within its R25/Beta tolerance).
        for t in [s.t_pla_c, s.t_tca_c, s.t_amb_c] {
            assert!((t - amb).abs() < 1.0, "{s:?}");
        }
        assert_ne!(s.radius_mm, p.sample().radius_mm, "two different links");
    }
}

//! The in-process plants a shell can pick by name (`morph-sim --plant`, `morph-plant --plant`).
//!
//! The one place that maps a name to a plant. The high-fidelity plant
//! (`morphlink_plant::hifi::Hifi`, behind the plant crate's `hifi` feature) is not built in
//! yet: wiring it in is the `PlantKind::Hifi` arm of [`in_process`] and the `hifi` feature on
//! the `morphlink-plant` dependency in `host/Cargo.toml`.

use morphlink_plant::Plant;
use morphlink_sim::LinkSetup;

/// An in-process plant, by name.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum PlantKind {
    /// The lumped link (`morphlink_plant::Lumped`): the nominal link of `morph-sim`.
    Lumped,
    /// The high-fidelity link (`morphlink_plant::hifi`): not built in yet.
    Hifi,
}

/// Why `hifi` is refused until it is built in.
pub const HIFI_NOT_BUILT: &str = "the hifi plant is not built in (this build has no \
     morphlink_plant::hifi; build with the plant crate's `hifi` feature once it exists)";

/// The plant `kind` for the nominal link `setup`, or why it cannot be had.
pub fn in_process(kind: PlantKind, setup: &LinkSetup) -> Result<Box<dyn Plant>, String> {
    match kind {
        PlantKind::Lumped => Ok(Box::new(setup.lumped())),
        PlantKind::Hifi => Err(HIFI_NOT_BUILT.to_string()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn lumped_is_built_in_and_hifi_says_it_is_not() {
        let p = in_process(PlantKind::Lumped, &LinkSetup::NOMINAL).unwrap();
        assert_eq!(p.sample(), LinkSetup::NOMINAL.lumped().sample());
        let e = in_process(PlantKind::Hifi, &LinkSetup::NOMINAL)
            .err()
            .unwrap();
        assert!(e.starts_with("the hifi plant is not built in"), "{e}");
    }
}

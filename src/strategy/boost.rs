//! `boost`: the controller's thermal model driven open loop (feed-forward) to the target
//! temperatures with overdrive, then the steady power; soften and lock are gated on the bare
//! thermistors, bend on the model.

use super::model::observer::HeatedNode;
use super::model::{target, ModelDrive, PlaView};
use super::{Start, Strategy, TargetTemps, Tick, RELEASE_S};
use crate::vocab::{Measurements, Phase, Powers};

/// The `boost` strategy.
#[derive(Clone, Copy, Debug)]
pub struct Boost {
    /// The model it drives.
    pub drive: ModelDrive,
    /// This link's TCA map from MEASURED reports (see
    /// [`crate::calibration::Calibration::map`]).
    map: (f32, f32),
}

impl Boost {
    /// For a morph starting as `s` says: the TCA aims at the radius's temperature.
    pub fn new(s: &Start) -> Self {
        let map = s.cal.map();
        let need = target::tca_temp_for_radius_c(s.radius_mm);
        Boost {
            drive: ModelDrive::new(s, target::calibrated_aim_c(map, need, s.m.t_amb_c)),
            map,
        }
    }
}

impl Strategy for Boost {
    fn enter(&mut self, _phase: Phase, _now_ms: u64) {
        self.drive.enter();
    }

    fn phase_done(&mut self, t: &Tick) -> bool {
        self.drive.observe(t.now_ms, t.m);
        let o = self.drive.observer();
        let (pla_c, tca_c) = (o.model_c(HeatedNode::Pla), o.model_c(HeatedNode::Tca));
        match t.phase {
            Phase::Soften => t.m.t_pla_c >= t.th.soft_threshold_c,
            Phase::Bend => {
                let pla = PlaView {
                    learnt: true,
                    cold: false,
                };
                self.drive.bend_done(t, pla_c, tca_c, true, pla)
            }
            Phase::Lock => t.m.t_pla_c < t.th.rigid_threshold_c,
            Phase::Release => t.in_phase_s >= RELEASE_S,
            Phase::Idle | Phase::Rest | Phase::Fault => false,
        }
    }

    fn radius_estimate_mm(&self, m: &Measurements) -> f32 {
        let tca_c = self.drive.observer().model_c(HeatedNode::Tca);
        target::calibrated_final_radius_mm(self.map, tca_c, m.t_amb_c)
    }

    fn powers(&mut self, phase: Phase, t: &Tick) -> Powers {
        self.drive.powers(phase, t, 0.0, 0.0)
    }

    fn targets_c(&self, phase: Phase) -> TargetTemps {
        self.drive.targets_c(phase)
    }
}

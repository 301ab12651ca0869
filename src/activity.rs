//! The controller's one activity slot: idle, a morph, a `TUNE` or a `HEAT` pulse, never two at
//! once. Each starts only from idle (a pulse may replace a pulse), and every end (done, ABORT,
//! a trip, its own clock) goes back to idle, so the refusal rule, ABORT and a trip each have
//! one place ([`Activity::refusal`], [`Activity::stop`]).

use crate::pulse::Pulse;
use crate::tune::Tune;
use crate::vocab::{Doing, Phase};

/// What runs now. A morph's progress lives in the [`crate::sequencer::Sequencer`], which also
/// keeps the last morph's target and strategy for STATUS after it ends; the slot says that one
/// runs.
#[derive(Clone, Debug, Default)]
// One slot without an allocator: the variants share its storage by design (a TUNE's record is
// the large one), and only one ever runs.
#[allow(clippy::large_enum_variant)]
pub enum Activity {
    /// Nothing: both heaters off.
    #[default]
    Idle,
    /// A morph (the sequencer runs it).
    Morph,
    /// A `TUNE` under way.
    Tune(Tune),
    /// A `HEAT` pulse.
    Heat(Pulse),
}

/// What a command wants to start, for [`Activity::refusal`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Start {
    /// `MORPH`.
    Morph,
    /// `TUNE`.
    Tune,
    /// `HEAT` (which may replace a running pulse).
    Heat,
    /// A change of the settings (`CONFIG SET`, `CONFIG RESET`, `SAVE`).
    Change,
    /// `MEASURED` (a change of the calibration, refused in the words of what runs).
    Measured,
}

/// Why a command cannot start now: the activity in its way.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Busy {
    /// A morph runs, in this phase.
    Morphing(Phase),
    /// A `TUNE` runs.
    Tuning,
    /// A `HEAT` pulse runs.
    Heating,
}

impl Activity {
    /// What the supervisor is told; `phase` is the sequencer's (read only for a morph).
    pub fn doing(&self, phase: Phase) -> Doing {
        match self {
            Activity::Idle => Doing::Idle,
            Activity::Morph => Doing::from(phase),
            Activity::Tune(_) => Doing::Tune,
            Activity::Heat(p) => Doing::Heat(p.heater),
        }
    }

    /// True unless idle.
    pub fn busy(&self) -> bool {
        !matches!(self, Activity::Idle)
    }

    /// The one refusal rule: whatever runs refuses every start, except that a pulse replaces a
    /// pulse. `phase` is the sequencer's.
    pub fn refusal(&self, start: Start, phase: Phase) -> Option<Busy> {
        match (self, start) {
            (Activity::Idle, _) | (Activity::Heat(_), Start::Heat) => None,
            (Activity::Morph, _) => Some(Busy::Morphing(phase)),
            (Activity::Tune(_), _) => Some(Busy::Tuning),
            (Activity::Heat(_), _) => Some(Busy::Heating),
        }
    }

    /// Ends whatever runs (ABORT, a trip, the end of its own work): the slot is idle after it.
    /// Returns what ran, so the caller can say how it ended.
    pub fn stop(&mut self) -> Activity {
        core::mem::take(self)
    }

    /// The running TUNE, if one runs.
    pub fn tune(&self) -> Option<&Tune> {
        match self {
            Activity::Tune(t) => Some(t),
            _ => None,
        }
    }

    /// The running pulse, if one runs.
    pub fn pulse(&self) -> Option<&Pulse> {
        match self {
            Activity::Heat(p) => Some(p),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::vocab::Heater;

    #[test]
    fn only_a_pulse_replaces_a_pulse_and_idle_refuses_nothing() {
        let pulse = Pulse::new(0, Heater::Pla, 0.5, 5.0).unwrap();
        let starts = [
            Start::Morph,
            Start::Tune,
            Start::Heat,
            Start::Change,
            Start::Measured,
        ];
        for s in starts {
            assert_eq!(Activity::Idle.refusal(s, Phase::Idle), None);
            assert_eq!(
                Activity::Morph.refusal(s, Phase::Bend),
                Some(Busy::Morphing(Phase::Bend))
            );
            let want = (s != Start::Heat).then_some(Busy::Heating);
            assert_eq!(Activity::Heat(pulse).refusal(s, Phase::Idle), want);
        }
    }

    #[test]
    fn stop_leaves_the_slot_idle_and_says_what_ran() {
        let mut a = Activity::Heat(Pulse::new(0, Heater::Tca, 0.2, 5.0).unwrap());
        assert_eq!(a.doing(Phase::Idle), Doing::Heat(Heater::Tca));
        assert!(matches!(a.stop(), Activity::Heat(_)));
        assert!(!a.busy());
        assert_eq!(a.doing(Phase::Bend), Doing::Idle);
        assert_eq!(
            Activity::Morph.doing(Phase::Lock),
            Doing::Morph(Phase::Lock)
        );
    }
}

//! Alarm lines: each fault's code, subject and the sentence that says what it means, what to
//! check and which settings and doc explain it.

use super::*;

/// The alarm line of a trip: `alarm: <code> <sentence>; heaters off, RESET when cleared
/// (<settings>; see docs/safety.md)`, naming the settings that govern it and the doc whose
/// `SAFETY_DOC_SECTION` explains them (Klipper's habit; the heading is left out to keep
/// the line within its cap).
pub fn alarm(l: &mut OutLine, f: &Fault) {
    let _ = write!(
        l,
        "{ALARM_TAG} {}; heaters off, RESET when cleared ({}; see {SAFETY_DOC})",
        FaultText(f),
        f.settings()
    );
}

/// The word of a fault's subject.
fn subject_str(s: &Subject) -> &'static str {
    match s {
        Subject::Sensor(x) => x.as_str(),
        Subject::Heater(h) => h.as_str(),
        Subject::Phase(p) => p.as_str(),
        Subject::Supply => "supply",
        Subject::Frame => "sensors",
    }
}

/// `<code> <sentence>` for a fault (alarms and `fault-active`).
pub(super) struct FaultText<'a>(pub(super) &'a Fault);

impl fmt::Display for FaultText<'_> {
    fn fmt(&self, l: &mut fmt::Formatter<'_>) -> fmt::Result {
        let f = self.0;
        let s = subject_str(&f.subject);
        let v = Fixed(f.value, 1);
        match f.code {
            FaultCode::ThermistorOpen => write!(
                l,
                "thermistor-open {s} thermistor reads open circuit; check its wiring"
            ),
            FaultCode::ThermistorShort => write!(
                l,
                "thermistor-short {s} thermistor reads short circuit; check its wiring"
            ),
            FaultCode::UnderTemperature => {
                write!(l, "under-temperature {s} reads {v} C, below its minimum")
            }
            FaultCode::OverTemperature if matches!(f.subject, Subject::Heater(_)) => write!(
                l,
                "over-temperature {s} part estimated {v} C from its thermistor, above its maximum"
            ),
            FaultCode::OverTemperature => {
                write!(l, "over-temperature {s} reads {v} C, above its maximum")
            }
            FaultCode::HeaterNotHeating => {
                write!(l, "heater-not-heating {s} reads {v} K under what its power gives; check wiring, MOSFET")
            }
            FaultCode::HeatingWhileOff => {
                write!(
                    l,
                    "heating-while-off {s} reads {v} K over what its power gives; check its MOSFET"
                )
            }
            FaultCode::StaleSensor => write!(l, "stale-sensor no sensor frame for {v} s"),
            FaultCode::SupplyOutOfRange => write!(
                l,
                "supply-out-of-range supply reads {v} V, allowed {}..{}",
                Fixed(SUPPLY_MIN_V, 1),
                Fixed(SUPPLY_MAX_V, 1)
            ),
            // A lock carries the PLA's reading: a rod this warm cannot hold the radius here.
            FaultCode::PhaseTimeout if f.value.is_finite() => write!(
                l,
                "phase-timeout phase {s} did not finish: pla stays at {v} C, too warm to hold this radius here; morph larger or cool the link"
            ),
            FaultCode::PhaseTimeout => write!(l, "phase-timeout phase {s} did not finish in time"),
            FaultCode::SensorFrozen => {
                write!(l, "sensor-frozen {s} moved {v} K")
            }
            FaultCode::SensorImplausible if f.subject == Subject::Sensor(Sensor::Amb) => {
                write!(
                    l,
                    "sensor-implausible {s} drifts {} K/s steadily",
                    Fixed(f.value, 2)
                )
            }
            FaultCode::SensorImplausible => {
                write!(l, "sensor-implausible {s} off its expected rise by {v} K")
            }
            FaultCode::HeaterOpen => write!(
                l,
                "heater-open {s} heater carries {} A while driven; check its leads, MOSFET",
                Fixed(f.value, 2)
            ),
            FaultCode::HeaterShort => write!(
                l,
                "heater-short {s} heater carries {} A while off; its MOSFET conducts, supply cut",
                Fixed(f.value, 2)
            ),
            FaultCode::HeaterResistance => write!(
                l,
                "heater-resistance {s} heater reads {v} ohm, out of range; check it and its channel"
            ),
            FaultCode::CutoffFailed => write!(
                l,
                "cutoff-failed {} A flow with the cut-off open: CUT THE SUPPLY BY HAND",
                Fixed(f.value, 2)
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::supervisor::{Fault, FaultCode, Subject, SAFETY_DOC_SECTION};
    use crate::vocab::Phase;
    use crate::vocab::{Heater, Sensor};
    extern crate std;
    use std::format;
    use std::vec::Vec;

    /// [`SAFETY_DOC`] (`include_str!` takes only a literal; the test checks they agree).
    const SAFETY_DOC_TEXT: &str = include_str!("../../../docs/safety.md");

    /// Every kind of trip, with every subject it can have.
    fn every_fault() -> Vec<Fault> {
        let sensors = Sensor::ALL.map(Subject::Sensor);
        let phases = [
            Phase::Rest,
            Phase::Soften,
            Phase::Bend,
            Phase::Lock,
            Phase::Release,
        ]
        .map(Subject::Phase);
        let heaters = Heater::ALL.map(Subject::Heater);
        let cases: [(FaultCode, &[Subject]); 16] = [
            (FaultCode::ThermistorOpen, &sensors),
            (FaultCode::ThermistorShort, &sensors),
            (FaultCode::UnderTemperature, &sensors),
            (FaultCode::OverTemperature, &sensors),
            (FaultCode::OverTemperature, &heaters),
            (FaultCode::HeaterNotHeating, &heaters),
            (FaultCode::HeatingWhileOff, &heaters),
            (FaultCode::StaleSensor, &[Subject::Frame]),
            (FaultCode::SupplyOutOfRange, &[Subject::Supply]),
            (FaultCode::PhaseTimeout, &phases),
            (FaultCode::SensorFrozen, &sensors),
            (FaultCode::SensorImplausible, &sensors),
            (FaultCode::HeaterOpen, &heaters),
            (FaultCode::HeaterShort, &heaters),
            (FaultCode::HeaterResistance, &heaters),
            (FaultCode::CutoffFailed, &[Subject::Supply]),
        ];
        // Each with a value, and each phase timeout also without one (a lock's carries the
        // PLA's reading; the others none).
        let clock = phases.map(|subject| Fault {
            code: FaultCode::PhaseTimeout,
            subject,
            value: f32::NAN,
        });
        cases
            .iter()
            .flat_map(|(code, subjects)| {
                subjects.iter().map(move |&subject| Fault {
                    code: *code,
                    subject,
                    value: -123.4,
                })
            })
            .chain(clock)
            .collect()
    }

    #[test]
    fn a_phase_timeout_by_the_clock_says_so_and_a_lock_too_warm_names_its_reading() {
        let text = |phase, value| {
            let mut l = OutLine::new();
            alarm(
                &mut l,
                &Fault {
                    code: FaultCode::PhaseTimeout,
                    subject: Subject::Phase(phase),
                    value,
                },
            );
            l
        };
        let bend = text(Phase::Bend, f32::NAN);
        assert!(
            bend.starts_with("alarm: phase-timeout phase bend did not finish in time; ")
                && bend.contains("(BEND_TIMEOUT_S; "),
            "{bend}"
        );
        let warm = text(Phase::Lock, 60.04);
        assert!(
            warm.starts_with(
                "alarm: phase-timeout phase lock did not finish: pla stays at 60.0 C, too warm"
            ) && warm.contains("(LOCK_TIMEOUT_S, CLOSED_LOCK_SETTLE_TAU_S; "),
            "{warm}"
        );
    }

    /// The safety doc's section `heading` (a `## ` heading), up to the next `## ` heading.
    fn doc_section(heading: &str) -> &'static str {
        let start = SAFETY_DOC_TEXT
            .find(&format!("\n## {heading}\n"))
            .unwrap_or_else(|| panic!("{SAFETY_DOC} has no \"## {heading}\" heading"));
        let body = &SAFETY_DOC_TEXT[start + 1..];
        let end = body[3..].find("\n## ").map_or(body.len(), |e| e + 3);
        &body[..end]
    }

    #[test]
    fn every_alarm_names_its_settings_and_a_doc_section_that_explains_them() {
        assert_eq!(SAFETY_DOC, "docs/safety.md", "the doc the test reads");
        let section = doc_section(SAFETY_DOC_SECTION);
        for f in every_fault() {
            let mut l = OutLine::new();
            alarm(&mut l, &f);
            assert!(
                l.starts_with(&format!("alarm: {} ", f.code.as_str())),
                "{l}"
            );
            let tail = format!(
                "; heaters off, RESET when cleared ({}; see {SAFETY_DOC})",
                f.settings()
            );
            // Not truncated: the whole suffix fits the line.
            assert!(l.ends_with(&tail), "{l}");
            for setting in f.settings().split(", ") {
                assert!(
                    section.contains(&format!("`{setting}`")),
                    "{SAFETY_DOC} \"{SAFETY_DOC_SECTION}\" does not explain `{setting}` ({l})"
                );
            }
        }
    }
}

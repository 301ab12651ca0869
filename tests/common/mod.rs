//! Shared helpers of the integration tests: a rig that records every line it sends, on either
//! plant: the lumped link (the controller's own equations) or the high-fidelity link (built
//! from different physics; docs/plant.md).
#![allow(dead_code)]

/// One test per plant for each check `name(link)`: `name::lumped` and `name::hifi` (import
/// with `#[macro_use] mod common;`).
#[allow(unused_macros)]
macro_rules! on_both_links {
    ($($name:ident),* $(,)?) => {$(
        mod $name {
            use super::Link;
            #[test]
            fn lumped() {
                super::$name(Link::Lumped)
            }
            #[test]
            fn hifi() {
                super::$name(Link::Hifi)
            }
        }
    )*};
}

use std::sync::OnceLock;

use morphlink::bench::Noise;
use morphlink::controller::Outputs;
use morphlink::protocol::{classify, LineKind};
use morphlink::sequencer::{
    BEND_TIMEOUT_S, LOCK_TIMEOUT_S, RELEASE_TIMEOUT_S, REST_TIMEOUT_S, SOFTEN_TIMEOUT_S,
};
use morphlink::tune::TuneStep;
use morphlink::vocab::Phase;
use morphlink_plant::hifi::{Grid, Hifi, HifiSpec};
use morphlink_plant::Plant;
use morphlink_sim::{LinkSetup, Rig};

/// The simulated link a bench runs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Link {
    /// The nominal lumped link: the controller's own equations.
    Lumped,
    /// The nominal high-fidelity link of the same parameters on `Grid::Reduced` (its
    /// reduced-order form: within 5e-6 of the full grid's peak rise in beads and heater means,
    /// the same radius after a morph; docs/plant.md, "Cost").
    Hifi,
}

/// Both links, lumped first.
pub const LINKS: [Link; 2] = [Link::Lumped, Link::Hifi];

/// The nominal hifi link at rest, built once (its identification and reduced model take a
/// moment) and cloned for each bench.
fn nominal_hifi() -> Hifi {
    static LINK: OnceLock<Hifi> = OnceLock::new();
    LINK.get_or_init(|| {
        let spec = HifiSpec::nominal(LinkSetup::NOMINAL.params, Grid::Reduced).unwrap();
        Hifi::new(spec).unwrap()
    })
    .clone()
}

/// A rig plus the lines it has written.
pub struct Bench {
    pub rig: Rig<Box<dyn Plant>>,
    pub lines: Vec<String>,
}

impl Bench {
    /// The nominal lumped link.
    pub fn new() -> Self {
        Self::with_plant(LinkSetup::NOMINAL)
    }

    /// The nominal hifi link.
    pub fn hifi() -> Self {
        Self::on(Link::Hifi)
    }

    /// The nominal `link`.
    pub fn on(link: Link) -> Self {
        match link {
            Link::Lumped => Self::new(),
            Link::Hifi => Self::with_rig(Rig::with_plant(Box::new(nominal_hifi()), Noise::NOMINAL)),
        }
    }

    /// The nominal `link` in still air of convection `h_w_m2k` (W/(m² K)).
    pub fn in_air_at(link: Link, h_w_m2k: f64) -> Self {
        let h_scale = h_w_m2k / morphlink_model::params::H_AIR_W_M2K;
        match link {
            Link::Lumped => Self::with_plant(
                morphlink_sim::ensemble::Mismatch {
                    air: true,
                    h_scale,
                    ..morphlink_sim::ensemble::Mismatch::NONE
                }
                .plant(),
            ),
            Link::Hifi => {
                let mut spec = HifiSpec::nominal(LinkSetup::NOMINAL.params, Grid::Reduced).unwrap();
                spec.medium = morphlink_plant::Medium::Air;
                spec.h_scale = h_scale;
                Self::with_rig(Rig::with_plant(
                    Box::new(Hifi::new(spec).unwrap()),
                    Noise::NOMINAL,
                ))
            }
        }
    }

    /// The lumped link `plant`.
    pub fn with_plant(plant: LinkSetup) -> Self {
        Self::with_rig(Rig::with_plant(Box::new(plant.lumped()), plant.noise()))
    }

    /// The ensemble's hifi link `draw` (seed `seed`; the strategy and calibration charts'
    /// links), with its drawn noise.
    pub fn hifi_draw(seed: u64, draw: u64) -> Self {
        let (spec, noise) =
            morphlink_sim::ensemble::hifi_draw(seed, draw).expect("the ensemble's draws are valid");
        Self::with_rig(Rig::with_plant(
            Box::new(Hifi::new(spec).expect("a drawn link builds")),
            noise,
        ))
    }

    /// The nominal `link` wired wrong: `wiring` rewrites its bead temperatures on their way to
    /// the board (see [`Miswired`]).
    pub fn miswired(link: Link, wiring: Wiring) -> Self {
        let plant: Box<dyn Plant> = match link {
            Link::Lumped => Box::new(LinkSetup::NOMINAL.lumped()),
            Link::Hifi => Box::new(nominal_hifi()),
        };
        Self::with_rig(Rig::with_plant(
            Box::new(Miswired::new(plant, wiring)),
            Noise::NOMINAL,
        ))
    }

    /// The same bench on a board without current sense (the paper's wiring plus the cut-off):
    /// only the thermistors see the heaters.
    pub fn thermistors_only(mut self) -> Self {
        self.rig.bench.set_current_sense(false);
        self
    }

    fn with_rig(rig: Rig<Box<dyn Plant>>) -> Self {
        Bench {
            rig,
            lines: Vec::new(),
        }
    }

    /// Sends one line; returns the lines written in reply.
    pub fn send(&mut self, line: &str) -> Vec<String> {
        let mut reply = Vec::new();
        self.rig
            .handle_line(line, &mut |l| reply.push(l.to_string()));
        self.lines.extend(reply.iter().cloned());
        reply
    }

    /// One tick; returns the outputs and the event/alarm lines it produced.
    pub fn tick(&mut self) -> (Outputs, Vec<String>) {
        let out = self.rig.tick();
        let mut ev = Vec::new();
        self.rig.drain_events(&mut |l| ev.push(l.to_string()));
        self.lines.extend(ev.iter().cloned());
        (out, ev)
    }

    /// Ticks until `pred` holds or `max_s` of simulated time passes; true if it held.
    pub fn run_until(&mut self, max_s: f64, mut pred: impl FnMut(&Bench) -> bool) -> bool {
        let end = self.rig.now_ms() + (max_s * 1000.0) as u64;
        while self.rig.now_ms() < end {
            if pred(self) {
                return true;
            }
            self.tick();
        }
        pred(self)
    }

    /// Ticks until the TUNE in progress is in `step` (at most 200 s of simulated time); true if
    /// it got there. The one wait the TUNE tests share before they act inside a step.
    pub fn run_to_tune_step(&mut self, step: TuneStep) -> bool {
        self.run_until(200.0, |b| b.rig.ctrl.tune_step() == Some(step))
    }

    /// Runs TUNE to its end; returns the line that ended it (`event: tune done ...` or
    /// `... failed ...`).
    pub fn tune_to_end(&mut self) -> String {
        let total_s = morphlink::tune::TUNE_TOTAL_S;
        assert_eq!(self.send("TUNE"), [format!("ok total_s={total_s:.0}")]);
        let from = self.lines.len();
        assert!(
            self.run_until(total_s as f64 + 5.0, |b| !b.rig.ctrl.tuning()),
            "tune did not end: {:?}",
            &self.lines[from..]
        );
        self.lines[from..]
            .iter()
            .rev()
            .find(|l| l.starts_with("event: tune done") || l.starts_with("event: tune failed"))
            .cloned()
            .unwrap_or_else(|| panic!("no end line: {:?}", &self.lines[from..]))
    }

    /// Ticks for `s` seconds of simulated time.
    pub fn run_for(&mut self, s: f64) {
        let end = self.rig.now_ms() + (s * 1000.0) as u64;
        while self.rig.now_ms() < end {
            self.tick();
        }
    }

    pub fn phase(&self) -> Phase {
        self.rig.ctrl.phase()
    }

    /// Starts a morph (asserting `ok`) and runs until the controller is idle again; returns its
    /// time, s.
    pub fn morph(&mut self, radius_mm: f32, mode: &str) -> f64 {
        self.morph_peaks(radius_mm, mode).0
    }

    /// As [`Bench::morph`], and the peak true temperatures over the morph (the PLA rod's mean,
    /// the TCA's mean), °C.
    pub fn morph_peaks(&mut self, radius_mm: f32, mode: &str) -> (f64, [f64; 2]) {
        let r = self.send(&format!("MORPH {radius_mm} {mode}"));
        assert_eq!(r, ["ok"], "MORPH {radius_mm} {mode}");
        let t0 = self.rig.now_ms();
        let mut peak_c = [f64::NEG_INFINITY; 2];
        // Every phase may run to its timeout (a still-air lock takes minutes).
        let max_s = (REST_TIMEOUT_S
            + SOFTEN_TIMEOUT_S
            + BEND_TIMEOUT_S
            + LOCK_TIMEOUT_S
            + RELEASE_TIMEOUT_S) as f64;
        assert!(
            self.run_until(max_s + 10.0, |b| {
                let t = b.rig.plant().truth();
                peak_c = [peak_c[0].max(t.pla_c), peak_c[1].max(t.tca_c)];
                !b.rig.ctrl.busy()
            }),
            "morph did not finish: {:?}",
            self.lines
        );
        ((self.rig.now_ms() - t0) as f64 / 1000.0, peak_c)
    }

    /// Runs until the next `event: shape` line (docs/shape.md), at most `max_s`; the line.
    #[allow(dead_code)]
    pub fn rest_until_shape(&mut self, max_s: f64) -> String {
        let from = self.lines.len();
        let found = |b: &Bench| {
            b.lines[from..]
                .iter()
                .any(|l| l.starts_with("event: shape"))
        };
        assert!(self.run_until(max_s, found), "no shape line in {max_s} s");
        let line = self.lines[from..]
            .iter()
            .find(|l| l.starts_with("event: shape"));
        line.cloned().unwrap_or_default()
    }

    /// Alarm lines written since line `from` of [`Bench::lines`].
    pub fn alarms_since(&self, from: usize) -> Vec<String> {
        self.lines[from..]
            .iter()
            .filter(|l| classify(l) == LineKind::Alarm)
            .cloned()
            .collect()
    }

    /// A known false alarm, measured: exactly one alarm since line `from`, starting with
    /// `start`, raised `t_s` after MORPH where `at_s` was measured (within 0.3 s).
    pub fn assert_known_alarm(&self, from: usize, start: &str, t_s: f64, at_s: f64) {
        let alarms = self.alarms_since(from);
        assert_eq!(
            alarms.len(),
            1,
            "one alarm, {start}...: {:?}",
            &self.lines[from..]
        );
        assert!(alarms[0].starts_with(start), "{start}...: {}", alarms[0]);
        assert!(
            (t_s - at_s).abs() < 0.3,
            "{}: at {t_s} s, not {at_s}",
            alarms[0]
        );
    }

    /// Phase names announced by `event: phase` lines so far.
    pub fn phases(&self) -> Vec<String> {
        self.lines
            .iter()
            .filter_map(|l| {
                l.strip_prefix("event: phase ")
                    .map(|r| r.split(' ').next().unwrap().to_string())
            })
            .collect()
    }

    /// Value of `key=` in a reply line.
    pub fn field(line: &str, key: &str) -> Option<String> {
        line.split(' ')
            .find_map(|w| w.strip_prefix(&format!("{key}=")).map(str::to_string))
    }

    /// Every alarm line so far.
    #[allow(dead_code)]
    pub fn alarms(&self) -> Vec<String> {
        self.alarms_since(0)
    }
}

/// A wiring fault between the link and the board's thermistor inputs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Wiring {
    /// The PLA and TCA thermistors swapped.
    Swapped,
    /// The PLA thermistor come off its heater: it reads the silicone's surface, a fifth of what
    /// the PLA bead in place would read above the bath, a minute behind.
    PlaOffItsHeater,
}

/// A plant seen through a wiring fault (the plant itself is healthy).
pub struct Miswired {
    plant: Box<dyn Plant>,
    wiring: Wiring,
    /// The off-heater bead's lagged temperature, °C.
    off_c: Option<f64>,
}

impl Miswired {
    /// The time constant of a bead off its heater, s.
    pub const OFF_TAU_S: f64 = 60.0;
    /// The share of the rod's rise a bead off its heater sees.
    pub const OFF_SHARE: f64 = 0.2;

    pub fn new(plant: Box<dyn Plant>, wiring: Wiring) -> Self {
        Miswired {
            plant,
            wiring,
            off_c: None,
        }
    }
}

impl Plant for Miswired {
    fn step(&mut self, dt_s: f64, duty: morphlink_plant::Duties) {
        self.plant.step(dt_s, duty);
        let s = self.plant.sample();
        let to = s.t_amb_c + Self::OFF_SHARE * (s.t_pla_c - s.t_amb_c);
        let c = self.off_c.get_or_insert(to);
        *c += (to - *c) * (dt_s / Self::OFF_TAU_S).min(1.0);
    }
    fn sample(&self) -> morphlink_plant::Sample {
        let mut s = self.plant.sample();
        match self.wiring {
            Wiring::Swapped => std::mem::swap(&mut s.t_pla_c, &mut s.t_tca_c),
            Wiring::PlaOffItsHeater => s.t_pla_c = self.off_c.unwrap_or(s.t_amb_c),
        }
        s
    }
    fn truth(&self) -> morphlink_plant::Truth {
        self.plant.truth()
    }
    fn set(&mut self, setting: morphlink_plant::Setting) -> Result<(), morphlink_plant::SetError> {
        self.plant.set(setting)
    }
    fn failure(&self) -> Option<&str> {
        self.plant.failure()
    }
}

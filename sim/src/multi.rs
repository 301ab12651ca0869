//! Several links on one simulated board and one shared bench supply: the core's
//! [`Links`] driving one plant per link, each on its own [`Bench`], all fed by a
//! [`SharedSupply`] with an internal resistance and a current limit (constant-current mode),
//! so a load past the limit sags the supply as it would on a bench.
//!
//! Each period the heaters' on-windows are laid out where the core's scheduler phased them;
//! the supply's voltage is worked out piece by piece over the period (every piece has its own
//! set of heaters on), and each plant is stepped with the duty that gives it the energy it
//! really got: `Σ piece · (V_piece / V_open)²` of each heater's window, at the open-circuit
//! voltage the plant is set to. The boards read the period's mean terminal voltage, and each
//! heater's on-current just inside its own window, at the voltage there.

use morphlink::bench::{Bench, Noise, SIM_WAIT_MAX_S};
use morphlink::budget::MAX_LINKS;
use morphlink::controller::{Config, Inputs, TICK_MS};
use morphlink::links::{LinkOutputs, Links};
use morphlink::protocol::{reply, OutLine, SimCommand, SimFault};
use morphlink::vocab::Sensor;
use morphlink_plant::{Duties, Plant, Setting};

/// Most heater windows of one period.
const WINDOWS: usize = 2 * MAX_LINKS;
/// Where in its window a board samples a heater's on-current, share of the PWM period: 5 µs
/// in, inside the current-sense probe's 10 µs pulse (`morphlink::electrical::MIN_SENSED_ON_US`).
const SAMPLE_INSIDE: f64 = 0.005;

/// `x` wrapped into [0, 1).
fn wrap(x: f64) -> f64 {
    x - libm::floor(x)
}

/// A bench supply shared by every link.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SharedSupply {
    /// Open-circuit voltage, V.
    pub open_v: f64,
    /// Internal (source and wiring) resistance, Ω.
    pub internal_ohm: f64,
    /// Constant-current limit, A: at more load the voltage falls to hold it.
    pub limit_a: f64,
}

impl SharedSupply {
    /// A 12 V bench supply with 0.1 Ω of leads and 10 A to give: stiff, never in its limit.
    pub const STIFF: SharedSupply = SharedSupply {
        open_v: 12.0,
        internal_ohm: 0.1,
        limit_a: 10.0,
    };

    /// Terminal voltage with conductance `g_s` (S) switched on, V.
    pub fn volts(&self, g_s: f64) -> f64 {
        if g_s <= 0.0 {
            return self.open_v;
        }
        let v = self.open_v / (1.0 + self.internal_ohm * g_s);
        if v * g_s > self.limit_a {
            self.limit_a / g_s
        } else {
            v
        }
    }
}

/// What the shared supply did over one period.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SupplyTick {
    /// The heaters' summed true power over the period, W (the plants' own).
    pub power_w: f64,
    /// The heaters' summed power as the controllers reckon it (their powers), W.
    pub reckoned_w: f64,
    /// Highest instantaneous current of the period, A (at most the supply's limit).
    pub peak_a: f64,
    /// Highest current the heaters on at once would draw from the supply without its limit,
    /// A: past the limit the supply sags instead.
    pub demand_a: f64,
    /// Mean terminal voltage over the period, V.
    pub mean_v: f64,
    /// Lowest terminal voltage of the period, V.
    pub min_v: f64,
}

/// The board's links, their benches and plants, the shared supply and a clock.
pub struct MultiRig<P> {
    /// The core under test.
    pub links: Links<MAX_LINKS>,
    /// Link `k`'s plant on its board channel.
    pub benches: heapless::Vec<Bench<P>, MAX_LINKS>,
    /// The supply every link shares.
    pub supply: SharedSupply,
    /// The last period's supply record.
    pub last: SupplyTick,
    outs: [LinkOutputs; MAX_LINKS],
    now_ms: u64,
    waited_ms: u64,
}

impl<P: Plant> MultiRig<P> {
    /// One link per plant (1 to [`MAX_LINKS`]), each with its own noise seed, on `supply`;
    /// after one control tick.
    pub fn new(plants: impl IntoIterator<Item = P>, noise: Noise, supply: SharedSupply) -> Self {
        let board = Config::DEFAULT;
        let mut benches = heapless::Vec::new();
        for (k, mut p) in plants.into_iter().enumerate() {
            let _ = p.set(Setting::SupplyV(supply.open_v));
            let seed = noise.seed.wrapping_add(0x9e37_79b9 * k as u64);
            if benches
                .push(Bench::new(p, board, Noise { seed, ..noise }))
                .is_err()
            {
                panic!("at most {MAX_LINKS} links");
            }
        }
        assert!(!benches.is_empty(), "at least one link");
        let n = benches.len();
        let mut rig = MultiRig {
            links: Links::new(board, n),
            benches,
            supply,
            last: SupplyTick::default(),
            outs: [LinkOutputs::default(); MAX_LINKS],
            now_ms: 0,
            waited_ms: 0,
        };
        rig.tick();
        rig
    }

    /// How many links.
    pub fn count(&self) -> usize {
        self.benches.len()
    }

    /// Rig time, ms.
    pub fn now_ms(&self) -> u64 {
        self.now_ms
    }

    /// Rig time spent in `SIM WAIT`, ms.
    pub fn waited_ms(&self) -> u64 {
        self.waited_ms
    }

    /// True radius of link `k`, mm.
    pub fn radius_mm(&self, k: usize) -> f64 {
        self.benches[k].radius_mm()
    }

    /// The first plant that can no longer answer: its link (0-based) and why.
    pub fn plant_failure(&self) -> Option<(usize, &str)> {
        self.benches
            .iter()
            .enumerate()
            .find_map(|(k, b)| b.plant().failure().map(|w| (k, w)))
    }

    /// Runs every board up to `ms` of link time (a rest reference for current sense).
    pub fn boot(&mut self, ms: u64) {
        while self.now_ms < ms {
            self.tick();
        }
    }

    /// One control period: every link samples and steps, then the plants run the period on
    /// the shared supply.
    pub fn tick(&mut self) {
        let n = self.count();
        let now = self.now_ms;
        let inputs: heapless::Vec<Inputs, MAX_LINKS> =
            self.benches.iter_mut().map(|b| b.inputs(now)).collect();
        self.links.step(self.now_ms, &inputs, &mut self.outs[..n]);
        for k in 0..n {
            self.benches[k].drive(self.now_ms, self.outs[k].out);
        }
        self.run_period();
    }

    /// Lays out every heater's window over one period, works out the supply piece by piece
    /// and steps each plant with what it really got.
    fn run_period(&mut self) {
        let n = self.count();
        let dt_s = TICK_MS as f64 / 1000.0;
        // (link, heater, start, length, conductance)
        let mut windows: heapless::Vec<(usize, usize, f64, f64, f64), WINDOWS> =
            heapless::Vec::new();
        let board = Config::DEFAULT;
        for k in 0..n {
            let d = self.benches[k].reaching(self.now_ms);
            let s = self.benches[k].plant().sample();
            let ohm = s.heater_ohm.unwrap_or([
                board.pla_heater.resistance_ohm as f64,
                board.tca_heater.resistance_ohm as f64,
            ]);
            for (i, duty) in [d.pla, d.tca].into_iter().enumerate() {
                let phase = self.outs[k].phase[i] as f64;
                let start = phase - libm::floor(phase);
                let _ = windows.push((k, i, start, duty.clamp(0.0, 1.0), 1.0 / ohm[i]));
            }
        }
        // Piece edges: every window's start and end.
        let mut edges: heapless::Vec<f64, { 2 * WINDOWS + 2 }> = heapless::Vec::new();
        let _ = edges.push(0.0);
        let _ = edges.push(1.0);
        for w in &windows {
            let _ = edges.push(w.2);
            let _ = edges.push(wrap(w.2 + w.3));
        }
        edges.sort_unstable_by(f64::total_cmp);
        let on = |w: &(usize, usize, f64, f64, f64), t: f64| w.3 > 0.0 && wrap(t - w.2) < w.3;
        let mut got = [[0.0f64; 2]; MAX_LINKS];
        let mut tick = SupplyTick {
            min_v: f64::INFINITY,
            ..SupplyTick::default()
        };
        let v_open = self.supply.open_v;
        for pair in edges.windows(2) {
            let (a, b) = (pair[0], pair[1]);
            let len = b - a;
            if len <= 0.0 {
                continue;
            }
            let mid = 0.5 * (a + b);
            let g: f64 = windows.iter().filter(|w| on(w, mid)).map(|w| w.4).sum();
            let v = self.supply.volts(g);
            tick.peak_a = tick.peak_a.max(v * g);
            let unlimited = SharedSupply {
                limit_a: f64::INFINITY,
                ..self.supply
            };
            tick.demand_a = tick.demand_a.max(unlimited.volts(g) * g);
            tick.mean_v += v * len;
            tick.min_v = tick.min_v.min(v);
            for w in windows.iter().filter(|w| on(w, mid)) {
                got[w.0][w.1] += len * (v / v_open) * (v / v_open);
            }
        }
        // Each heater's on-current is sampled just inside its own window (a probe pulse where
        // its duty is below one): the supply there, with every window on at that instant.
        let mut pulse_v = [[v_open; 2]; MAX_LINKS];
        for w in &windows {
            let t = wrap(w.2 + SAMPLE_INSIDE);
            let g: f64 = windows
                .iter()
                .filter(|o| on(o, t) || (o.0 == w.0 && o.1 == w.1))
                .map(|o| o.4)
                .sum();
            pulse_v[w.0][w.1] = self.supply.volts(g);
        }
        for k in 0..n {
            self.benches[k].set_terminal_v(Some(tick.mean_v));
            self.benches[k].set_pulse_v(Some(pulse_v[k]));
            let d = Duties {
                pla: got[k][0].min(1.0),
                tca: got[k][1].min(1.0),
            };
            self.benches[k].run_duties(dt_s, d);
            let t = self.benches[k].plant().truth();
            tick.power_w += t.pla_w + t.tca_w;
            let p = self.links.link(k).powers();
            tick.reckoned_w += (p.pla_w + p.tca_w) as f64;
        }
        self.last = tick;
        self.now_ms += TICK_MS;
    }

    /// Writes every queued event or alarm line through `out`.
    pub fn drain_events(&mut self, out: &mut impl FnMut(&str)) {
        while let Some(l) = self.links.pop_event_line() {
            out(&l);
        }
    }

    /// Handles one protocol line, `SIM` commands included (`@<n> SIM ...` for link n; `SIM
    /// SUPPLY` sets the shared supply's open-circuit voltage).
    pub fn handle_line(&mut self, line: &str, out: &mut impl FnMut(&str)) {
        if let Some((k, sim)) = self.links.handle_line(self.now_ms, line, out) {
            self.sim_command(k, sim, out);
        }
        // A command may change the duties (ABORT): applied at once, as the firmware does.
        for k in 0..self.count() {
            self.outs[k] = self.links.outputs(k);
            self.benches[k].drive(self.now_ms, self.outs[k].out);
        }
    }

    fn sim_command(&mut self, k: usize, cmd: SimCommand, out: &mut impl FnMut(&str)) {
        /// The fault a `SIM FAULT` injects.
        fn f_of(cmd: SimCommand) -> Option<SimFault> {
            match cmd {
                SimCommand::Fault(f, _) => Some(f),
                _ => None,
            }
        }
        match cmd {
            SimCommand::Wait(seconds) => self.wait(seconds, out),
            SimCommand::Supply(v) => {
                let mut l = OutLine::new();
                if !(0.0..=morphlink::bench::SIM_SUPPLY_MAX_V).contains(&v) {
                    reply::sim_supply_out_of_range(&mut l, morphlink::bench::SIM_SUPPLY_MAX_V);
                } else {
                    self.supply.open_v = v as f64;
                    for b in &mut self.benches {
                        let _ = b.plant_mut().set(Setting::SupplyV(v as f64));
                    }
                    reply::sim_supply(&mut l, v);
                }
                out(&l);
            }
            // The ambient bead is the board's, one for every link (docs/multilink.md): the
            // room it reads, and a fault or drift on it, reach every link's frame, and a CLEAR
            // on any link clears it.
            SimCommand::Ambient(_)
            | SimCommand::Fault(_, Sensor::Amb)
            | SimCommand::Drift(Sensor::Amb, _)
                if !matches!(
                    f_of(cmd),
                    Some(SimFault::HeaterOpen | SimFault::HeaterStuck)
                ) =>
            {
                let mut reply = OutLine::new();
                for (j, b) in self.benches.iter_mut().enumerate() {
                    b.command(cmd, &mut |l: &str| {
                        if j == k {
                            reply.clear();
                            let _ = reply.push_str(l);
                        }
                    });
                }
                out(&reply);
            }
            SimCommand::Clear => {
                for (j, b) in self.benches.iter_mut().enumerate() {
                    if j != k {
                        b.clear_sensor(Sensor::Amb.index());
                    }
                }
                self.benches[k].command(cmd, &mut |l: &str| out(l));
            }
            _ => {
                let mut reply = OutLine::new();
                self.benches[k].command(cmd, &mut |l: &str| {
                    reply.clear();
                    let _ = reply.push_str(l);
                });
                if self.benches[k].plant().failure().is_none() {
                    out(&reply);
                }
            }
        }
    }

    /// `SIM WAIT <s>` on every link at once.
    fn wait(&mut self, seconds: f32, out: &mut impl FnMut(&str)) {
        let mut l = OutLine::new();
        if !(0.0..=SIM_WAIT_MAX_S).contains(&seconds) {
            reply::sim_wait_out_of_range(&mut l, SIM_WAIT_MAX_S);
            out(&l);
            return;
        }
        let ticks = (seconds as f64 * 1000.0 / TICK_MS as f64 + 0.5) as u64;
        for _ in 0..ticks {
            self.tick();
            self.waited_ms += TICK_MS;
            self.drain_events(out);
            if self.plant_failure().is_some() {
                return;
            }
        }
        reply::ok(&mut l);
        out(&l);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_supply_past_its_limit_sags_to_hold_its_current() {
        let s = SharedSupply {
            open_v: 12.0,
            internal_ohm: 0.0,
            limit_a: 1.0,
        };
        assert_eq!(s.volts(0.0), 12.0);
        // 6.5 Ω would draw 1.85 A at 12 V: the supply holds 1 A, so 6.5 V.
        assert!((s.volts(1.0 / 6.5) - 6.5).abs() < 1e-9);
        let stiff = SharedSupply::STIFF;
        assert!((stiff.volts(1.0 / 30.0) - 12.0 / (1.0 + 0.1 / 30.0)).abs() < 1e-9);
    }
}

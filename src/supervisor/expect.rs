//! The supervisor's one expectation of its sensors: a family of the link's lumped model
//! ([`crate::lumped::Network`]) fed the powers the duties deliver, whose hull bounds what a
//! healthy link's heated thermistors can read. Every residual test judges against it (`residual`).
//!
//! Members differ in what the supervisor does not know about this link:
//! - its surroundings: before `TUNE`, the two ends of the rim convection a link may have
//!   ([`CONVECTION_RANGE_W_M2K`]: from half still air's to twice still water's): with the same
//!   heat capacities the airier link rises higher and cools slower at every moment, so the two
//!   bracket every medium between; after `TUNE`, the convection it found;
//! - where its bead sits: on its heated node or on that node's silicone shell,
//!   and what share of the model's rise it reads ([`UNTUNED_GAIN_RANGE`], or the fitted share
//!   ± [`TUNED_SPREAD`]), of its own heater's and of the other heater's (from
//!   [`UNTUNED_CROSS_LEAST`] to the model's own: the high-fidelity link couples its heaters
//!   less than the model);
//! - how late it reads: at once or through a first-order lag of [`BEAD_LAG_MAX_S`].
//!
//! The model is linear in its heat inputs, so each convection runs three networks: one from the
//! link's state at the start (its readings) under the ambient reading, and one driven by each
//! heater from cold; a member adds them with its shares. The stored heat of an ABORT, the
//! other heater's heat, a warm link and a bath that changes are in the networks, not in rules.

use crate::calibration::Calibration;
use crate::link::CONVECTION_RANGE_W_M2K;
use crate::lumped::{lag_remaining, node, Network};
use crate::vocab::{Heater, Powers};

/// Share of the model's rise a bead reads before `TUNE`, (least, most), 1: the high-fidelity
/// beads read 0.72–0.93 of their heater's rise, and the drawn links' silicone, heaters and
/// geometry move the model's own rise by tens of per cent (docs/safety.md, "The expectation").
pub const UNTUNED_GAIN_RANGE: (f32, f32) = (0.7, 1.25);
const _: () = assert!(UNTUNED_GAIN_RANGE.0 > 0.0 && UNTUNED_GAIN_RANGE.0 < 1.0);
const _: () = assert!(UNTUNED_GAIN_RANGE.1 >= 1.0 && UNTUNED_GAIN_RANGE.1 <= 2.0);
/// Least share of the model's rise from the other heater a bead reads before `TUNE`, 1: the
/// high-fidelity link couples its heaters less than the model in places (the PLA's heat at the
/// TCA's bead in soften), yet never by half; a TCA that dies while the PLA's heat still warms
/// its bead is told from a live one by this share.
pub const UNTUNED_CROSS_LEAST: f32 = 0.5;
const _: () = assert!(UNTUNED_CROSS_LEAST >= 0.0 && UNTUNED_CROSS_LEAST <= UNTUNED_GAIN_RANGE.0);
/// After `TUNE`, each share is the fitted one within this fraction either way, 1: the fit is a
/// steady rise, and the model's transients differ from the link's by this much of it.
pub const TUNED_SPREAD: f32 = 0.25;
const _: () = assert!(TUNED_SPREAD > 0.0 && TUNED_SPREAD < 0.5);
/// Slowest bead the family reads through, s: the high-fidelity PLA bead reads its rod about
/// 10 s late.
pub const BEAD_LAG_MAX_S: f32 = 12.0;
const _: () = assert!(BEAD_LAG_MAX_S >= 1.0 && BEAD_LAG_MAX_S <= 60.0);

/// The lags a member is also read through, shares of [`BEAD_LAG_MAX_S`]: a bead between them
/// lies between their readings, and a fast one's change is near the shortest's.
const LAG_SHARES: [f32; 3] = [0.2, 0.5, 1.0];
const LAGS: usize = LAG_SHARES.len();
const _: () = assert!(LAG_SHARES[0] > 0.0 && LAG_SHARES[0] < LAG_SHARES[1] && LAG_SHARES[2] == 1.0);
/// The channels the family predicts: the PLA and TCA thermistors ([`Heater::index`]).
const CHANNELS: usize = 2;
/// Members per channel: convection × node × own share × cross share, each read at once and
/// through each of the lags.
const MEMBERS: usize = 16;

/// The family's free parameters for one calibration.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Family {
    /// Rim convection of each bracketing model, W/(m² K).
    h_w_m2k: [f32; 2],
    /// Each channel's (least, most) share of its own heater's and of the other's rise.
    own: [(f32, f32); CHANNELS],
    cross: [(f32, f32); CHANNELS],
    /// Whether a bead may sit on its node's shell.
    shell: bool,
}

impl Family {
    fn of(cal: &Calibration) -> Family {
        let (lo, hi) = UNTUNED_GAIN_RANGE;
        let untuned = (lo, hi);
        if !cal.fitted() {
            return Family {
                h_w_m2k: [CONVECTION_RANGE_W_M2K.1, CONVECTION_RANGE_W_M2K.0],
                own: [untuned; CHANNELS],
                cross: [(UNTUNED_CROSS_LEAST, 1.0); CHANNELS],
                shell: true,
            };
        }
        let spread = |g: f32| (g * (1.0 - TUNED_SPREAD), g * (1.0 + TUNED_SPREAD));
        // TUNE tells water from still air; within either the link's own convection is the fit's
        // within a factor (1 − 2 × spread), whose steady part the fitted shares hold.
        let h = cal.model_convection_w_m2k();
        let (lo_h, hi_h) = CONVECTION_RANGE_W_M2K;
        let f = 1.0 - 2.0 * TUNED_SPREAD;
        Family {
            h_w_m2k: [(h / f).min(hi_h), (h * f).max(lo_h)],
            own: Heater::ALL.map(|h| spread(cal.sensor_gain(h))),
            cross: Heater::ALL.map(|h| spread(cal.cross_gain(h))),
            shell: true,
        }
    }
}

/// The heater a channel belongs to.
const fn heater_of(channel: usize) -> Heater {
    Heater::ALL[channel]
}

/// A channel's node and its shell in the network.
const fn nodes_of(channel: usize) -> [usize; 2] {
    if channel == 0 {
        [node::PLA, node::PLA_SHELL]
    } else {
        [node::TCA, node::TCA_SHELL]
    }
}

/// The family's state: per convection the free network (°C) and one network per heater (K
/// above the surroundings), and each member's lagged reading (K).
#[derive(Clone, Copy, Debug)]
pub struct Expectation {
    family: Family,
    /// The calibration's family (the fitted one once `TUNE` has run); `family` is the
    /// compiled-in one instead while a `TUNE` runs ([`Expectation::tuning`]).
    calibrated: Family,
    /// `None` until the first whole frame (or after [`Expectation::restart`]).
    nets: Option<[[Network; 3]; 2]>,
    lagged_k: [[[f32; LAGS]; MEMBERS]; CHANNELS],
    /// Each member's reading at once, K (last tick's until the update).
    now_k: [[f32; MEMBERS]; CHANNELS],
    /// This tick's least and greatest change of any member since the last tick, K.
    change_k: [(f32, f32); CHANNELS],
    /// This tick's hull of every channel, (floor, ceiling), K above the ambient reading.
    bounds_k: [(f32, f32); CHANNELS],
    /// This tick's least model rise of each heater's own heat at its bead, K.
    own_heat_k: [f32; CHANNELS],
}

impl Expectation {
    /// The family of the compiled-in link, not yet started.
    pub fn new() -> Self {
        Expectation {
            family: Family::of(&Calibration::DEFAULT),
            calibrated: Family::of(&Calibration::DEFAULT),
            nets: None,
            lagged_k: [[[0.0; LAGS]; MEMBERS]; CHANNELS],
            now_k: [[0.0; MEMBERS]; CHANNELS],
            change_k: [(0.0, 0.0); CHANNELS],
            bounds_k: [(f32::NAN, f32::NAN); CHANNELS],
            own_heat_k: [0.0; 2],
        }
    }

    /// Takes the family of `cal` (the fitted one once `TUNE` has run) and starts again from the
    /// next readings.
    pub fn set_calibration(&mut self, cal: &Calibration) {
        self.calibrated = Family::of(cal);
        self.tuning(false);
    }

    /// Whether a `TUNE` runs: it is judged by the compiled-in family, since the calibration it
    /// replaces may no longer describe the link (moved from still air into water, say). A
    /// change of family starts it again from the next readings (a `TUNE` that trips switches
    /// back while its fault is latched: the change test's rise sum, kept, holds RESET then).
    pub fn tuning(&mut self, tuning: bool) {
        let family = if tuning {
            Family::of(&Calibration::DEFAULT)
        } else {
            self.calibrated
        };
        if family != self.family {
            self.family = family;
            self.restart();
        }
    }

    /// Forgets the link's state: the next frame starts the family from its readings.
    pub fn restart(&mut self) {
        self.nets = None;
        self.bounds_k = [(f32::NAN, f32::NAN); CHANNELS];
    }

    /// Whether the family runs (it has had a whole frame since it started).
    pub fn started(&self) -> bool {
        self.nets.is_some()
    }

    /// This tick's (floor, ceiling) of `channel`, K above the ambient reading (NaN before the
    /// family starts).
    pub fn bounds_k(&self, channel: usize) -> (f32, f32) {
        self.bounds_k[channel]
    }

    /// The least and the greatest change of any member of `channel` over the last update, K:
    /// how fast a healthy reading can fall and rise now.
    pub fn change_k(&self, channel: usize) -> (f32, f32) {
        self.change_k[channel]
    }

    /// The least rise the family gives `heater`'s own heat at its bead now, K: how much of the
    /// floor a heater that does not heat would take away.
    pub fn own_heat_k(&self, heater: Heater) -> f32 {
        self.own_heat_k[heater.index()]
    }

    /// Advances every member `dt_s` under the powers `p` (W) delivered since the last tick,
    /// with the readings `t_c` (PLA, TCA thermistors) and the ambient reading `amb_c`, °C, and
    /// takes the hull. A first whole frame starts the family from its readings (a warm link is
    /// not a fault).
    pub fn update(&mut self, dt_s: f32, p: Powers, t_c: [f32; CHANNELS], amb_c: f32) {
        if !amb_c.is_finite() || !t_c[0].is_finite() || !t_c[1].is_finite() {
            return;
        }
        let nets = match self.nets.as_mut() {
            Some(nets) => {
                for net in nets.iter_mut() {
                    net[0].advance(dt_s, 0.0, 0.0, amb_c);
                    net[1].advance(dt_s, 0.0, p.pla_w, 0.0);
                    net[2].advance(dt_s, p.tca_w, 0.0, 0.0);
                }
                nets
            }
            None => {
                let start = |h: f32| {
                    let mut free = Network::new(h, amb_c);
                    free.temp_c = [t_c[1], t_c[1], t_c[0], t_c[0], t_c[0].min(t_c[1])];
                    [free, Network::new(h, 0.0), Network::new(h, 0.0)]
                };
                let h = self.family.h_w_m2k;
                let nets = self.nets.insert([start(h[0]), start(h[1])]);
                self.lagged_k = [[[f32::NAN; LAGS]; MEMBERS]; CHANNELS];
                self.now_k = [[f32::NAN; MEMBERS]; CHANNELS];
                nets
            }
        };
        let keep = LAG_SHARES.map(|share| lag_remaining(dt_s, share * BEAD_LAG_MAX_S));
        let f = &self.family;
        for ch in 0..CHANNELS {
            let h = heater_of(ch);
            let (own_net, cross_net) = match h {
                Heater::Pla => (1, 2),
                Heater::Tca => (2, 1),
            };
            let at = nodes_of(ch);
            let node_count = if f.shell { 2 } else { 1 };
            let (mut lo, mut hi) = (f32::INFINITY, f32::NEG_INFINITY);
            let mut least_own = f32::INFINITY;
            let (mut fall, mut rise) = (f32::INFINITY, f32::NEG_INFINITY);
            let mut m = 0;
            for net in nets.iter() {
                for &n in &at[..node_count] {
                    let free_k = net[0].temp_c[n] - amb_c;
                    let (own_k, cross_k) = (net[own_net].temp_c[n], net[cross_net].temp_c[n]);
                    least_own = least_own.min(f.own[ch].0 * own_k);
                    for g in [f.own[ch].0, f.own[ch].1] {
                        for c in [f.cross[ch].0, f.cross[ch].1] {
                            let now_k = free_k + g * own_k + c * cross_k;
                            let mut moved = |d: f32, was: f32| {
                                if was.is_finite() {
                                    fall = fall.min(d - was);
                                    rise = rise.max(d - was);
                                }
                                lo = lo.min(d);
                                hi = hi.max(d);
                            };
                            moved(now_k, self.now_k[ch][m]);
                            self.now_k[ch][m] = now_k;
                            for (lag, keep) in self.lagged_k[ch][m].iter_mut().zip(keep) {
                                let was = *lag;
                                *lag = if was.is_finite() {
                                    now_k + (was - now_k) * keep
                                } else {
                                    now_k
                                };
                                moved(*lag, was);
                            }
                            m += 1;
                        }
                    }
                }
            }
            self.bounds_k[ch] = (lo, hi);
            // No change yet on the first tick.
            self.change_k[ch] = if fall <= rise {
                (fall, rise)
            } else {
                (0.0, 0.0)
            };
            self.own_heat_k[ch] = least_own;
        }
    }
}

impl Default for Expectation {
    fn default() -> Self {
        Self::new()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Runs the family `s` seconds at `p` from a link at 22 °C, feeding it `read` (PLA, TCA
    /// readings from the time, s).
    fn run(e: &mut Expectation, s: f32, p: Powers, read: impl Fn(f32) -> [f32; 2]) {
        for i in 0..(s * 10.0) as usize {
            let [pla, tca] = read(i as f32 / 10.0);
            e.update(0.1, p, [pla, tca], 22.0);
        }
    }

    #[test]
    fn the_hull_brackets_the_model_itself_in_water_and_in_air() {
        for h in [
            crate::link::LINK.surroundings.h_w_m2k as f32,
            crate::tune::TUNE_STILL_AIR_W_M2K,
        ] {
            let mut link = Network::new(h, 22.0);
            let mut e = Expectation::new();
            let p = Powers {
                pla_w: 4.0,
                tca_w: 1.0,
            };
            for i in 0..600 {
                let t = link.temp_c;
                e.update(0.1, p, [t[node::PLA], t[node::TCA]], 22.0);
                for ch in 0..2 {
                    let y = t[nodes_of(ch)[0]] - 22.0;
                    let (lo, hi) = e.bounds_k(ch);
                    assert!(
                        y >= lo - 1e-3 && y <= hi + 1e-3,
                        "{h} {ch} at {i}: {lo} {y} {hi}"
                    );
                }
                link.advance(0.1, p.tca_w, p.pla_w, 22.0);
            }
            // The floor has risen well clear of a dead heater's reading, the ceiling above air's.
            let (lo, hi) = e.bounds_k(0);
            assert!(lo > 20.0 && hi > 100.0, "{lo} {hi}");
        }
    }

    #[test]
    fn a_warm_start_is_the_link_and_cools_within_the_hull() {
        let mut e = Expectation::new();
        run(&mut e, 0.1, Powers::default(), |_| [60.0, 40.0]);
        let (lo, hi) = e.bounds_k(0);
        assert!(lo <= 38.0 && hi >= 38.0, "{lo} {hi}");
        run(&mut e, 60.0, Powers::default(), |_| [60.0, 40.0]);
        let (lo, hi) = e.bounds_k(0);
        // A link that holds 38 K for a minute with no heat is above every member.
        assert!(hi < 38.0 && lo >= 0.0 - 1e-3, "{lo} {hi}");
    }

    #[test]
    fn a_fitted_calibration_narrows_the_family() {
        let mut cal = Calibration::DEFAULT;
        cal.pla_rise_k_per_w *= 0.8;
        assert!(cal.fitted());
        let p = Powers {
            pla_w: 2.0,
            tca_w: 0.0,
        };
        let width = |cal: &Calibration| {
            let mut e = Expectation::new();
            e.set_calibration(cal);
            run(&mut e, 60.0, p, |_| [22.0, 22.0]);
            let (lo, hi) = e.bounds_k(0);
            hi - lo
        };
        assert!(width(&cal) < 0.8 * width(&Calibration::DEFAULT));
    }
}

//! Several links on one board and one supply: a [`Controller`] per link (its own activity,
//! calibration, settings, supervisor and alarms) and the supply's scheduler
//! ([`crate::budget`]) between them. Per tick: queued morphs that now fit start, the scheduler
//! shares the budget out as allowances and PWM phases, then each link's controller steps with
//! its own inputs under its allowance. Per line: the address (`@<n>`, `@*`) picks the link;
//! `GAIT`, `LINKS` and the supply's settings are the board's own.
//!
//! A fault on one link stops that link only (each link has its own cut-off, docs/bringup.md);
//! a fault every link sees (the supply out of range, the shared ambient bead lost) trips every
//! link's own supervisor, so every link stops and says why. With one link and no budget set,
//! every line and tick is exactly the controller's own.

use crate::budget::{self, Class, Demand, LinkShare, Share, SupplyBudget, MAX_LINKS};
use crate::controller::{Config, Controller, Inputs, Outputs};
use crate::electrical::{Currents, ShuntSense, ELECTRICAL_TICKS, PULSE_SAG_SHARE, SHORT_MIN_A};
use crate::fault::{Fault, FaultCode, Subject};
use crate::heater::HeaterConfig;
use crate::protocol::links::{self as wire, Address, LinksCommand, SupplySetting};
use crate::protocol::{self, Command, ConfigCommand, Mode, OutLine, SimCommand};
use crate::vocab::{Doing, Phase, Powers};
use heapless::{Deque, Vec};

/// One link's outputs: its duties and cut-off, and where in the PWM period each heater's
/// on-window starts (fractions of the period: PLA, TCA).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct LinkOutputs {
    /// Duties and the link's cut-off.
    pub out: Outputs,
    /// Start of each heater's on-window, fraction of the period (PLA, TCA).
    pub phase: [f32; 2],
}

/// A MORPH waiting for room in the budget.
#[derive(Clone, Copy, Debug, PartialEq)]
struct Queued {
    radius_mm: f32,
    mode: Mode,
    reserve_w: Powers,
    /// Queue order (lower first).
    at: u32,
}

/// Depth of the board's own event queue (queued, dropped): one per link and room to spare.
const LINK_EVENTS: usize = 2 * MAX_LINKS;

/// The links of one board, at most `N`.
pub struct Links<const N: usize> {
    ctrl: Vec<Controller, N>,
    budget: SupplyBudget,
    /// When each link's activity was admitted (scheduler order).
    since: [u32; N],
    was_busy: [bool; N],
    queued: [Option<Queued>; N],
    /// The PLA power each link's running soften was admitted with, W: what brings its rod
    /// soft within half its soften timeout ([`Links::in_time_pla_w`]); its reserve in rest
    /// and soften is never less.
    soften_pla_w: [f32; N],
    next_order: u32,
    shares: [LinkShare; N],
    events: Deque<OutLine, LINK_EVENTS>,
    /// Where the round-robin over the links' events goes on.
    next_event: usize,
    /// The board's current sense (reads each link's stray current).
    shunt: ShuntSense,
    /// Each link's heaters' current while their gates are off, last tick, A: see
    /// [`Demand::stray_a`].
    stray_a: [[f32; 2]; N],
    /// Ticks in a row some heater's on-current read a sagging supply
    /// ([`Links::judge_sag`]).
    sag_ticks: u8,
    /// The link whose SAVE the shell is writing.
    saving: usize,
}

impl<const N: usize> Links<N> {
    /// `count` links (1 to `N`) with the board settings `cfg`, at rest, no budget.
    pub fn new(cfg: Config, count: usize) -> Self {
        let count = count.clamp(1, N.min(MAX_LINKS));
        let mut ctrl = Vec::new();
        for _ in 0..count {
            let _ = ctrl.push(Controller::new(cfg));
        }
        Links {
            ctrl,
            budget: SupplyBudget::UNLIMITED,
            since: [0; N],
            was_busy: [false; N],
            queued: [None; N],
            soften_pla_w: [0.0; N],
            next_order: 1,
            shares: [[Share::default(); 2]; N],
            events: Deque::new(),
            next_event: 0,
            shunt: cfg.shunt,
            stray_a: [[0.0; 2]; N],
            sag_ticks: 0,
            saving: 0,
        }
    }

    /// How many links.
    pub fn count(&self) -> usize {
        self.ctrl.len()
    }

    /// Link `k`'s controller (0-based).
    pub fn link(&self, k: usize) -> &Controller {
        &self.ctrl[k]
    }

    /// Link `k`'s controller, to load its settings or feed its timing (0-based).
    pub fn link_mut(&mut self, k: usize) -> &mut Controller {
        &mut self.ctrl[k]
    }

    /// The shared supply's budget and current limit.
    pub fn budget(&self) -> SupplyBudget {
        self.budget
    }

    /// Whether link `k` has a MORPH waiting for the budget.
    pub fn queued(&self, k: usize) -> bool {
        self.queued.get(k).is_some_and(|q| q.is_some())
    }

    /// This tick's share of link `k` (allowance and phase of PLA, TCA).
    pub fn share(&self, k: usize) -> LinkShare {
        self.shares[k]
    }

    /// Link `k`'s outputs now (also right after a command: ABORT zeroes them at once), each
    /// duty clipped to its window.
    pub fn outputs(&self, k: usize) -> LinkOutputs {
        let o = self.ctrl[k].outputs();
        let s = self.shares[k];
        LinkOutputs {
            out: Outputs {
                pla_duty: budget::clip_duty(o.pla_duty, &s[0]),
                tca_duty: budget::clip_duty(o.tca_duty, &s[1]),
                ..o
            },
            phase: [s[0].phase, s[1].phase],
        }
    }

    /// True while no link is busy and none has a morph queued.
    pub fn idle(&self) -> bool {
        (0..self.count()).all(|k| !self.ctrl[k].busy() && !self.queued(k))
    }

    /// The supply voltage the links read, V: the highest (the cut-offs sit after the sense,
    /// so each reads the same supply; the highest is the safe side for currents).
    pub fn supply_v(&self) -> f32 {
        self.ctrl
            .iter()
            .map(|c| c.supply_v())
            .filter(|v| v.is_finite())
            .fold(f32::NAN, f32::max)
    }

    fn demand(&self, k: usize) -> Demand {
        let c = &self.ctrl[k];
        let class = match c.doing() {
            Doing::Tune | Doing::Heat(_) => Class::Fixed,
            Doing::Morph(Phase::Bend | Phase::Lock) => Class::Holding,
            Doing::Morph(Phase::Soften | Phase::Rest) => Class::Softening,
            Doing::Morph(_) | Doing::Idle => Class::Idle,
        };
        let mut reserve_w = c.reserve_w();
        if class == Class::Softening {
            reserve_w.pla_w = reserve_w.pla_w.max(self.soften_pla_w[k]);
        }
        Demand {
            class,
            since: self.since[k],
            wanted_w: c.wanted(),
            reserve_w,
            ohm: c.heater_ohm(),
            stray_a: self.stray_a[k],
        }
    }

    fn demands(&self) -> Vec<Demand, N> {
        (0..self.count()).map(|k| self.demand(k)).collect()
    }

    /// What the running links hold, W.
    fn held_w(&self) -> f32 {
        budget::held_w(&self.demands())
    }

    /// One control tick at `now_ms`: `inputs[k]` is link `k`'s frame (its thermistors and
    /// currents, the shared ambient and supply), `out[k]` gets its outputs.
    pub fn step(&mut self, now_ms: u64, inputs: &[Inputs], out: &mut [LinkOutputs]) {
        // A current over the short threshold with the gate off: a stuck MOSFET whose cut-off
        // did not open. It flows whatever the allowances say, so the scheduler counts it.
        let currents: Vec<Option<Currents>, N> = inputs
            .iter()
            .take(self.count())
            .map(|i| i.current.map(|c| Currents::of(&c, &self.shunt)))
            .collect();
        for (s, c) in self.stray_a.iter_mut().zip(&currents) {
            *s = c.map_or([0.0; 2], |c| {
                c.off_a.map(|a| if a > SHORT_MIN_A { a } else { 0.0 })
            });
        }
        self.judge_sag(inputs, &currents);
        self.start_queued(now_ms);
        for k in 0..self.count() {
            self.note_started(k);
        }
        let n = self.count();
        if self.budget.binding() {
            let v = self.supply_v();
            // A current no gate governs that the budget cannot hold beside the running links
            // (a shorted heater behind a cut-off that did not open, which that link has named):
            // their reserves are gone, so they stop and say what flows; the supply must be cut
            // by hand. A short that its cut-off ends within its settling ticks is no such load.
            let cut_failed = self.ctrl[..n].iter().any(Controller::cutoff_failed);
            let overrun = budget::overrun_a(&self.budget, v, &self.demands());
            if let (true, Some(a)) = (cut_failed, overrun) {
                // The running links and the queued ones (whose morph the queue then drops).
                for k in 0..n {
                    if self.ctrl[k].busy() || self.queued[k].is_some() {
                        self.ctrl[k].trip_shared(Fault {
                            code: FaultCode::CutoffFailed,
                            subject: Subject::Supply,
                            value: a,
                        });
                    }
                }
            }
            let demands = self.demands();
            budget::allocate(&self.budget, v, &demands, &mut self.shares[..n]);
        } else {
            for s in self.shares[..n].iter_mut() {
                *s = [Share::UNLIMITED; 2];
            }
        }
        for k in 0..n.min(inputs.len()).min(out.len()) {
            let s = self.shares[k];
            self.ctrl[k].set_allowance(Powers {
                pla_w: s[0].allow_w,
                tca_w: s[1].allow_w,
            });
            self.ctrl[k].step(now_ms, &inputs[k]);
            out[k] = self.outputs(k);
        }
        // A link that faults drops the morph it has queued at once, with the reason: a morph
        // left queued would start by itself after a RESET, which the user did not ask.
        for k in 0..n {
            if self.queued[k].is_some() && self.ctrl[k].fault().is_some() {
                let mut why = OutLine::new();
                self.ctrl[k].morph_refusal(&mut why);
                self.drop_queued(k, &why);
            }
        }
    }

    /// A supply that cannot give what the heaters' pulses draw together (its own current limit
    /// under `supply_limit_a`, which the scheduler lays the pulses out under) falls into
    /// constant-current mode inside them: the on-currents then read, at the resistances read
    /// before, a voltage [`PULSE_SAG_SHARE`] or more under the same frame's supply reading. Two
    /// heaters or more reading it in one tick are the supply's (one heater alone is its own
    /// resistance, which its link judges): those samples teach no link a resistance nor judge
    /// one, and once it holds [`ELECTRICAL_TICKS`] ticks in a row every link stops with
    /// `supply-out-of-range` at the lowest voltage read, and an event says what to set. The
    /// sagging morphs would otherwise run on heat they do not get and land off their targets.
    /// One link is judged as the controller alone judges it (`Links` of one is exactly it).
    fn judge_sag(&mut self, inputs: &[Inputs], currents: &[Option<Currents>]) {
        let n = currents.len();
        let mut sag = [[false; 2]; N];
        let mut lowest: Option<(usize, f32)> = None;
        let mut sagging = 0;
        let judged = if n > 1 { n } else { 0 };
        for (k, c) in currents.iter().enumerate().take(judged) {
            let Some(c) = c else {
                continue;
            };
            let (pulse_v, supply_v) = self.ctrl[k].pulse_v(c, &inputs[k]);
            for (i, p) in pulse_v.into_iter().enumerate() {
                if p < (1.0 - PULSE_SAG_SHARE) * supply_v {
                    sag[k][i] = true;
                    sagging += 1;
                    if lowest.is_none_or(|(_, low)| p < low) {
                        lowest = Some((k, p));
                    }
                }
            }
        }
        let supply_sags = sagging >= 2;
        for (k, s) in sag.iter().enumerate().take(n) {
            self.ctrl[k].note_sag(if supply_sags { *s } else { [false; 2] });
        }
        self.sag_ticks = if supply_sags {
            self.sag_ticks.saturating_add(1)
        } else {
            0
        };
        // A current no gate governs (a shorted heater) loads the supply unscheduled: its sag is
        // that fault's, which the link names and the stray's own rule judges.
        let stray = self.stray_a[..self.count()]
            .iter()
            .flatten()
            .any(|&a| a > 0.0);
        let Some((k, pulse_v)) = lowest.filter(|_| self.sag_ticks >= ELECTRICAL_TICKS && !stray)
        else {
            return;
        };
        if (0..self.count()).all(|j| self.ctrl[j].fault().is_some()) {
            return;
        }
        let mut e = OutLine::new();
        wire::supply_sag_event(&mut e, pulse_v, self.budget.limit_a);
        self.push_event(k, &e);
        // Every link, the queued ones too (the queue then drops their morphs).
        for j in 0..self.count() {
            self.ctrl[j].trip_shared(Fault {
                code: FaultCode::SupplyOutOfRange,
                subject: Subject::Supply,
                value: pulse_v,
            });
        }
    }

    /// Takes link `k`'s activity into the scheduler's order (oldest first) when it has just
    /// started: at once for a morph this board started (a GAIT's in the order it starts them),
    /// at the next tick for anything else.
    fn note_started(&mut self, k: usize) {
        let busy = self.ctrl[k].busy();
        if busy && !self.was_busy[k] {
            self.since[k] = self.next_order;
            self.next_order = self.next_order.wrapping_add(1);
        }
        self.was_busy[k] = busy;
    }

    /// Starts the queued morphs the budget now has room for, oldest first; one that does not
    /// fit keeps every later one waiting (no overtaking).
    fn start_queued(&mut self, now_ms: u64) {
        while let Some(k) = (0..self.count())
            .filter(|&k| self.queued[k].is_some())
            .min_by_key(|&k| self.queued[k].map_or(u32::MAX, |q| q.at))
        {
            let q = self.queued[k].expect("filtered");
            let ohm = self.ctrl[k].heater_ohm();
            if !budget::admits(
                &self.budget,
                self.supply_v(),
                &self.demands(),
                q.reserve_w,
                ohm,
            ) {
                // Nothing runs that could free room (every link idle or stopped): it never
                // starts, so it is dropped and says why, instead of waiting for good.
                if (0..self.count()).any(|j| self.ctrl[j].busy()) {
                    return;
                }
                let mut why = OutLine::new();
                let needs_w = budget::least_budget_w(q.reserve_w, self.count());
                wire::never_starts(&mut why, needs_w, self.budget.budget_w, self.budget.limit_a);
                self.drop_queued(k, &why);
                continue;
            }
            self.queued[k] = None;
            self.soften_pla_w[k] = q.reserve_w.pla_w;
            let mut refusal = OutLine::new();
            let cmd = Command::Morph {
                radius_mm: q.radius_mm,
                mode: q.mode,
            };
            self.ctrl[k].handle(now_ms, cmd, &mut |l: &str| {
                if l != protocol::OK {
                    refusal.clear();
                    let _ = refusal.push_str(l);
                }
            });
            self.note_started(k);
            if !refusal.is_empty() {
                self.drop_queued(k, &refusal);
            }
        }
    }

    /// Drops link `k`'s queued morph, if any, and says why: `why` is the refusal it met
    /// (`event: queued-morph dropped (<why>)`).
    fn drop_queued(&mut self, k: usize, why: &str) {
        self.queued[k] = None;
        let mut e = OutLine::new();
        wire::queued_dropped_event(&mut e, why);
        self.push_event(k, &e);
    }

    /// Queues a board event line of link `k` (addressed where there are several links).
    fn push_event(&mut self, k: usize, line: &str) {
        let l = self.addressed(k, line);
        if self.events.is_full() {
            self.events.pop_front();
        }
        let _ = self.events.push_back(l);
    }

    /// `line` as link `k` sends it: `@<k> ` first where there are several links.
    fn addressed(&self, k: usize, line: &str) -> OutLine {
        let mut l = OutLine::new();
        if self.count() > 1 {
            wire::addressed(&mut l, k, line);
        } else {
            let _ = l.push_str(line);
        }
        l
    }

    /// The next unsolicited line of any link (the board's own first, then the links in
    /// turn), addressed where there are several links.
    pub fn pop_event_line(&mut self) -> Option<OutLine> {
        if let Some(l) = self.events.pop_front() {
            return Some(l);
        }
        let n = self.count();
        for i in 0..n {
            let k = (self.next_event + i) % n;
            if let Some(l) = self.ctrl[k].pop_event_line() {
                self.next_event = (k + 1) % n;
                return Some(self.addressed(k, &l));
            }
        }
        None
    }

    /// Handles one received line: writes zero or more `data:` lines and exactly one final
    /// reply through `out`, except for `SIM` commands, returned with their link for the
    /// caller (a simulated build) to carry out and answer. Empty lines get no reply.
    pub fn handle_line(
        &mut self,
        now_ms: u64,
        line: &str,
        out: &mut dyn FnMut(&str),
    ) -> Option<(usize, SimCommand)> {
        let (address, rest) = match wire::split_address(line) {
            Ok(a) => a,
            Err(e) => {
                out(&protocol::format_error(&e));
                return None;
            }
        };
        let n = self.count();
        if address.is_some() && Self::is_board_line(rest) {
            out(&protocol::format_error(&wire::ERR_BOARD_ADDRESSED));
            return None;
        }
        match address {
            Some(Address::Link(k)) if k >= n => {
                let mut l = OutLine::new();
                wire::address_past(&mut l, k, n);
                out(&l);
                None
            }
            Some(Address::Link(k)) => self.board_or_link(now_ms, Some(k), rest, out),
            Some(Address::All) => {
                // A simulated link's SIM line is answered by its rig, one link at a time; each
                // link's SAVE is a flash write of its own.
                let each = match protocol::parse_line(rest) {
                    Ok(Some(Command::Sim(_))) => Some(&wire::ERR_SIM_EACH),
                    Ok(Some(Command::Save)) => Some(&wire::ERR_SAVE_EACH),
                    _ => None,
                };
                if let Some(e) = each {
                    out(&protocol::format_error(e));
                    return None;
                }
                for k in 0..n {
                    self.board_or_link(now_ms, Some(k), rest, &mut |l: &str| {
                        let mut d = OutLine::new();
                        wire::each_reply(&mut d, k, l);
                        out(&d);
                    });
                }
                let mut l = OutLine::new();
                wire::each_end(&mut l, n);
                out(&l);
                None
            }
            None => self.board_or_link(now_ms, None, rest, out),
        }
    }

    /// Whether `line` is the board's own (GAIT, LINKS, a supply setting), which takes no
    /// address.
    fn is_board_line(line: &str) -> bool {
        wire::parse_links_command(line).is_some()
            || matches!(
                protocol::parse_line(line),
                Ok(Some(Command::Config(ConfigCommand::Set { name, .. })))
                    if wire::supply_setting(name.as_str()).is_some()
            )
    }

    /// A line for the board (GAIT, LINKS, the supply's settings, an unaddressed ABORT) or
    /// for link `k` (link 1 where none is named).
    fn board_or_link(
        &mut self,
        now_ms: u64,
        k: Option<usize>,
        line: &str,
        out: &mut dyn FnMut(&str),
    ) -> Option<(usize, SimCommand)> {
        if let Some(cmd) = wire::parse_links_command(line) {
            match cmd {
                Ok(c) => self.links_command(now_ms, c, out),
                Err(e) => out(&protocol::format_error(&e)),
            }
            return None;
        }
        let parsed = protocol::parse_line(line);
        match parsed {
            Ok(Some(Command::Config(ConfigCommand::Set { name, value }))) => {
                if let Some(s) = wire::supply_setting(name.as_str()) {
                    self.set_supply(s, value.as_str(), out);
                    return None;
                }
            }
            Ok(Some(Command::Abort)) if k.is_none() => {
                self.abort_all(now_ms);
                out(protocol::OK);
                return None;
            }
            Ok(Some(Command::Help)) if self.count() > 1 => {
                let mut last = OutLine::new();
                self.ctrl[0].handle(now_ms, Command::Help, &mut |l: &str| {
                    if protocol::is_final_reply(l) {
                        last.clear();
                        let _ = last.push_str(l);
                    } else {
                        out(l);
                    }
                });
                for h in wire::HELP_LINKS {
                    let mut l = OutLine::new();
                    protocol::reply::help_line(&mut l, h);
                    out(&l);
                }
                out(&last);
                return None;
            }
            _ => {}
        }
        let k = k.unwrap_or(0);
        match parsed {
            Ok(Some(Command::Save)) if self.count() > 1 && !self.idle() => {
                out(&protocol::format_error(&wire::ERR_SAVE_BUSY));
                None
            }
            Ok(Some(Command::Morph { radius_mm, mode })) => {
                self.morph(now_ms, k, radius_mm, mode, out);
                None
            }
            Ok(Some(Command::Abort)) => {
                self.queued[k] = None;
                self.ctrl[k].handle(now_ms, Command::Abort, out);
                None
            }
            Ok(Some(cmd @ (Command::Tune | Command::Heat { .. }))) => {
                let mut l = OutLine::new();
                if self.fixed_refused(k, &cmd, &mut l) {
                    out(&l);
                    None
                } else {
                    self.ctrl[k].handle_line(now_ms, line, out).map(|s| (k, s))
                }
            }
            _ => self.ctrl[k].handle_line(now_ms, line, out).map(|s| (k, s)),
        }
    }

    /// Why link `k` cannot take a TUNE or HEAT (`cmd`) now, written in `l`: a morph of its
    /// own waits in the queue, or, under a budget, the fixed powers it holds do not fit beside
    /// the running links' reserves (or a queued morph is ahead of it). Such a step holds its
    /// powers from the first tick, ahead of every morph, so it must fit as a morph's soften
    /// must: it never takes a running link's reserve. A busy link answers for itself.
    fn fixed_refused(&self, k: usize, cmd: &Command, l: &mut OutLine) -> bool {
        if self.queued(k) {
            *l = protocol::format_error(&wire::ERR_QUEUED);
            return true;
        }
        if !self.budget.binding() || self.ctrl[k].busy() {
            return false;
        }
        let (what, needs) = match *cmd {
            Command::Heat {
                heater, power_w, ..
            } => ("HEAT", Powers::only(heater, power_w)),
            _ => ("TUNE", crate::tune::TUNE_STEP_POWERS),
        };
        let ahead = (0..self.count()).any(|j| self.queued(j));
        let ohm = self.ctrl[k].heater_ohm();
        let demands = self.demands();
        if !ahead && budget::admits(&self.budget, self.supply_v(), &demands, needs, ohm) {
            return false;
        }
        let free_w = self.budget.budget_w - self.held_w();
        wire::fixed_over_budget(l, what, needs.pla_w + needs.tca_w, free_w);
        true
    }

    /// Every link's heaters off and every queued morph dropped (an unaddressed ABORT, also
    /// the moment its line is read).
    pub fn abort_all(&mut self, now_ms: u64) {
        for j in 0..self.count() {
            self.queued[j] = None;
            self.ctrl[j].handle(now_ms, Command::Abort, &mut |_| {});
        }
    }

    /// The SAVE a line asked of one link, once, with that link (0-based): each link keeps its
    /// own settings, so the shell writes them where that link's are kept.
    pub fn take_save_request(&mut self) -> Option<(usize, crate::settings::codec::Blob)> {
        let (k, blob) =
            (0..self.count()).find_map(|k| self.ctrl[k].take_save_request().map(|b| (k, b)))?;
        self.saving = k;
        Some((k, blob))
    }

    /// The SAVE handed out by [`Links::take_save_request`] is done: its link's final reply.
    pub fn finish_save(
        &mut self,
        result: Result<crate::settings::store::SaveReport, crate::settings::store::StoreError>,
        out: &mut dyn FnMut(&str),
    ) {
        let k = self.saving.min(self.count() - 1);
        self.ctrl[k].finish_save(result, &mut |l: &str| out(l));
    }

    /// What a morph to `radius_mm` on link `k` reserves in soften, W: the controller's
    /// ([`Controller::soften_reserve_w`]), its PLA's share at least what softens the rod in
    /// time ([`Links::in_time_pla_w`]). `None` for a radius outside the table.
    pub fn soften_reserve_w(&self, k: usize, radius_mm: f32) -> Option<Powers> {
        self.soften_reserve_at(k, radius_mm, self.in_time_pla_w(k))
    }

    /// [`Links::soften_reserve_w`] with link `k`'s in-time PLA power already worked out.
    fn soften_reserve_at(&self, k: usize, radius_mm: f32, in_time_w: f32) -> Option<Powers> {
        let mut r = self.ctrl[k].soften_reserve_w(radius_mm)?;
        r.pla_w = r.pla_w.max(in_time_w);
        Some(r)
    }

    /// The least PLA power that brings link `k`'s rod soft within half its soften timeout, W,
    /// on its thermal model (the calibration's convection, from its PLA's reading, the rest of
    /// the link at ambient; at most the PLA's cap): the power a soften under a budget is
    /// admitted with and never cut below. The controller's own reserve, 1.3 times what holds
    /// the rod soft, softens a rod in water within a time constant of some 20 s; in still air
    /// that constant is minutes, and a soften held to it met its timeout (docs/multilink.md).
    /// The half leaves room for the model's error and the bead's lag.
    ///
    /// The model is linear: its PLA node is `P u(t) + f(t)` above ambient, `u` its response to
    /// 1 W from ambient and `f` its free fall from the reading, so one run of each at the
    /// model's stable step gives the least `P` that reaches the threshold at some moment of
    /// the window. It runs in the serial task, within the control tick's time on the target
    /// (a bisection of whole runs here starved the control task into the watchdog).
    pub fn in_time_pla_w(&self, k: usize) -> f32 {
        use crate::lumped::{node, Network};
        let c = &self.ctrl[k];
        let m = c.measurements();
        let morph = &c.settings().morph;
        let amb_c = if m.t_amb_c.is_finite() {
            m.t_amb_c
        } else {
            20.0
        };
        let start_c = if m.t_pla_c.is_finite() {
            m.t_pla_c.max(amb_c)
        } else {
            amb_c
        };
        let rise_k = morph.soft_threshold_c - amb_c;
        let h = c.calibration().model_convection_w_m2k();
        let mut step = Network::new(h, amb_c);
        let mut free = step;
        free.temp_c[node::PLA] = start_c;
        let dt_s = step.max_stable_step_s();
        let window_s = 0.5 * morph.soften_timeout_s;
        let mut least_w = f32::INFINITY;
        let mut t_s = 0.0;
        while t_s < window_s {
            step.advance(dt_s, 0.0, 1.0, amb_c);
            free.advance(dt_s, 0.0, 0.0, amb_c);
            t_s += dt_s;
            let u_k = step.temp_c[node::PLA] - amb_c;
            let f_k = free.temp_c[node::PLA] - amb_c;
            if u_k > 0.0 {
                least_w = least_w.min((rise_k - f_k) / u_k);
            }
        }
        least_w.clamp(0.0, HeaterConfig::PLA.max_power_w)
    }

    /// Whether link `k` would refuse a MORPH on its own (busy, faulted, no reading, radius):
    /// it then answers it itself.
    fn refuses_morph(&self, k: usize, radius_mm: f32) -> bool {
        let c = &self.ctrl[k];
        c.busy()
            || c.fault().is_some()
            || !c.measurements().t_pla_c.is_finite()
            || c.soften_reserve_w(radius_mm).is_none()
    }

    /// Why link `k` cannot take a morph whose soften reserves `reserve_w` (`None`: a radius
    /// outside the table, which the link refuses itself) under the budget now, written in `l`;
    /// false if it can (started at once or queued).
    fn morph_checks(&self, k: usize, reserve_w: Option<Powers>, l: &mut OutLine) -> bool {
        if self.queued(k) {
            *l = protocol::format_error(&wire::ERR_QUEUED);
            return true;
        }
        if let Some(r) = reserve_w {
            let needs_w = budget::least_budget_w(r, self.count());
            if self.budget.binding() && needs_w > self.budget.budget_w {
                wire::morph_over_budget(l, needs_w, self.budget.budget_w);
                return true;
            }
        }
        false
    }

    /// A MORPH for link `k`: started at once where the budget has room for its soften (and
    /// no morph is queued ahead of it), else queued (`ok`, then `event: queued`).
    fn morph(
        &mut self,
        now_ms: u64,
        k: usize,
        radius_mm: f32,
        mode: Mode,
        out: &mut dyn FnMut(&str),
    ) {
        let cmd = Command::Morph { radius_mm, mode };
        let mut l = OutLine::new();
        // Once per MORPH: it runs the link's thermal model (`Links::in_time_pla_w`).
        let reserve = self.soften_reserve_w(k, radius_mm);
        if self.morph_checks(k, reserve, &mut l) {
            return out(&l);
        }
        if self.refuses_morph(k, radius_mm) {
            self.ctrl[k].handle(now_ms, cmd, out);
            return;
        }
        let reserve_w = reserve.unwrap_or_default();
        let ahead = (0..self.count()).any(|j| self.queued(j));
        let ohm = self.ctrl[k].heater_ohm();
        let fits = budget::admits(
            &self.budget,
            self.supply_v(),
            &self.demands(),
            reserve_w,
            ohm,
        );
        if !self.budget.binding() || (!ahead && fits) {
            self.soften_pla_w[k] = reserve_w.pla_w;
            self.ctrl[k].handle(now_ms, cmd, out);
            self.note_started(k);
            return;
        }
        self.queued[k] = Some(Queued {
            radius_mm,
            mode,
            reserve_w,
            at: self.next_order,
        });
        self.next_order = self.next_order.wrapping_add(1);
        out(protocol::OK);
        let needs_w = reserve_w.pla_w + reserve_w.tca_w;
        let free_w = (self.budget.budget_w - self.held_w()).max(0.0);
        let mut e = OutLine::new();
        wire::queued_event(&mut e, needs_w, free_w);
        self.push_event(k, &e);
    }

    /// GAIT and LINKS.
    fn links_command(&mut self, now_ms: u64, c: LinksCommand, out: &mut dyn FnMut(&str)) {
        let mut l = OutLine::new();
        match c {
            LinksCommand::Links => {
                let mut total_w = 0.0;
                for k in 0..self.count() {
                    let c = &self.ctrl[k];
                    let p = c.powers();
                    let r = c.reserve_w();
                    let s = self.shares[k];
                    total_w += p.pla_w + p.tca_w;
                    l.clear();
                    wire::links_row(
                        &mut l,
                        &wire::LinkRow {
                            link: k,
                            phase: c.phase(),
                            queued: self.queued(k),
                            power_w: p.pla_w + p.tca_w,
                            allow_w: s[0].allow_w.min(HeaterConfig::PLA.max_power_w)
                                + s[1].allow_w.min(HeaterConfig::TCA.max_power_w),
                            reserve_w: r.pla_w + r.tca_w,
                        },
                    );
                    out(&l);
                }
                l.clear();
                wire::links_end(
                    &mut l,
                    self.count(),
                    total_w,
                    self.budget.budget_w,
                    self.budget.limit_a,
                    self.supply_v(),
                );
                out(&l);
            }
            LinksCommand::Gait {
                radii_mm,
                count,
                mode,
            } => {
                if count != self.count() {
                    wire::gait_count(&mut l, count, self.count());
                    return out(&l);
                }
                // Every link is checked before any starts: a refused GAIT changes nothing.
                for (k, &r) in radii_mm[..count].iter().enumerate() {
                    let mut why = OutLine::new();
                    let reserve = self.soften_reserve_w(k, r);
                    if !self.morph_checks(k, reserve, &mut why) && self.refuses_morph(k, r) {
                        // The link's own refusal, asked of a copy so nothing changes.
                        why = self.refusal_of(k, r, mode);
                    }
                    if !why.is_empty() {
                        wire::gait_refused(&mut l, k, &why);
                        return out(&l);
                    }
                }
                for k in self.longest_first(&radii_mm[..count]) {
                    let r = radii_mm[k];
                    let mut first = OutLine::new();
                    self.morph(now_ms, k, r, mode, &mut |line: &str| {
                        if first.is_empty() {
                            let _ = first.push_str(line);
                        }
                    });
                }
                out(protocol::OK);
            }
        }
    }

    /// The links of a GAIT to `radii_mm` in the order their morphs are started or queued: the
    /// longest first (the most TCA power its table gives, link order among equals). A morph's
    /// length grows with its bend (a tighter radius heats the TCA further and the rod flows
    /// further), and a queue that starts the longest jobs first (list scheduling's
    /// longest-processing-time rule) keeps the short ones for the room the long ones leave,
    /// instead of a long morph starting last (docs/multilink.md, "The order of a gait").
    fn longest_first(&self, radii_mm: &[f32]) -> Vec<usize, N> {
        let tca_w = |k: usize| {
            self.ctrl[k]
                .soften_reserve_w(radii_mm[k])
                .map_or(0.0, |r| r.tca_w)
        };
        // Each link's power once, the most first.
        let mut order: Vec<(f32, usize), N> =
            (0..radii_mm.len().min(N)).map(|k| (-tca_w(k), k)).collect();
        budget::sort_stable_by(&mut order, |e| e.0);
        order.iter().map(|e| e.1).collect()
    }

    /// What link `k` answers a MORPH it refuses (busy, faulted, no reading, out of range),
    /// without starting anything: the refusals are the ones its own MORPH gives.
    fn refusal_of(&self, k: usize, radius_mm: f32, mode: Mode) -> OutLine {
        let c = &self.ctrl[k];
        let mut l = OutLine::new();
        if c.fault().is_some() || c.busy() || !c.measurements().t_pla_c.is_finite() {
            c.morph_refusal(&mut l);
        } else if c.soften_reserve_w(radius_mm).is_none() {
            let (min, max) = crate::table::range_mm();
            protocol::reply::radius_out_of_range(&mut l, min, max);
        }
        let _ = mode;
        l
    }

    /// `CONFIG SET supply_budget_w|supply_limit_a <value>`: range-checked against what the
    /// links need and what the supply gives; a refusal changes nothing.
    fn set_supply(&mut self, s: SupplySetting, text: &str, out: &mut dyn FnMut(&str)) {
        let mut l = OutLine::new();
        let value = crate::fixed::parse_decimal(text).unwrap_or(f32::NAN);
        match self.check_supply(s, value) {
            Ok(()) => {
                match s {
                    SupplySetting::BudgetW => self.budget.budget_w = value,
                    SupplySetting::LimitA => self.budget.limit_a = value,
                }
                wire::supply_set(&mut l, s, value);
            }
            Err(SupplyRefusal::Range(why)) => wire::supply_refused(&mut l, s, value, why),
            Err(SupplyRefusal::OverSupply(most_w)) => {
                wire::budget_over_supply(&mut l, value, most_w)
            }
            Err(SupplyRefusal::UnderReserves(held_w)) => {
                wire::budget_under_reserves(&mut l, value, held_w)
            }
            Err(SupplyRefusal::UnderQueued(needs_w, k)) => {
                wire::budget_under_queued(&mut l, value, needs_w, k)
            }
            Err(SupplyRefusal::UnderBudget(most_w)) => {
                wire::limit_under_budget(&mut l, value, most_w, self.budget.budget_w)
            }
        }
        out(&l);
    }

    /// What SAVE writes of the board's own settings with link `k`'s (0-based): the supply's
    /// budget and limit, with link 1's settings.
    pub fn board_record(&self, k: usize) -> Option<[u8; budget::SUPPLY_RECORD_BYTES]> {
        (k == 0).then(|| self.budget.to_bytes())
    }

    /// Puts the supply settings a SAVE kept in force at boot (`stored`: what link 1's store
    /// holds, `Ok(None)` if nothing), each checked as `CONFIG SET` checks it; anything else
    /// leaves the defaults. Either way an event says which. Call after every link's settings
    /// are loaded (the least budget depends on their calibrations).
    pub fn load_board(&mut self, stored: Result<Option<&[u8]>, ()>) {
        let why = match stored {
            Ok(Some(bytes)) => match budget::SupplyBudget::from_bytes(bytes) {
                Some(b) => {
                    let before = self.budget;
                    let limit = self.check_supply(SupplySetting::LimitA, b.limit_a);
                    if limit.is_ok() {
                        self.budget.limit_a = b.limit_a;
                    }
                    let budget = self.check_supply(SupplySetting::BudgetW, b.budget_w);
                    if limit.is_ok() && budget.is_ok() {
                        self.budget.budget_w = b.budget_w;
                        let mut l = OutLine::new();
                        wire::supply_loaded_event(&mut l, b.budget_w, b.limit_a);
                        self.push_board_event(l);
                        return;
                    }
                    self.budget = before;
                    wire::SupplyDefaults::OutOfRange
                }
                None => wire::SupplyDefaults::Format,
            },
            Ok(None) => wire::SupplyDefaults::Absent,
            Err(()) => wire::SupplyDefaults::Flash,
        };
        let mut l = OutLine::new();
        wire::supply_defaults_event(&mut l, why);
        self.push_board_event(l);
    }

    /// Queues a line of the board's own (no link's address).
    fn push_board_event(&mut self, line: OutLine) {
        if self.events.is_full() {
            self.events.pop_front();
        }
        let _ = self.events.push_back(line);
    }

    /// The least budget that lets every link soften its cheapest morph, W.
    pub fn least_budget_w(&self) -> f32 {
        let (min_mm, max_mm) = crate::table::range_mm();
        (0..self.count())
            .map(|k| {
                // The in-time power is the link's, whatever the radius: worked out once.
                let in_time_w = self.in_time_pla_w(k);
                [min_mm, max_mm]
                    .iter()
                    .filter_map(|&r| self.soften_reserve_at(k, r, in_time_w))
                    .map(|r| budget::least_budget_w(r, self.count()))
                    .fold(f32::INFINITY, f32::min)
            })
            .fold(0.0, f32::max)
    }

    fn check_supply(&self, s: SupplySetting, value: f32) -> Result<(), SupplyRefusal> {
        let v = self.supply_v();
        match s {
            SupplySetting::BudgetW => {
                let least = self.least_budget_w();
                if !(value.is_finite() && value > 0.0 && value <= budget::BUDGET_MAX_W) {
                    return Err(SupplyRefusal::Range(budget::BudgetError::OutOfRange {
                        min: least,
                        max: budget::BUDGET_MAX_W,
                    }));
                }
                if value < least {
                    return Err(SupplyRefusal::Range(budget::BudgetError::TooSmall {
                        least,
                    }));
                }
                let held = self.held_w();
                if value < held {
                    return Err(SupplyRefusal::UnderReserves(held));
                }
                // A queued morph must still fit once the links ahead of it are done.
                let n = self.count();
                if let Some((k, needs_w)) = (0..n)
                    .filter_map(|k| self.queued[k].map(|q| (k, q)))
                    .map(|(k, q)| (k, budget::least_budget_w(q.reserve_w, n)))
                    .find(|&(_, w)| value < w)
                {
                    return Err(SupplyRefusal::UnderQueued(needs_w, k));
                }
                let most_w = self.budget.limit_a * v;
                if self.budget.limit_a < budget::LIMIT_MAX_A && v.is_finite() && value > most_w {
                    return Err(SupplyRefusal::OverSupply(most_w));
                }
            }
            SupplySetting::LimitA => {
                if !(value.is_finite()
                    && (budget::LIMIT_MIN_A..=budget::LIMIT_MAX_A).contains(&value))
                {
                    return Err(SupplyRefusal::Range(budget::BudgetError::OutOfRange {
                        min: budget::LIMIT_MIN_A,
                        max: budget::LIMIT_MAX_A,
                    }));
                }
                // One heater's pulse alone must fit: the lowest resistance at the supply read.
                let v = if v.is_finite() {
                    v
                } else {
                    budget::NOMINAL_SUPPLY_V
                };
                // At each heater's resistance read or its nominal one, the lower: a heater read
                // warm (the TCA's resistance rises with its temperature) draws more once cold.
                let nominal = [
                    HeaterConfig::PLA.resistance_ohm,
                    HeaterConfig::TCA.resistance_ohm,
                ];
                let least = self
                    .ctrl
                    .iter()
                    .flat_map(|c| {
                        let ohm = c.heater_ohm();
                        [ohm[0].min(nominal[0]), ohm[1].min(nominal[1])]
                    })
                    .map(|ohm| v / ohm)
                    .fold(0.0, f32::max);
                if value < least {
                    return Err(SupplyRefusal::Range(budget::BudgetError::TooSmall {
                        least,
                    }));
                }
                // The budget must stay within what the lower limit gives.
                let most_w = value * v;
                if self.budget.budget_w < budget::BUDGET_MAX_W && self.budget.budget_w > most_w {
                    return Err(SupplyRefusal::UnderBudget(most_w));
                }
            }
        }
        Ok(())
    }
}

/// Why a supply setting was refused.
enum SupplyRefusal {
    Range(budget::BudgetError),
    OverSupply(f32),
    UnderReserves(f32),
    /// A budget under what a queued morph needs (W, its link).
    UnderQueued(f32, usize),
    /// A limit that gives less than the budget (W at the measured supply).
    UnderBudget(f32),
}

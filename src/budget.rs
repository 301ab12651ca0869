//! One supply shared by several links: the power budget, the supply's current limit, and the
//! scheduler that shares them out every tick (load management, as multi-zone heater
//! controllers do it).
//!
//! Each tick [`allocate`] gives every heater of every link an *allowance* (W) and a *phase*
//! (where in the PWM period its on-window starts) such that
//! - the allowances sum to at most the budget ([`SupplyBudget::budget_w`]), so whatever the
//!   controllers then ask, the summed power reckoned at the measured supply stays inside it;
//! - the on-windows, laid out at their phases with the duties of the allowances, never have
//!   heaters on together whose currents sum past the supply's limit
//!   ([`SupplyBudget::limit_a`]): each window is placed where the heaters already placed leave
//!   room for its current over its whole length (a window shorter than its allowance is an
//!   allowance cut to that length).
//!
//! Who gets what: first every link's *reserve* (what holds what it has already started: a
//! softened rod soft, a bending or locking TCA at its shape, a TUNE or HEAT step at its
//! power), then what each still asks, in priority order (fixed-power steps, then links holding
//! a shape, then links softening, each group oldest first). A morph is admitted only while the
//! reserves, its own included, fit the budget ([`admits`]): so a reserve is never cut to make
//! room for a later link, and no link is ever starved below what holds its shape.
//! docs/multilink.md has the long story and the measurements.

use crate::electrical::PROBE_DUTY;
use crate::heater::HeaterConfig;
use crate::vocab::{Heater, Powers};

/// Most links one board drives (the boards' channel tables, docs/bringup.md, carry at most
/// this many).
pub const MAX_LINKS: usize = 4;

/// Largest budget `supply_budget_w` takes, W: more than every heater of [`MAX_LINKS`] links at
/// its cap (4 × 7 W), so the default never binds and one link runs exactly as it did alone.
pub const BUDGET_MAX_W: f32 = 100.0;
/// Largest current limit `supply_limit_a` takes, A: above what [`MAX_LINKS`] links draw with
/// every heater on at 18 V (4 × 3.4 A), so the default never binds.
pub const LIMIT_MAX_A: f32 = 20.0;
/// The supply a current limit is judged at before the first reading, V (the boards' 12 V).
pub const NOMINAL_SUPPLY_V: f32 = 12.0;
/// Smallest current limit, A: below this no heater's pulse fits.
pub const LIMIT_MIN_A: f32 = 0.1;

/// A reserve is this many times the power that holds its part at its target at steady state:
/// a PLA held at 1.3× its holding power still reaches its soft threshold (about 60 % of the
/// way from ambient to that power's steady temperature) within one time constant, and the
/// margin covers a link whose losses exceed the model's by 30 %.
pub const RESERVE_MARGIN: f32 = 1.3;

/// Per tick a busy heater's allowance may exceed what it asked last tick by this share...
pub const GROWTH_SHARE: f32 = 0.25;
/// ...plus this, W: a heater whose model asks for more (a guard released, a new phase) gets
/// it within a few ticks, while unused allowance is lent to the links behind it.
pub const GROWTH_W: f32 = 0.2;

/// What a board's probe pulses (current sense: 10 µs a tick per heater) draw at most per
/// heater, W; kept out of the budget so the allocated powers plus the probes stay inside it
/// (2.2 mW into a 6.5 Ω TCA at 12 V).
pub const PROBE_RESERVE_W: f32 = 0.005;

/// The supply the links share.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SupplyBudget {
    /// Most power all heaters together may take, W (reckoned at the measured supply and the
    /// resistances the controllers reckon with).
    pub budget_w: f32,
    /// Most current the supply gives, A: no instant of a PWM period has heaters on whose
    /// currents sum past it.
    pub limit_a: f32,
}

impl SupplyBudget {
    /// No budget and no current limit beyond the heaters' own caps: one link runs as alone.
    pub const UNLIMITED: SupplyBudget = SupplyBudget {
        budget_w: BUDGET_MAX_W,
        limit_a: LIMIT_MAX_A,
    };

    /// Whether this budget limits anything (the default does not).
    pub fn binding(&self) -> bool {
        self.budget_w < BUDGET_MAX_W || self.limit_a < LIMIT_MAX_A
    }

    /// The stored form SAVE writes beside link 1's settings: a format byte, then the budget
    /// and the limit as little-endian `f32`s. The map item's own CRC guards it; a load
    /// range-checks what it decodes as a `CONFIG SET` would.
    pub fn to_bytes(&self) -> [u8; SUPPLY_RECORD_BYTES] {
        let mut b = [0; SUPPLY_RECORD_BYTES];
        b[0] = SUPPLY_RECORD_FORMAT;
        b[1..5].copy_from_slice(&self.budget_w.to_le_bytes());
        b[5..9].copy_from_slice(&self.limit_a.to_le_bytes());
        b
    }

    /// Decodes [`SupplyBudget::to_bytes`]; `None` for another length or format.
    pub fn from_bytes(b: &[u8]) -> Option<SupplyBudget> {
        let b: &[u8; SUPPLY_RECORD_BYTES] = b.try_into().ok()?;
        if b[0] != SUPPLY_RECORD_FORMAT {
            return None;
        }
        let f = |i: usize| f32::from_le_bytes([b[i], b[i + 1], b[i + 2], b[i + 3]]);
        Some(SupplyBudget {
            budget_w: f(1),
            limit_a: f(5),
        })
    }
}

/// Length of the supply's stored form, bytes ([`SupplyBudget::to_bytes`]).
pub const SUPPLY_RECORD_BYTES: usize = 9;
/// Format byte of the supply's stored form: a change of layout takes a new one, and an older
/// form then boots as the defaults.
const SUPPLY_RECORD_FORMAT: u8 = 1;

/// Why a budget was refused.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum BudgetError {
    /// Not a number in range: the range.
    OutOfRange {
        /// Smallest value, in the setting's unit.
        min: f32,
        /// Largest value, in the setting's unit.
        max: f32,
    },
    /// Too small for any morph's soften: the least value that works.
    TooSmall {
        /// The least value that lets one link soften, in the setting's unit.
        least: f32,
    },
}

/// What a link's activity is, for the scheduler's order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Class {
    /// A TUNE or HEAT step: fixed powers its fit or judgement depend on.
    Fixed,
    /// A morph in bend or lock: the TCA holds the shape, in bend the rod is held soft.
    Holding,
    /// A morph in soften.
    Softening,
    /// Nothing the budget must keep (idle, rest, release, faulted).
    Idle,
}

/// One link as the scheduler sees it this tick.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Demand {
    /// Its activity's class.
    pub class: Class,
    /// When its activity was admitted (lower runs first within a class).
    pub since: u32,
    /// What it asked last tick, before any allowance, W.
    pub wanted_w: Powers,
    /// What holds what it has started, W.
    pub reserve_w: Powers,
    /// The resistances its controller reckons with, Ω (PLA, TCA).
    pub ohm: [f32; 2],
    /// Current each heater draws while its gate is off, A (PLA, TCA): a MOSFET failed short
    /// behind a cut-off that did not open, 0 where none flows or current is not sensed. No
    /// allowance governs it, so the budget counts it first and the current limit is what it
    /// leaves.
    pub stray_a: [f32; 2],
}

/// The stray currents of `demands` (their [`Demand::stray_a`]), A, and what they take at
/// `supply_v`, W.
fn stray(demands: &[Demand], supply_v: f32) -> (f32, f32) {
    let a: f32 = demands.iter().map(|d| d.stray_a[0] + d.stray_a[1]).sum();
    (a, a * supply_v)
}

/// One heater's share of a tick.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Share {
    /// Most power the heater may take this tick, W.
    pub allow_w: f32,
    /// Where its on-window starts, as a fraction of the PWM period in [0, 1).
    pub phase: f32,
    /// Longest its on-window may be, fraction of the period: the room the current limit left
    /// it (1 where there is no limit). The shell clips a duty to it ([`clip_duty`]).
    pub window: f32,
}

impl Share {
    /// No allowance below the heater's cap, the window from the period's start, all of it.
    pub const UNLIMITED: Share = Share {
        allow_w: f32::INFINITY,
        phase: 0.0,
        window: 1.0,
    };
}

/// The windows are laid out for duties this share longer than the allowances give at the
/// supply read: a controller reads the supply again before it sets its duty, and 5 % of duty
/// covers a supply 2.4 % lower than the scheduler's reading.
pub const WINDOW_GUARD_SHARE: f32 = 0.05;

/// `duty` clipped to `share`'s window: the current limit holds at the output stage whatever
/// the supply did between the scheduler's reading and the controller's.
pub fn clip_duty(duty: f32, share: &Share) -> f32 {
    duty.min(share.window)
}

/// The scheduler's answer for one link: PLA and TCA.
pub type LinkShare = [Share; 2];

/// Most on-windows a layout holds: two heaters a link, and a newcomer's two at admission.
const WINDOWS: usize = 2 * MAX_LINKS + 2;

/// The heaters' current profile over one PWM period: on-windows already placed.
#[derive(Clone, Copy, Debug)]
struct Profile {
    /// (start, length, amps), start and length as fractions of the period.
    windows: [(f32, f32, f32); WINDOWS],
    n: usize,
}

impl Profile {
    const EMPTY: Profile = Profile {
        windows: [(0.0, 0.0, 0.0); WINDOWS],
        n: 0,
    };

    /// Summed current at instant `t` of the period, A.
    fn amps_at(&self, t: f32) -> f32 {
        self.windows[..self.n]
            .iter()
            .filter(|(s, len, _)| covers(*s, *len, t))
            .map(|w| w.2)
            .sum()
    }

    /// Where a window of `want` (≤ 1) drawing `amps` goes: the earliest start with room for
    /// all of it under `limit_a` (first fit), else the start with the most room; `(start,
    /// length)`. Candidates start at 0 and where a placed window ends.
    fn place(&self, amps: f32, want: f32, limit_a: f32) -> (f32, f32) {
        if want <= 0.0 {
            return (0.0, 0.0);
        }
        let mut starts = [0.0f32; WINDOWS + 1];
        for (j, (s, len, _)) in self.windows[..self.n].iter().enumerate() {
            starts[j + 1] = frac(s + len);
        }
        let starts = &mut starts[..=self.n];
        sort(starts);
        let mut best = (0.0, 0.0);
        for &start in starts.iter() {
            let len = self.room(start, amps, want, limit_a);
            if len > best.1 + 1e-6 {
                best = (start, len);
            }
            if best.1 >= want - 1e-6 {
                break;
            }
        }
        best
    }

    /// How long from `start` (at most `want`) `amps` more stay under `limit_a`.
    fn room(&self, start: f32, amps: f32, want: f32, limit_a: f32) -> f32 {
        // The profile changes only where a window starts or ends: check each piece.
        let mut edges: [f32; 2 * WINDOWS + 1] = [1.0; 2 * WINDOWS + 1];
        let mut k = 0;
        for (s, len, _) in &self.windows[..self.n] {
            for e in [*s, frac(s + len)] {
                edges[k] = frac(e - start);
                k += 1;
            }
        }
        edges[k] = 1.0;
        let edges = &mut edges[..=k];
        sort(edges);
        let mut from = 0.0;
        for &to in edges.iter() {
            if to <= from {
                continue;
            }
            let mid = frac(start + 0.5 * (from + to));
            if self.amps_at(mid) + amps > limit_a + 1e-6 {
                return from.min(want);
            }
            if to >= want {
                return want;
            }
            from = to;
        }
        want
    }

    fn push(&mut self, start: f32, len: f32, amps: f32) {
        if self.n < WINDOWS {
            self.windows[self.n] = (start, len, amps);
            self.n += 1;
        }
    }
}

/// `x` wrapped into [0, 1).
fn frac(x: f32) -> f32 {
    if !x.is_finite() {
        return 0.0;
    }
    // The values wrapped are sums and differences of a few fractions: a few steps at most.
    let mut f = x % 1.0;
    if f < 0.0 {
        f += 1.0;
    }
    if f >= 1.0 {
        0.0
    } else {
        f
    }
}

/// Whether the window (start `s`, length `len`, wrapping at the period's end) covers `t`.
fn covers(s: f32, len: f32, t: f32) -> bool {
    len > 0.0 && frac(t - s) < len
}

/// Insertion sort (a few dozen values, no allocation).
fn sort(v: &mut [f32]) {
    for i in 1..v.len() {
        let mut j = i;
        while j > 0 && v[j - 1] > v[j] {
            v.swap(j - 1, j);
            j -= 1;
        }
    }
}

/// The heater `h` of a link whose controller reckons with `ohm`.
fn heater(h: Heater, ohm: f32) -> HeaterConfig {
    let cfg = match h {
        Heater::Pla => HeaterConfig::PLA,
        Heater::Tca => HeaterConfig::TCA,
    };
    HeaterConfig {
        resistance_ohm: if ohm.is_finite() && ohm > 0.0 {
            ohm
        } else {
            cfg.resistance_ohm
        },
        ..cfg
    }
}

/// What the running links of `demands` hold, W: their reserves summed.
pub fn held_w(demands: &[Demand]) -> f32 {
    demands
        .iter()
        .filter(|d| d.class != Class::Idle)
        .map(|d| d.reserve_w.pla_w + d.reserve_w.tca_w)
        .sum()
}

/// The stray current of `demands`, A, if the budget cannot hold it beside the reserves of the
/// links that run (their reserves and it over `budget`'s power at `supply_v`, or it alone over
/// the current limit): a load no gate governs has taken what the scheduler promised them, so
/// they can no longer be kept safe where they are (a softened rod, a held bend) and must stop.
/// `None` where no current strays or the budget holds it.
pub fn overrun_a(budget: &SupplyBudget, supply_v: f32, demands: &[Demand]) -> Option<f32> {
    let (stray_a, stray_w) = stray(demands, supply_v);
    let held = held_w(demands);
    let over = held + stray_w > budget.budget_w || stray_a >= budget.limit_a;
    (stray_a > 0.0 && over).then_some(stray_a)
}

/// The least budget that lets a morph whose soften reserves `reserve_w` start on an idle
/// board, W.
pub fn least_budget_w(reserve_w: Powers, links: usize) -> f32 {
    reserve_w.pla_w + reserve_w.tca_w + PROBE_RESERVE_W * 2.0 * links as f32
}

/// Whether a morph reserving `reserve_w` on a link whose heaters are reckoned at `ohm` may
/// start beside the links of `demands` within `budget` at the supply `supply_v`: the
/// reserves, its own included, fit the power budget, and their on-windows (each at least the
/// current-sense probe's) fit under the current limit.
pub fn admits(
    budget: &SupplyBudget,
    supply_v: f32,
    demands: &[Demand],
    reserve_w: Powers,
    ohm: [f32; 2],
) -> bool {
    let (stray_a, stray_w) = stray(demands, supply_v);
    if held_w(demands) + stray_w + least_budget_w(reserve_w, demands.len()) > budget.budget_w {
        return false;
    }
    let v = usable_v(supply_v);
    if v == 0.0 || budget.limit_a >= LIMIT_MAX_A {
        return true;
    }
    let limit_a = budget.limit_a - stray_a;
    // The layout the scheduler will make: every link's reserve (an idle one's probes) and
    // the newcomer's, tallest first. The newcomer is whichever idle link asks.
    let mut all: heapless::Vec<Demand, { MAX_LINKS + 1 }> = heapless::Vec::new();
    for d in demands.iter().take(MAX_LINKS) {
        let mut d = *d;
        if d.class == Class::Idle {
            d.reserve_w = Powers::default();
        }
        let _ = all.push(d);
    }
    let _ = all.push(Demand {
        class: Class::Softening,
        since: u32::MAX,
        wanted_w: reserve_w,
        reserve_w,
        ohm,
        stray_a: [0.0; 2],
    });
    let mut heaters: heapless::Vec<(f32, f32), { 2 * MAX_LINKS + 2 }> = heapless::Vec::new();
    for d in &all {
        for h in [Heater::Pla, Heater::Tca] {
            let cfg = heater(h, d.ohm[h.index()]);
            let _ = heaters.push((cfg.resistance_ohm, window_for(&cfg, d.reserve_w.of(h), v)));
        }
    }
    heaters.sort_unstable_by(|a, b| a.0.total_cmp(&b.0));
    let mut profile = Profile::EMPTY;
    for (ohm, want) in heaters {
        let amps = v / ohm;
        let (start, len) = profile.place(amps, want, limit_a);
        if len + 1e-6 < want {
            return false;
        }
        profile.push(start, len, amps);
    }
    true
}

/// The heaters of the links in `order` (scheduler order), the largest current (lowest
/// resistance in `ohm`) first and in scheduler order among equals: tall windows laid out
/// first pack a current limit best.
fn tallest_first(
    order: &[usize],
    ohm: &[[f32; 2]; MAX_LINKS],
) -> heapless::Vec<(usize, Heater), WINDOWS> {
    let mut v: heapless::Vec<(usize, Heater), WINDOWS> = heapless::Vec::new();
    for &k in order {
        for h in [Heater::Pla, Heater::Tca] {
            let _ = v.push((k, h));
        }
    }
    sort_stable_by(&mut v, |e| {
        heater(e.1, ohm[e.0][e.1.index()]).resistance_ohm
    });
    v
}

/// Sorts `v` by `key`, ascending, equals kept in their order. An insertion sort: the scheduler
/// orders at most [`WINDOWS`] items, and core's sort takes 2.7 KiB of flash.
pub(crate) fn sort_stable_by<T>(v: &mut [T], key: impl Fn(&T) -> f32) {
    for i in 1..v.len() {
        let mut j = i;
        while j > 0 && key(&v[j - 1]) > key(&v[j]) {
            v.swap(j - 1, j);
            j -= 1;
        }
    }
}

/// The supply a layout is reckoned at, V (0: unknown, no layout).
fn usable_v(supply_v: f32) -> f32 {
    if supply_v.is_finite() && supply_v > 1.0 {
        supply_v
    } else {
        0.0
    }
}

/// The window a heater taking `w` (W) at `v` (V) is laid out with: its duty and the guard,
/// at least the current-sense probe's, at most the period.
fn window_for(cfg: &HeaterConfig, w: f32, v: f32) -> f32 {
    // `duty` is never NaN (0 for anything it cannot reckon).
    (cfg.duty(w, v) * (1.0 + WINDOW_GUARD_SHARE)).clamp(PROBE_DUTY, 1.0)
}

/// Shares `budget` among the links of `demands` for one tick at the measured supply
/// `supply_v` (see the module's comment). `out[k]` is link `k`'s share.
pub fn allocate(budget: &SupplyBudget, supply_v: f32, demands: &[Demand], out: &mut [LinkShare]) {
    let n = demands.len().min(out.len()).min(MAX_LINKS);
    // Order: class, then age, then link number.
    let mut order = [0usize; MAX_LINKS];
    for (i, o) in order.iter_mut().enumerate().take(n) {
        *o = i;
    }
    let key = |k: usize| (demands[k].class, demands[k].since, k);
    for i in 1..n {
        let mut j = i;
        while j > 0 && key(order[j - 1]) > key(order[j]) {
            order.swap(j - 1, j);
            j -= 1;
        }
    }
    let order = &order[..n];
    let (stray_a, stray_w) = stray(&demands[..n], supply_v);
    let limit_a = budget.limit_a - stray_a;
    let mut left_w = budget.budget_w - stray_w - PROBE_RESERVE_W * 2.0 * n as f32;
    let mut reserved = [[0.0f32; 2]; MAX_LINKS];
    let mut allow = [[0.0f32; 2]; MAX_LINKS];
    // What each heater may take at most this tick: its cap, and for a busy link what it
    // asked plus room to grow (a fixed-power step its whole step at once).
    let most = |k: usize, h: Heater| -> f32 {
        let d = &demands[k];
        let cap = heater(h, d.ohm[h.index()]).max_power_w;
        if d.class == Class::Idle {
            return 0.0;
        }
        let grown = d.wanted_w.of(h) * (1.0 + GROWTH_SHARE) + GROWTH_W;
        let grown = if d.class == Class::Fixed {
            grown.max(d.reserve_w.of(h))
        } else {
            grown
        };
        grown.min(cap)
    };
    // Pass 1: every reserve, in order; pass 2: the rest of what each may take, a link's TCA
    // before its PLA (the TCA reaching its target is what ends a bend).
    for pass in 0..2 {
        for &k in order {
            for h in [Heater::Tca, Heater::Pla] {
                let target = if pass == 0 {
                    demands[k].reserve_w.of(h).min(most(k, h))
                } else {
                    most(k, h)
                };
                let more = (target - allow[k][h.index()]).clamp(0.0, left_w.max(0.0));
                allow[k][h.index()] += more;
                left_w -= more;
                if pass == 0 {
                    reserved[k][h.index()] = allow[k][h.index()];
                }
            }
        }
    }
    let v = usable_v(supply_v);
    if v == 0.0 || budget.limit_a >= LIMIT_MAX_A {
        for &k in order {
            for i in 0..2 {
                out[k][i] = Share {
                    allow_w: allow[k][i],
                    ..Share::UNLIMITED
                };
            }
        }
        return;
    }
    // The on-windows, in the same order: first every probe and reserve, each where the
    // current limit leaves it room; then each grown to its whole allowance, where it is or
    // moved to where all of it fits.
    let mut profile = Profile::EMPTY;
    let mut slot = [[0usize; 2]; MAX_LINKS];
    let mut ohm = [[0.0f32; 2]; MAX_LINKS];
    for &k in order {
        ohm[k] = demands[k].ohm;
    }
    for (k, h) in tallest_first(order, &ohm) {
        let i = h.index();
        let cfg = heater(h, demands[k].ohm[i]);
        let amps = v / cfg.resistance_ohm;
        let want = window_for(&cfg, reserved[k][i], v);
        let (start, len) = profile.place(amps, want, limit_a);
        slot[k][i] = profile.n;
        profile.push(start, len, amps);
    }
    for &k in order {
        for h in [Heater::Pla, Heater::Tca] {
            let i = h.index();
            let cfg = heater(h, demands[k].ohm[i]);
            let j = slot[k][i];
            let (start, len, amps) = profile.windows[j];
            let want = window_for(&cfg, allow[k][i], v);
            // Grown where it is, or moved wherever the whole of it fits; never shrunk.
            let (start, len) = if want > len {
                profile.windows[j].1 = 0.0;
                let here = profile.room(start, amps, want, limit_a);
                let (s2, l2) = profile.place(amps, want, limit_a);
                let best = if l2 > here + 1e-6 {
                    (s2, l2)
                } else {
                    (start, here)
                };
                let best = if best.1 >= len { best } else { (start, len) };
                profile.windows[j] = (best.0, best.1, amps);
                best
            } else {
                (start, len)
            };
            let fits = len / (1.0 + WINDOW_GUARD_SHARE);
            let duty = cfg.duty(allow[k][i], v);
            out[k][i] = Share {
                allow_w: if fits < duty {
                    cfg.power_w(fits, v)
                } else {
                    allow[k][i]
                },
                phase: start,
                window: len,
            };
        }
    }
}

/// The highest summed current of the heaters' on-windows over one period, A: each heater `i`
/// on from `phase[i]` for `duty[i]` of the period (wrapping), drawing `amps[i]`. What the
/// tests and the simulated supply hold the layout to.
pub fn peak_amps(phase: &[f32], duty: &[f32], amps: &[f32]) -> f32 {
    let mut p = Profile::EMPTY;
    for i in 0..phase.len().min(WINDOWS) {
        p.push(frac(phase[i]), duty[i].clamp(0.0, 1.0), amps[i]);
    }
    // The peak is at some window's start.
    (0..p.n)
        .map(|i| p.amps_at(p.windows[i].0 + 1e-6))
        .fold(0.0, f32::max)
}

#[cfg(test)]
mod tests {
    #[test]
    fn the_supplys_stored_form_reads_back_and_refuses_another_format() {
        let b = SupplyBudget {
            budget_w: 8.5,
            limit_a: 3.0,
        };
        assert_eq!(SupplyBudget::from_bytes(&b.to_bytes()), Some(b));
        let mut other = b.to_bytes();
        other[0] = 2;
        assert_eq!(SupplyBudget::from_bytes(&other), None);
        assert_eq!(SupplyBudget::from_bytes(&other[..8]), None);
    }

    use super::*;
    use proptest::prelude::*;

    fn busy(class: Class, since: u32, wanted: (f32, f32), reserve: (f32, f32)) -> Demand {
        Demand {
            class,
            since,
            wanted_w: Powers {
                pla_w: wanted.0,
                tca_w: wanted.1,
            },
            reserve_w: Powers {
                pla_w: reserve.0,
                tca_w: reserve.1,
            },
            ohm: [30.0, 6.5],
            stray_a: [0.0; 2],
        }
    }

    #[test]
    fn an_unlimited_budget_gives_every_busy_heater_what_it_asks_in_phase() {
        let d = [busy(Class::Softening, 0, (5.0, 2.0), (2.0, 0.8))];
        let mut out = [[Share::default(); 2]; 1];
        allocate(&SupplyBudget::UNLIMITED, 12.0, &d, &mut out);
        assert_eq!(out[0][0].allow_w, 5.0);
        assert_eq!(out[0][1].allow_w, 2.0);
        assert_eq!((out[0][0].phase, out[0][1].phase), (0.0, 0.0));
        assert_eq!((out[0][0].window, out[0][1].window), (1.0, 1.0));
    }

    #[test]
    fn reserves_come_first_and_the_holding_link_before_the_softening_one() {
        let budget = SupplyBudget {
            budget_w: 5.0,
            limit_a: LIMIT_MAX_A,
        };
        let d = [
            busy(Class::Softening, 1, (5.0, 2.0), (1.5, 0.5)),
            busy(Class::Holding, 0, (2.0, 1.0), (1.5, 0.8)),
        ];
        let mut out = [[Share::default(); 2]; 2];
        allocate(&budget, 12.0, &d, &mut out);
        let sum: f32 = out.iter().flatten().map(|s| s.allow_w).sum();
        assert!(sum <= 5.0 + 1e-4, "{sum}");
        // Both reserves are met; the holding link then takes what it asks first.
        assert!(out[0][0].allow_w >= 1.5 && out[0][1].allow_w >= 0.5);
        assert!(out[1][0].allow_w >= 1.5 && out[1][1].allow_w >= 0.8);
        assert!(out[1][0].allow_w > 1.5);
    }

    #[test]
    fn idle_links_get_nothing() {
        let d = [busy(Class::Idle, 0, (1.0, 1.0), (0.0, 0.0))];
        let mut out = [[Share::default(); 2]; 1];
        allocate(&SupplyBudget::UNLIMITED, 12.0, &d, &mut out);
        assert_eq!(out[0][0].allow_w + out[0][1].allow_w, 0.0);
    }

    #[test]
    fn admission_needs_room_for_every_reserve() {
        let budget = SupplyBudget {
            budget_w: 5.0,
            limit_a: LIMIT_MAX_A,
        };
        let one = [busy(Class::Holding, 0, (2.0, 1.0), (2.0, 1.0))];
        let r = Powers {
            pla_w: 1.5,
            tca_w: 0.4,
        };
        assert!(admits(&budget, 12.0, &one, r, [30.0, 6.5]));
        let r = Powers {
            pla_w: 2.5,
            tca_w: 0.4,
        };
        assert!(!admits(&budget, 12.0, &one, r, [30.0, 6.5]));
        // Under a 0.5 A limit only one 30 ohm PLA (0.4 A) is on at a time: two reserves of
        // 3 W (62.5 % duty each) do not fit one period, two of 2 W (42 %) do.
        let tight = SupplyBudget {
            budget_w: 50.0,
            limit_a: 0.5,
        };
        let pla = |w: f32| Powers {
            pla_w: w,
            tca_w: 0.0,
        };
        // (Both heaters of 30 ohm here: a 6.5 ohm TCA's probe alone would pass 0.5 A.)
        let thirty = |d: Demand| Demand {
            ohm: [30.0, 30.0],
            ..d
        };
        let one = [thirty(busy(Class::Holding, 0, (3.0, 0.0), (3.0, 0.0)))];
        assert!(!admits(&tight, 12.0, &one, pla(3.0), [30.0, 30.0]));
        let one = [thirty(busy(Class::Holding, 0, (2.0, 0.0), (2.0, 0.0)))];
        assert!(admits(&tight, 12.0, &one, pla(2.0), [30.0, 30.0]));
    }

    #[test]
    fn a_stray_current_overruns_the_budget_only_past_the_running_reserves_or_the_limit() {
        let mut stuck = busy(Class::Idle, 0, (0.0, 0.0), (0.0, 0.0));
        stuck.stray_a = [0.0, 1.8];
        let holding = busy(Class::Holding, 1, (2.0, 1.0), (2.0, 1.0));
        let at = |budget_w, limit_a| SupplyBudget { budget_w, limit_a };
        // 21.6 W at 12 V beside a 3 W reserve: over 24 W, not over 25 W.
        assert_eq!(
            overrun_a(&at(24.0, 3.0), 12.0, &[stuck, holding]),
            Some(1.8)
        );
        assert_eq!(overrun_a(&at(25.0, 3.0), 12.0, &[stuck, holding]), None);
        // The stray alone at the current limit.
        assert_eq!(
            overrun_a(&at(40.0, 1.8), 12.0, &[stuck, holding]),
            Some(1.8)
        );
        // No stray, or nothing running beside one the budget holds: nothing to stop.
        assert_eq!(overrun_a(&at(1.0, 3.0), 12.0, &[holding]), None);
        let idle = busy(Class::Idle, 1, (0.0, 0.0), (0.0, 0.0));
        assert_eq!(overrun_a(&at(22.0, 3.0), 12.0, &[stuck, idle]), None);
    }

    #[test]
    fn a_current_no_gate_governs_is_counted_before_every_allowance() {
        // Link 1 faulted with its TCA MOSFET shorted behind a stuck cut-off: 1.8 A flow, its
        // gate off. Link 2 asks for its TCA's whole power on a 3 A supply.
        let budget = SupplyBudget {
            budget_w: 40.0,
            limit_a: 3.0,
        };
        let mut stuck = busy(Class::Idle, 0, (0.0, 0.0), (0.0, 0.0));
        stuck.stray_a = [0.0, 1.8];
        let d = [stuck, busy(Class::Holding, 1, (0.0, 20.0), (0.0, 3.0))];
        let mut out = [[Share::default(); 2]; 2];
        allocate(&budget, 12.0, &d, &mut out);
        let tca = heater(Heater::Tca, 6.5);
        let duty = tca.duty(out[1][1].allow_w, 12.0).min(out[1][1].window);
        let peak = 1.8 + peak_amps(&[out[1][1].phase], &[duty], &[12.0 / 6.5]);
        // Any instant with link 2's TCA on draws 1.8 + 1.85 A, over 3 A: it may not be on.
        assert!(peak <= 3.0 + 1e-3, "peak {peak} A, duty {duty}");
        assert_eq!(out[1][1].allow_w, 0.0);
        // Its PLA (0.4 A) fits beside the stray current.
        let d = [stuck, busy(Class::Holding, 1, (2.0, 0.0), (2.0, 0.0))];
        allocate(&budget, 12.0, &d, &mut out);
        assert!(out[1][0].allow_w > 1.9, "{}", out[1][0].allow_w);
        // The power budget counts the stray 21.6 W too.
        let tight = SupplyBudget {
            budget_w: 25.0,
            limit_a: LIMIT_MAX_A,
        };
        allocate(&tight, 12.0, &d, &mut out);
        assert!(
            out[1][1].allow_w <= 25.0 - 21.6 + 1e-3,
            "{}",
            out[1][1].allow_w
        );
        assert!(!admits(
            &tight,
            12.0,
            &d,
            Powers {
                pla_w: 3.0,
                tca_w: 0.5
            },
            [30.0, 6.5]
        ));
    }

    #[test]
    fn two_tcas_that_together_pass_the_limit_are_never_on_at_once() {
        let budget = SupplyBudget {
            budget_w: 50.0,
            limit_a: 2.5,
        };
        let d = [
            busy(Class::Holding, 0, (0.0, 2.0), (0.0, 2.0)),
            busy(Class::Holding, 1, (0.0, 2.0), (0.0, 2.0)),
        ];
        let mut out = [[Share::default(); 2]; 2];
        allocate(&budget, 12.0, &d, &mut out);
        let cfg = HeaterConfig::TCA;
        let duty = [
            cfg.duty(out[0][1].allow_w, 12.0),
            cfg.duty(out[1][1].allow_w, 12.0),
        ];
        let amps = [12.0 / 6.5; 2];
        let peak = peak_amps(&[out[0][1].phase, out[1][1].phase], &duty, &amps);
        assert!(peak <= 2.5, "{peak}");
        assert!(out[0][1].allow_w > 1.9 && out[1][1].allow_w > 1.9);
    }

    proptest! {
        #[test]
        fn the_budget_and_the_current_limit_hold_for_any_demands(
            budget_w in 0.5f32..30.0,
            limit_a in 0.5f32..8.0,
            supply_v in 6.0f32..18.0,
            links in proptest::collection::vec(
                (0u8..4, 0u32..10, 0.0f32..6.0, 0.0f32..3.0, 0.0f32..3.0, 0.0f32..1.0,
                 20.0f32..40.0, 4.0f32..9.0),
                1..=MAX_LINKS),
        ) {
            let budget = SupplyBudget { budget_w, limit_a };
            let class = [Class::Fixed, Class::Holding, Class::Softening, Class::Idle];
            let d: heapless::Vec<Demand, MAX_LINKS> = links.iter().map(|l| Demand {
                class: class[l.0 as usize],
                since: l.1,
                wanted_w: Powers { pla_w: l.2, tca_w: l.3 },
                reserve_w: Powers { pla_w: l.4, tca_w: l.5 },
                ohm: [l.6, l.7],
                stray_a: [0.0; 2],
            }).collect();
            let mut out = [[Share::default(); 2]; MAX_LINKS];
            allocate(&budget, supply_v, &d, &mut out[..d.len()]);
            let mut phase = heapless::Vec::<f32, WINDOWS>::new();
            let mut duty = heapless::Vec::<f32, WINDOWS>::new();
            let mut amps = heapless::Vec::<f32, WINDOWS>::new();
            let mut sum = 0.0;
            for (k, s) in out[..d.len()].iter().enumerate() {
                for h in [Heater::Pla, Heater::Tca] {
                    let cfg = heater(h, d[k].ohm[h.index()]);
                    let share = s[h.index()];
                    prop_assert!(share.allow_w >= 0.0 && share.allow_w <= cfg.max_power_w + 1e-4);
                    prop_assert!((0.0..1.0).contains(&share.phase));
                    sum += share.allow_w;
                    phase.push(share.phase).unwrap();
                    let d = cfg.duty(share.allow_w, supply_v);
                    prop_assert!(d <= share.window + 1e-4, "duty {} past its window {}", d, share.window);
                    // The shell clips to the window: lay out the windows themselves.
                    duty.push(share.window.min(1.0)).unwrap();
                    amps.push(supply_v / cfg.resistance_ohm).unwrap();
                }
            }
            prop_assert!(sum <= budget_w + 1e-3, "sum {} over {}", sum, budget_w);
            let peak = peak_amps(&phase, &duty, &amps);
            prop_assert!(peak <= limit_a + 1e-3, "peak {} over {}", peak, limit_a);
        }
    }
}

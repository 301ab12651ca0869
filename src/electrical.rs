//! The heaters seen electrically, on a board that senses their current: each heater's load
//! current through a low-side shunt and amplifier, sampled by the ADC inside its PWM on-time
//! and inside its off-time; the resistance that gives; and the checks an industrial heater
//! controller makes with it (Omron's heater-burnout and SSR-failure alarms): no current while
//! driven (open), current while not driven (short), a resistance out of its range, and current
//! after the supply's cut-off opened (cut-off failed). A board without current sense gives no
//! currents, and none of this runs (docs/safety.md, "Current sense").

use crate::fault::{Fault, FaultCode, Subject};
use crate::supervisor::Faults;
use crate::vocab::Heater;

/// Heater PWM frequency, Hz (every board's: `boards/src/stm32.rs`).
pub const PWM_HZ: f32 = 1000.0;
/// Shortest on-time the ADC samples inside, µs: the amplifier settles (an INA180 or the G4's
/// op-amp, a few µs) and one conversion fits with margin.
pub const MIN_SENSED_ON_US: f32 = 10.0;
/// The duty of that on-time (1 %). Where a heater's duty is lower (off included) and the
/// supply is connected, the board drives one probe pulse of [`MIN_SENSED_ON_US`] per control
/// tick and samples inside it, so a current is measured every tick, at idle too: 0.22 mJ a
/// tick into the 6.5 Ω TCA at 12 V, 2.2 mW, a few hundredths of a kelvin.
pub const PROBE_DUTY: f32 = MIN_SENSED_ON_US * PWM_HZ / 1e6;
/// Largest duty on a board that senses current: every period keeps an off-window of
/// [`MIN_SENSED_ON_US`], so a shorted MOSFET is seen at full drive too.
pub const MAX_SENSED_DUTY: f32 = 1.0 - PROBE_DUTY;

/// Load-current sense: a shunt and an amplifier per heater into an ADC channel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShuntSense {
    /// Shunt resistance, Ω.
    pub shunt_ohm: f32,
    /// Amplifier gain, V/V.
    pub gain: f32,
    /// ADC reference, V.
    pub vref_v: f32,
    /// Full scale of the summed reading, counts.
    pub full_scale_counts: u32,
}

impl ShuntSense {
    /// 50 mΩ into a gain-20 amplifier (INA180A1; the G431's op-amp at gain 16 is close): 1 V/A,
    /// so the 3.3 V ADC spans 3.3 A, above the TCA's 1.85 A at 12 V; a 12-bit count is 0.8 mA.
    pub const DEFAULT: ShuntSense = ShuntSense {
        shunt_ohm: 0.05,
        gain: 20.0,
        vref_v: 3.3,
        // The controller's summed 16 × 12-bit reading (held equal in `controller`).
        full_scale_counts: 16 * 4095,
    };

    /// Amperes per summed count.
    fn amps_per_count(&self) -> f32 {
        self.vref_v / (self.full_scale_counts as f32 * self.shunt_ohm * self.gain)
    }

    /// Current for a summed reading, A.
    pub fn amps(&self, counts: u32) -> f32 {
        counts as f32 * self.amps_per_count()
    }

    /// Summed reading for a current (the simulated board's ADC), counts.
    pub fn counts(&self, amps: f32) -> u32 {
        let c = amps / self.amps_per_count();
        if !(c > 0.0) {
            0
        } else if c > self.full_scale_counts as f32 {
            self.full_scale_counts
        } else {
            (c + 0.5) as u32
        }
    }
}

/// One tick's current readings, summed ADC counts as the thermistors' (in [`Heater::index`]
/// order): inside each heater's PWM on-time (or its probe pulse) and inside its off-time.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct CurrentCounts {
    /// Sampled while the heater's MOSFET is driven on.
    pub on: [u32; 2],
    /// Sampled while it is driven off.
    pub off: [u32; 2],
}

/// One tick's currents in amperes (as [`CurrentCounts`]).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Currents {
    /// While driven on, A.
    pub on_a: [f32; 2],
    /// While driven off, A.
    pub off_a: [f32; 2],
}

impl Currents {
    /// The readings of `counts` through `sense`.
    pub fn of(counts: &CurrentCounts, sense: &ShuntSense) -> Self {
        Currents {
            on_a: counts.on.map(|c| sense.amps(c)),
            off_a: counts.off.map(|c| sense.amps(c)),
        }
    }
}

/// Resistance range of the PLA heater, Ω: the 30 Ω wrap ±10 % as wound, its small coefficient
/// over 10–130 °C and the sense chain's ±3 %, with margin. Below it a partial short (turns
/// touching), above it a broken or loose wrap; the 6.5 Ω TCA wired to this channel reads far
/// below.
pub const PLA_OHM_RANGE: (f32, f32) = (21.0, 42.0);
/// Resistance range of the TCA, Ω: 6.5 Ω ±10 %, its temperature coefficient up to 2.25e-3/K
/// over 10–130 °C (+24 %), its strain term (±3 %) and the sense chain's ±3 %, with margin.
/// The 30 Ω wrap on this channel reads far above.
pub const TCA_OHM_RANGE: (f32, f32) = (4.5, 11.0);
const _: () = assert!(
    PLA_OHM_RANGE.0 < crate::heater::HeaterConfig::PLA.resistance_ohm
        && crate::heater::HeaterConfig::PLA.resistance_ohm < PLA_OHM_RANGE.1
        && TCA_OHM_RANGE.0 < crate::heater::HeaterConfig::TCA.resistance_ohm
        && crate::heater::HeaterConfig::TCA.resistance_ohm < TCA_OHM_RANGE.1
        && TCA_OHM_RANGE.1 < PLA_OHM_RANGE.0
);

/// A driven heater whose current is under this share of what its highest resistance would
/// draw is open (a broken lead, a burnt wrap, a MOSFET that never closes).
pub const OPEN_MAX_SHARE: f32 = 0.3;
/// Current while not driven above which a MOSFET conducts that should not (a short, a
/// MOSFET failed on), A: some ten times the sense chain's noise and offset (a few mA), under
/// a quarter of the PLA wrap's least current (its highest resistance at the lowest allowed
/// supply), so even a MOSFET that only partly conducts is seen.
pub const SHORT_MIN_A: f32 = 0.05;
const _: () = assert!(SHORT_MIN_A < 0.25 * crate::supervisor::SUPPLY_MIN_V / PLA_OHM_RANGE.1);
/// Consecutive ticks a reading must stay wrong before it trips: 2 (0.2 s), so one sample
/// taken while the duty changed (an ABORT during the ADC burst) never does, and every
/// electrical fault is named within 0.3 s of the tick it began in.
pub const ELECTRICAL_TICKS: u8 = 2;
/// Ticks after the cut-off opened before a current left is its failure, 3: its switch
/// (a P-MOSFET in µs, a relay in 10 ms) has opened by then, with a tick to spare.
pub const CUTOFF_SETTLE_TICKS: u8 = 3;
/// Weight of a new resistance reading in the filtered value the duties are computed with:
/// 0.3 a tick follows the TCA's resistance through its fastest heating (about 1 %/s) within a
/// few ticks, and averages the PLA's noisier reading (0.4 A) over about three.
pub const OHM_FILTER_WEIGHT: f32 = 0.3;

/// A TCA whose thermistor reads within this of the ambient one, undriven, is at rest, K: its
/// resistance then is the reference its own thermometer counts from. 1 K: two beads' tolerance
/// at rest, a twentieth of a morph's TCA rise.
pub const SELF_REST_MAX_K: f32 = 1.0;
/// Least weight of a rest tick's resistance in the reference: the reference is the mean of
/// the first 100 rest ticks, then follows with this weight (10 s), so the probe pulses' 0.2 %
/// noise a reading averages to about 0.03 %, a tenth of a kelvin's worth.
pub const REST_FILTER_WEIGHT: f32 = 0.01;
/// Rest ticks a reference at a new shape needs to be whole (the mean of the first ticks, as
/// [`REST_FILTER_WEIGHT`] says: 10 s).
const REST_WHOLE_TICKS: u16 = (1.0 / REST_FILTER_WEIGHT) as u16;
/// Two shapes this close are one, 1/m of curvature (a morph's estimate repeats to far better).
const SAME_SHAPE_PER_M: f32 = 1e-3;

/// A heater's on-current reads a supply sagging inside its pulse once it gives, at the
/// resistance read before, a voltage this share under the same frame's supply reading: a supply
/// shared by several links whose own current limit is under what their pulses draw together
/// falls into constant-current mode there (a TCA's pulse beside another's on a supply at its
/// limit drops 40 % or more). 0.15 is twice the drop a healthy bench supply's 0.1 Ω gives with
/// every heater of four links on at once (9 A: 7.5 %) and twenty times the PLA channel's noise
/// (3 mA on its 0.4 A; the chain's gain error cancels against the resistance read through it);
/// a heater's resistance moves under 0.2 % a tick. [`crate::links`] judges it, and only two
/// heaters or more at once are the supply's (one alone is its own resistance); such samples say
/// nothing of the heaters' resistance.
pub const PULSE_SAG_SHARE: f32 = 0.15;
const _: () = assert!(PULSE_SAG_SHARE > 0.05 && PULSE_SAG_SHARE < 1.0 - OPEN_MAX_SHARE);

/// The electrical checks' state: per heater, how long each reading has been wrong, and the
/// filtered resistance; the TCA's resistance at rest.
#[derive(Clone, Copy, Debug, Default)]
pub struct Electrical {
    open: [u8; 2],
    short: [u8; 2],
    range: [u8; 2],
    cutoff: u8,
    since_cut: u8,
    /// Filtered resistance of each heater, Ω (`None` before a reading).
    ohm: [Option<f32>; 2],
    /// This tick's currents (`None`: not sensed).
    now: Option<Currents>,
    /// The TCA's resistance at rest and the ambient it was read at (Ω, °C).
    rest: Option<(f32, f32)>,
    /// Rest ticks in the reference (up to `1 / REST_FILTER_WEIGHT`).
    rest_n: u16,
    /// The link's curvature when the reference was read, 1/m (NaN: unknown).
    rest_shape_per_m: f32,
    /// This tick's resistance of each heater, Ω, where it was read within its range.
    raw: [Option<f32>; 2],
    /// The next frame's on-sample of each heater was taken in a sagging supply
    /// ([`Electrical::note_sag`]).
    sag: [bool; 2],
}

/// What drove the heaters while a frame's currents were sampled: the last tick's outputs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Drive {
    /// Duties in [`Heater::index`] order.
    pub duty: [f32; 2],
    /// The supply's cut-off was closed.
    pub supply_on: bool,
}

fn range(h: Heater) -> (f32, f32) {
    match h {
        Heater::Pla => PLA_OHM_RANGE,
        Heater::Tca => TCA_OHM_RANGE,
    }
}

/// Counts ticks a condition holds; true once it has held `n` in a row.
fn persists(count: &mut u8, wrong: bool, n: u8) -> bool {
    *count = if wrong { count.saturating_add(1) } else { 0 };
    *count >= n
}

impl Electrical {
    /// True while current flows with the cut-off open, past its settling ticks, for
    /// [`ELECTRICAL_TICKS`] in a row: the cut-off failed (`cutoff-failed`), and what flows no
    /// gate and no cut-off of this link stops.
    pub fn cutoff_failed(&self) -> bool {
        self.cutoff >= ELECTRICAL_TICKS
    }

    /// Judges one frame's currents, sampled under `drive` from a supply of `supply_v` volts,
    /// pushing what is wrong to `out`; `None` (no current sense) judges nothing.
    pub fn check(
        &mut self,
        currents: Option<Currents>,
        drive: Drive,
        supply_v: f32,
        out: &mut Faults,
    ) {
        self.now = currents;
        self.raw = [None; 2];
        let sag = core::mem::take(&mut self.sag);
        let Some(c) = currents else {
            return;
        };
        let heater_fault = |code, h: Heater, value| Fault {
            code,
            subject: Subject::Heater(h),
            value,
        };
        if !drive.supply_on {
            // Whatever the gates do, a cut supply carries no current.
            self.since_cut = self.since_cut.saturating_add(1);
            let most = c.on_a.iter().chain(&c.off_a).fold(0.0f32, |m, &a| m.max(a));
            let left = self.since_cut > CUTOFF_SETTLE_TICKS && most > SHORT_MIN_A;
            if persists(&mut self.cutoff, left, ELECTRICAL_TICKS) {
                let _ = out.push(Fault {
                    code: FaultCode::CutoffFailed,
                    subject: Subject::Supply,
                    value: most,
                });
            }
            self.open = [0; 2];
            self.range = [0; 2];
            self.short = [0; 2];
            return;
        }
        self.since_cut = 0;
        self.cutoff = 0;
        for h in [Heater::Pla, Heater::Tca] {
            let i = h.index();
            let (lo_ohm, hi_ohm) = range(h);
            // The on-sample is inside the pulse or, below the probe duty, the probe pulse.
            let on_a = c.on_a[i];
            let open = on_a < OPEN_MAX_SHARE * supply_v / hi_ohm;
            if persists(&mut self.open[i], open, ELECTRICAL_TICKS) {
                let _ = out.push(heater_fault(FaultCode::HeaterOpen, h, on_a));
            }
            // The off-window exists below MAX_SENSED_DUTY, the controller's cap.
            let off_a = c.off_a[i];
            let short = drive.duty[i] <= MAX_SENSED_DUTY && off_a > SHORT_MIN_A;
            if persists(&mut self.short[i], short, ELECTRICAL_TICKS) {
                let _ = out.push(heater_fault(FaultCode::HeaterShort, h, off_a));
            }
            // A sagging supply is the supply's fault, judged once for every link; the tick
            // breaks this heater's run of out-of-range readings.
            if sag[i] {
                self.range[i] = 0;
            }
            if open || sag[i] {
                continue;
            }
            let r = supply_v / on_a;
            let out_of_range = !(lo_ohm..=hi_ohm).contains(&r);
            if persists(&mut self.range[i], out_of_range, ELECTRICAL_TICKS) {
                let _ = out.push(heater_fault(FaultCode::HeaterResistance, h, r));
            }
            if !out_of_range {
                self.raw[i] = Some(r);
                self.ohm[i] = Some(match self.ohm[i] {
                    Some(f) => f + OHM_FILTER_WEIGHT * (r - f),
                    None => r,
                });
            }
        }
    }

    /// The supply inside each heater's pulse as the frame's currents `c` give it under `drive`
    /// from a supply reading `supply_v`, V: the on-current times the resistance read before
    /// (NaN for a heater not yet read, one that reads open, or a supply cut). Under
    /// [`PULSE_SAG_SHARE`] below the supply's reading, the supply sags there.
    pub fn pulse_v(&self, c: &Currents, drive: Drive, supply_v: f32) -> [f32; 2] {
        [Heater::Pla, Heater::Tca].map(|h| {
            let (i, on_a) = (h.index(), c.on_a[h.index()]);
            match (drive.supply_on, self.ohm[i]) {
                (true, Some(r)) if on_a >= OPEN_MAX_SHARE * supply_v / range(h).1 => on_a * r,
                _ => f32::NAN,
            }
        })
    }

    /// The next frame's on-samples of the heaters `sag` marks were taken in a sagging supply:
    /// that frame judges neither their resistance nor takes it in.
    pub fn note_sag(&mut self, sag: [bool; 2]) {
        self.sag = sag;
    }

    /// Heater `h`'s filtered resistance, Ω, where current is sensed and it has been read.
    pub fn ohm(&self, h: Heater) -> Option<f32> {
        self.now.and(self.ohm[h.index()])
    }

    /// This tick's currents while driven on, A (`None`: not sensed).
    pub fn on_a(&self) -> Option<[f32; 2]> {
        self.now.map(|c| c.on_a)
    }

    /// Takes this tick's TCA resistance into its reference at ambient `t_amb_c` where the TCA is
    /// at rest: not driven and its thermistor within [`SELF_REST_MAX_K`] of ambient
    /// (`t_tca_c`), with the link at curvature `shape_per_m` (1/m, NaN: unknown). The reference
    /// before every MORPH and TUNE is the last one at rest. At a new shape (a morph has bent the
    /// link since) the reference is read afresh: the mean of its first `1 / REST_FILTER_WEIGHT`
    /// ticks, then followed with that weight.
    pub fn note_rest(&mut self, tca_driven: bool, t_tca_c: f32, t_amb_c: f32, shape_per_m: f32) {
        let (Some(r), false) = (self.raw[Heater::Tca.index()], tca_driven) else {
            return;
        };
        if !((t_tca_c - t_amb_c).abs() <= SELF_REST_MAX_K) {
            return;
        }
        let shape = self.rest_shape_per_m;
        if !((shape - shape_per_m).abs() <= SAME_SHAPE_PER_M
            || shape.is_nan() && shape_per_m.is_nan())
        {
            self.rest_n = 0;
            self.rest_shape_per_m = shape_per_m;
        }
        self.rest_n = self.rest_n.saturating_add(1);
        let w = (1.0 / self.rest_n as f32).max(REST_FILTER_WEIGHT);
        let (r0, t0) = self.rest.unwrap_or((r, t_amb_c));
        self.rest = Some((r0 + w * (r - r0), t0 + w * (t_amb_c - t0)));
    }

    /// The link's shape `from_per_m` turned out to be `to_per_m` (1/m of curvature; a measured
    /// radius): the rest reference read at it, or being read, is counted from the true one.
    pub fn retag_rest_shape(&mut self, from_per_m: f32, to_per_m: f32) {
        if self.rest_shape_per_m.to_bits() == from_per_m.to_bits() {
            self.rest_shape_per_m = to_per_m;
        }
    }

    /// The link's curvature when the TCA's rest reference was read, 1/m (NaN: unknown).
    pub fn rest_shape_per_m(&self) -> f32 {
        self.rest_shape_per_m
    }

    /// The shape of the rest reference once it is whole (the mean of `1 / REST_FILTER_WEIGHT`
    /// rest ticks at it), 1/m; None while one is being read.
    pub fn whole_rest_shape_per_m(&self) -> Option<f32> {
        (self.rest.is_some() && self.rest_n >= REST_WHOLE_TICKS).then_some(self.rest_shape_per_m)
    }

    /// The TCA's own resistance as its mean temperature, °C, with temperature coefficient
    /// `tcr_per_k`: the rest reference's ambient plus `(R/R₀ − 1)/α`. The sense chain's gain
    /// error cancels in the ratio; what is left is the coefficient's error, and the coil's
    /// strain since the reference (docs/safety.md, "The TCA as its own thermometer").
    pub fn tca_self_c(&self, tcr_per_k: f32) -> Option<f32> {
        let (r0, t0) = self.rest?;
        let r = self.ohm(Heater::Tca)?;
        let t = t0 + (r / r0 - 1.0) / tcr_per_k;
        t.is_finite().then_some(t)
    }

    /// Heater `h`'s resistance this tick, unfiltered, Ω, where it was read within its range.
    pub fn raw_ohm(&self, h: Heater) -> Option<f32> {
        self.raw[h.index()]
    }

    /// The TCA's resistance at rest and the ambient it was read at (Ω, °C).
    pub fn tca_rest(&self) -> Option<(f32, f32)> {
        self.rest
    }

    /// The TCA's filtered resistance over its value at rest, 1.
    pub fn tca_ratio(&self) -> Option<f32> {
        Some(self.ohm(Heater::Tca)? / self.rest?.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const ON: Drive = Drive {
        duty: [0.5, 0.05],
        supply_on: true,
    };

    fn healthy(v: f32) -> Currents {
        Currents {
            on_a: [v / 30.0, v / 6.5],
            off_a: [0.002, 0.003],
        }
    }

    fn run(e: &mut Electrical, c: Currents, d: Drive, ticks: usize) -> Faults {
        let mut all = Faults::new();
        for _ in 0..ticks {
            let mut f = Faults::new();
            e.check(Some(c), d, 12.0, &mut f);
            for x in f {
                let _ = all.push(x);
            }
        }
        all
    }

    /// One rest tick with the TCA at `ohm` (its heater probed, not driven) in 22 °C surroundings
    /// with the link at `shape_per_m`; the strain report it gives, if any.
    fn rest_tick(e: &mut Electrical, ohm: f32, shape_per_m: f32) {
        let idle = Drive {
            duty: [0.0; 2],
            supply_on: true,
        };
        let c = Currents {
            on_a: [0.4, 12.0 / ohm],
            off_a: [0.0; 2],
        };
        let mut f = Faults::new();
        e.check(Some(c), idle, 12.0, &mut f);
        e.note_rest(false, 22.2, 22.0, shape_per_m)
    }

    #[test]
    fn a_new_shapes_rest_reference_is_read_afresh_and_whole_after_its_first_ticks() {
        let mut e = Electrical::default();
        for _ in 0..150 {
            rest_tick(&mut e, 6.5, 20.0);
        }
        assert_eq!(e.rest_shape_per_m(), 20.0);
        assert_eq!(e.whole_rest_shape_per_m(), Some(20.0));
        // Bent 10 /m tighter, the coil reads 0.3 % lower: the reference follows it once whole.
        let bent = 6.5 * (1.0 - 0.003);
        for k in 0..REST_WHOLE_TICKS {
            rest_tick(&mut e, bent, 30.0);
            let whole = k + 1 == REST_WHOLE_TICKS;
            assert_eq!(e.whole_rest_shape_per_m().is_some(), whole, "tick {k}");
        }
        assert_eq!(e.whole_rest_shape_per_m(), Some(30.0));
        assert!((e.tca_self_c(1.5e-3).unwrap() - 22.0).abs() < 0.05);
        // A measured shape re-tags it; an unknown shape (NaN) is a shape of its own.
        e.retag_rest_shape(30.0, 31.0);
        assert_eq!(e.rest_shape_per_m(), 31.0);
        rest_tick(&mut e, bent, f32::NAN);
        assert!(e.rest_shape_per_m().is_nan());
        assert_eq!(e.whole_rest_shape_per_m(), None);
        // A warm TCA is not at rest: nothing is read.
        e.note_rest(false, 30.0, 22.0, 40.0);
        assert!(e.rest_shape_per_m().is_nan());
    }

    #[test]
    fn a_healthy_link_reads_its_resistances_and_trips_nothing() {
        let mut e = Electrical::default();
        assert!(run(&mut e, healthy(12.0), ON, 50).is_empty());
        assert!((e.ohm(Heater::Pla).unwrap() - 30.0).abs() < 0.01);
        assert!((e.ohm(Heater::Tca).unwrap() - 6.5).abs() < 0.01);
        // Idle: both off, the probe pulse still reads the heaters.
        let idle = Drive {
            duty: [0.0; 2],
            supply_on: true,
        };
        assert!(run(&mut e, healthy(12.0), idle, 50).is_empty());
    }

    #[test]
    fn each_fault_trips_after_two_ticks_and_not_after_one() {
        let cases: [(Currents, FaultCode, Heater); 4] = [
            (
                Currents {
                    on_a: [0.0, 12.0 / 6.5],
                    ..healthy(12.0)
                },
                FaultCode::HeaterOpen,
                Heater::Pla,
            ),
            (
                Currents {
                    off_a: [0.0, 12.0 / 6.5],
                    ..healthy(12.0)
                },
                FaultCode::HeaterShort,
                Heater::Tca,
            ),
            (
                Currents {
                    on_a: [12.0 / 15.0, 12.0 / 6.5],
                    ..healthy(12.0)
                },
                FaultCode::HeaterResistance,
                Heater::Pla,
            ),
            (
                // The wrap on the TCA's channel.
                Currents {
                    on_a: [0.4, 12.0 / 30.0],
                    ..healthy(12.0)
                },
                FaultCode::HeaterResistance,
                Heater::Tca,
            ),
        ];
        for (c, code, h) in cases {
            let mut e = Electrical::default();
            assert!(run(&mut e, c, ON, 1).is_empty(), "{code:?} after one tick");
            let f = run(&mut e, c, ON, 1);
            assert_eq!(f.len(), 1, "{code:?}: {f:?}");
            assert_eq!((f[0].code, f[0].subject), (code, Subject::Heater(h)));
        }
    }

    #[test]
    fn a_current_left_after_the_cut_off_opened_is_its_failure() {
        let cut = Drive {
            duty: [0.0; 2],
            supply_on: false,
        };
        let mut e = Electrical::default();
        // The switch's own settling time, then a clean cut: nothing.
        let stuck = Currents {
            on_a: [0.0, 1.8],
            off_a: [0.0, 1.8],
        };
        assert!(run(&mut e, stuck, cut, CUTOFF_SETTLE_TICKS as usize).is_empty());
        assert!(run(&mut e, Currents::default(), cut, 50).is_empty());
        let mut e = Electrical::default();
        let f = run(&mut e, stuck, cut, CUTOFF_SETTLE_TICKS as usize + 2);
        assert_eq!(f.len(), 1);
        assert_eq!(
            (f[0].code, f[0].subject),
            (FaultCode::CutoffFailed, Subject::Supply)
        );
        // No current sense: nothing judged, nothing read.
        let mut e = Electrical::default();
        let mut f = Faults::new();
        e.check(None, ON, 12.0, &mut f);
        assert!(f.is_empty() && e.ohm(Heater::Tca).is_none());
    }

    #[test]
    fn counts_and_amps_round_trip() {
        let s = ShuntSense::DEFAULT;
        for a in [0.0f32, 0.05, 0.4, 1.85, 3.0] {
            assert!((s.amps(s.counts(a)) - a).abs() < 1e-3, "{a}");
        }
        assert_eq!(s.counts(f32::NAN), 0);
        assert_eq!(s.counts(100.0), s.full_scale_counts);
    }
}

//! The controller: `step(now, inputs) -> outputs` once per control tick, and protocol lines in,
//! reply lines out. It owns the supervisor and the sequencer and is all the firmware, the
//! simulator and the emulated image need: they only move ADC counts in and duties out.
//!
//! Per tick: ADC counts → classified temperatures and supply volts → supervisor (a trip turns
//! both heaters off in this same tick and latches) → the one activity that runs (a morph's
//! sequencer, a TUNE or a HEAT pulse: [`crate::activity`]) → watts → PWM duties.

use crate::activity::{Activity, Busy, Start};
use crate::calibration::{Calibration, CalibrationError, ReportRejection};
use crate::electrical::{CurrentCounts, Currents, Drive, Electrical, ShuntSense, MAX_SENSED_DUTY};
use crate::heater::HeaterConfig;
use crate::part_limit::{under_ceiling_w, CEILING_MARGIN_K};
use crate::protocol::{self, reply, tune_reply, Command, Mode, OutLine, SimCommand};
use crate::pulse::Pulse;
use crate::sequencer::{SeqEvent, Sequencer};
use crate::settings::codec::{self, Blob, LoadError};
use crate::settings::store::{Loaded, SaveReport, StoreError};
use crate::settings::{SetError, Settings, Spec, CALIBRATION_SPECS};
use crate::shape::{self, Outcome, RestShape, ShapeEvent};
use crate::stats::LoopTiming;
use crate::strategy::model::MODEL_KEEP_ALIVE_W;
use crate::supervisor::{Fault, FaultCode, Faults, Frame, Subject, Supervisor};
use crate::table;
use crate::thermistor::ThermistorConfig;
use crate::tune::{Tune, TuneEvent, TuneFailure, TuneTick};
use crate::vocab::{Doing, Heater, Measurements, Phase, Powers};
use heapless::Deque;

/// Control rate, Hz. The fastest thermal part (the TCA, about 1 s) is sampled ten times per
/// time constant; thermistors lag 2–10 s, so faster control would see nothing new.
pub const CONTROL_HZ: u32 = 10;
/// Control period, ms.
pub const TICK_MS: u64 = 1000 / CONTROL_HZ as u64;
// The tick divides the second exactly (timestamps and timeouts count whole ticks).
const _: () = assert!(TICK_MS * CONTROL_HZ as u64 == 1000);
// A stale frame is 10 ticks old (supervisor::STALE_AFTER_MS), and the heater command watchdog
// outlasts the same 10 missed ticks (heater::CommandWatchdog::DEFAULT_MAX_AGE_MS): one late
// tick never trips either.
const _: () = assert!(crate::supervisor::STALE_AFTER_MS >= 10 * TICK_MS);
const _: () = assert!(crate::heater::CommandWatchdog::DEFAULT_MAX_AGE_MS >= 10 * TICK_MS);
/// ADC samples summed per reading (16 × 12-bit: 1 °C steps become about 0.03 °C, and mains
/// noise averages out over the 16 ms burst).
pub const OVERSAMPLE: u32 = 16;
/// Full scale of one summed reading, counts.
pub const FULL_SCALE_COUNTS: u32 = OVERSAMPLE * 4095;
const _: () = assert!(ShuntSense::DEFAULT.full_scale_counts == FULL_SCALE_COUNTS);

/// Heater-supply sense: a resistor divider into an ADC channel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SupplySense {
    /// ADC reference, V.
    pub vref_v: f32,
    /// Supply volts per ADC-pin volt: (R_top + R_bottom) / R_bottom.
    pub divider_ratio: f32,
    /// Full scale of the summed reading, counts.
    pub full_scale_counts: u32,
}

impl SupplySense {
    /// 47 kΩ over 10 kΩ from the supply to a 3.3 V ADC: 12 V reads 2.1 V, 18.8 V is full scale.
    pub const DEFAULT: SupplySense = SupplySense {
        vref_v: 3.3,
        divider_ratio: 5.7,
        full_scale_counts: FULL_SCALE_COUNTS,
    };

    /// Supply voltage for a summed reading, V.
    pub fn volts(&self, counts: u32) -> f32 {
        counts as f32 / self.full_scale_counts as f32 * self.vref_v * self.divider_ratio
    }

    /// Summed reading for a supply voltage (used by the simulator), counts.
    pub fn counts(&self, volts: f32) -> u32 {
        let c = volts / (self.vref_v * self.divider_ratio) * self.full_scale_counts as f32;
        if c.is_nan() || c < 0.0 {
            0
        } else if c > self.full_scale_counts as f32 {
            self.full_scale_counts
        } else {
            (c + 0.5) as u32
        }
    }
}

/// Board-level settings of the controller.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Config {
    /// The three thermistor channels (same part and pull-up).
    pub thermistor: ThermistorConfig,
    /// Supply sense.
    pub supply: SupplySense,
    /// PLA heater.
    pub pla_heater: HeaterConfig,
    /// TCA heater.
    pub tca_heater: HeaterConfig,
    /// Load-current sense, where the board has it (its frames then carry
    /// [`Inputs::current`]).
    pub shunt: ShuntSense,
}

impl Config {
    /// 10 kΩ B3950 NTCs with 10 kΩ pull-ups, 16× oversampled 12-bit ADC, 12 V supply sense,
    /// 30 Ω PLA wrap and 6.5 Ω TCA.
    pub const DEFAULT: Config = Config {
        thermistor: ThermistorConfig::DEFAULT.with_full_scale(FULL_SCALE_COUNTS),
        supply: SupplySense::DEFAULT,
        pla_heater: HeaterConfig::PLA,
        tca_heater: HeaterConfig::TCA,
        shunt: ShuntSense::DEFAULT,
    };
}

/// One tick's raw inputs.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Inputs {
    /// Summed ADC counts of the thermistors, in [`crate::vocab::Sensor::index`] order (PLA,
    /// TCA, ambient).
    pub thermistor_counts: [u32; 3],
    /// Summed ADC counts of the supply sense.
    pub supply_counts: u32,
    /// When these samples were taken, ms.
    pub sample_ms: u64,
    /// Both heaters' load currents, on a board that senses them (`None`: the paper's
    /// wiring, thermistors only).
    pub current: Option<CurrentCounts>,
}

/// One tick's outputs: PWM duties in [0, 1] and the supply's cut-off. The default is the safe
/// state: both heaters off and the supply cut.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Outputs {
    /// PLA heater duty.
    pub pla_duty: f32,
    /// TCA heater duty.
    pub tca_duty: f32,
    /// The heater supply's cut-off is closed (the heaters have a supply). Open at reset and
    /// from any trip until RESET; closed once a tick's checks have passed with no fault.
    pub supply_on: bool,
}

impl Outputs {
    /// Idle with nothing latched: both heaters off, the supply connected.
    pub const IDLE: Outputs = Outputs {
        pla_duty: 0.0,
        tca_duty: 0.0,
        supply_on: true,
    };
}

/// Something to tell the user unprompted.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Event {
    /// Sequencer progress.
    Seq(SeqEvent),
    /// A safety trip.
    Alarm(Fault),
    /// What the boot did with the stored settings.
    Config(ConfigEvent),
    /// `TUNE` progress.
    Tune(TuneEvent),
    /// What a rest at a new shape gave ([`crate::shape`]).
    Shape(ShapeEvent),
}

/// What the boot did with the stored settings ([`Controller::load_settings`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ConfigEvent {
    /// The stored settings are in force: the newest SAVE's, or (`newest_skipped` says why the
    /// newest could not be used) an older one's.
    Loaded {
        /// Why the newest SAVE was skipped, if the settings are an older one's.
        newest_skipped: Option<LoadError>,
    },
    /// The defaults are in force, and why.
    Defaults(LoadError),
}

/// Depth of the unsolicited-line queue; a morph produces at most six events and a trip one.
pub const EVENT_QUEUE: usize = 16;

/// Longest reply to one command line, bytes: its `data:` lines and final line, each with a
/// `\n`. A bound for a shell that collects a reply before sending it; CONFIG, the longest, is
/// 1647 bytes with its 25 settings at their defaults and 1658 with every number at its
/// longest end (checked in `tests/protocol.rs`), HELP about 1000. The session's buffers are this
/// and twice this (static RAM, docs/firmware.md), and the serial task's longest pass under a
/// flood grows with them (docs/emulation.md): no more than CONFIG needs and some 70 bytes.
pub const MAX_REPLY_BYTES: usize = 1728;

/// The controller state.
pub struct Controller {
    cfg: Config,
    seq: Sequencer,
    sup: Supervisor,
    frame: Option<Frame>,
    /// The heaters seen electrically (current sense).
    elec: Electrical,
    powers: Powers,
    /// What the activity asked last tick under the parts' ceilings, before the allowance, W.
    wanted: Powers,
    /// Most power each heater may take, W: unlimited, or the shared supply's share
    /// ([`crate::budget`], set by [`crate::links::Links`] every tick).
    allowance: Powers,
    outputs: Outputs,
    supply_v: f32,
    events: Deque<Event, EVENT_QUEUE>,
    timing: Option<LoopTiming>,
    /// The faults alarmed since the last RESET (code and subject): each alarms once, however
    /// long it stays present. A ring: the newest replaces the oldest (a shifting list would
    /// put the 1.5 KiB `memmove` in the image for it).
    alarmed: [Option<(FaultCode, Subject)>; ALARMED_MAX],
    /// Where in `alarmed` the next fault goes: the oldest once the ring is full.
    alarmed_next: usize,
    /// The live settings (what the next morph runs with).
    settings: Settings,
    /// Whether the shell has settings storage (SAVE is then passed to it).
    storage: bool,
    /// A SAVE the shell is to carry out ([`Controller::take_save_request`]).
    save_request: Option<Blob>,
    /// What runs: idle, a morph, a TUNE or a HEAT pulse (one at a time).
    activity: Activity,
    /// The latched safety trip: the one place the fault state lives. While it is set the phase
    /// reads [`Phase::Fault`], the activity is idle and nothing heats.
    fault: Option<Fault>,
    /// The last morph started, for MEASURED.
    last: Option<LastMorph>,
    /// Counts the calibration's replacements (TUNE done, CONFIG RESET, CONFIG SET of a
    /// calibration value, settings loaded): a MEASURED report counts only for a morph of the
    /// current epoch.
    cal_epoch: u32,
    /// Each heater's HEAT time over the last window ([`crate::pulse::HEAT_WINDOW_S`]).
    heat_budget: crate::pulse::HeatBudget,
    /// The link's shape as the controller knows it, 1/m of curvature: as built until the first
    /// frame says the ambient (`None`), the last `done`'s estimate after a morph, NaN (unknown)
    /// while one heats and after one that did not finish. The TCA's rest reference and the
    /// rest-shape sensor's rests are tagged with it.
    shape_per_m: Option<f32>,
    /// `shape_per_m` is known, not a morph's estimate: the link as built (no morph since
    /// boot) or a MEASURED radius.
    shape_known: bool,
    /// The shape read from the TCA's resistance at rest ([`crate::shape`]).
    rest_shape: RestShape,
}

/// What MEASURED needs of the last morph.
#[derive(Clone, Copy, Debug)]
struct LastMorph {
    /// The strategy that ran (`auto` resolved).
    mode: Mode,
    /// TCA power the table gave it (scaled), W.
    power_w: f32,
    /// Ambient at MORPH, °C.
    ambient_c: f32,
    /// The TCA map in effect, `(a, b)`.
    map: (f32, f32),
    /// The radius `done` reported, mm (NaN until done).
    done_mm: f32,
    /// The calibration's epoch at MORPH ([`Controller`]'s `cal_epoch`).
    epoch: u32,
    /// A MEASURED report has been counted for it.
    counted: bool,
    /// Its rest-shape reading has been counted for it ([`crate::shape`]): a caliper's
    /// MEASURED may still follow (the reading does not stand in for one).
    read: bool,
}

/// MEASURED accepts radii this share beyond the table's range on either side: a link that
/// misses its table by more than the model ever did (1.8 mm, 5 %) still reports, twice that is
/// not a radius this link reached.
pub const MEASURED_RANGE_MARGIN: f32 = 0.1;
/// Least table power a power-strategy report scales, W: near the table's 0 W end a ratio of
/// powers says nothing.
pub const MEASURED_MIN_POWER_W: f32 = 0.1;

/// How many distinct faults are remembered as alarmed until RESET; beyond it the oldest is
/// forgotten (and would alarm again).
pub const ALARMED_MAX: usize = 8;

/// Firmware version reported by VERSION (defined in [`crate::vocab`]; here for the firmware).
pub use crate::vocab::VERSION;

impl Controller {
    /// A controller at rest (heaters off) with the given board settings.
    pub fn new(cfg: Config) -> Self {
        Controller {
            cfg,
            seq: Sequencer::new(),
            sup: Supervisor::new(),
            frame: None,
            elec: Electrical::default(),
            powers: Powers::default(),
            wanted: Powers::default(),
            allowance: Powers::UNLIMITED,
            outputs: Outputs::default(),
            supply_v: f32::NAN,
            events: Deque::new(),
            timing: None,
            alarmed: [None; ALARMED_MAX],
            alarmed_next: 0,
            settings: Settings::DEFAULT,
            storage: false,
            save_request: None,
            activity: Activity::Idle,
            fault: None,
            last: None,
            cal_epoch: 0,
            heat_budget: crate::pulse::HeatBudget::default(),
            shape_per_m: None,
            shape_known: false,
            rest_shape: RestShape::default(),
        }
    }

    /// Starts answering `STATS` from `timing`, which the firmware then feeds through
    /// [`Controller::record_timing`]. Without it (simulated builds) `STATS` is unsupported.
    pub fn enable_timing(&mut self, timing: LoopTiming) {
        self.timing = Some(timing);
    }

    /// Records one control tick's cycle-counter readings (see [`LoopTiming::record`]); does
    /// nothing unless [`Controller::enable_timing`] was called.
    pub fn record_timing(&mut self, start: u32, adc_done: u32, applied: u32) {
        if let Some(t) = &mut self.timing {
            t.record(start, adc_done, applied);
        }
    }

    /// Current phase (Fault while a fault is latched; Idle during a TUNE or a HEAT pulse).
    pub fn phase(&self) -> Phase {
        if self.fault.is_some() {
            Phase::Fault
        } else {
            self.seq.phase()
        }
    }

    /// The latched fault, if any.
    pub fn fault(&self) -> Option<Fault> {
        self.fault
    }

    /// What runs now, as the supervisor is told it.
    pub fn doing(&self) -> Doing {
        self.activity.doing(self.seq.phase())
    }

    /// Duties to apply now (also right after a command: ABORT zeroes them at once).
    pub fn outputs(&self) -> Outputs {
        self.outputs
    }

    /// The TCA's mean temperature from its own resistance, °C, on a board that senses current
    /// once it has a reference at rest ([`Electrical::tca_self_c`], with the calibration's
    /// coefficient).
    pub fn tca_self_c(&self) -> Option<f32> {
        self.elec.tca_self_c(self.settings.cal.tcr_per_k())
    }

    /// The heaters seen electrically (currents, resistances, the TCA's rest reference).
    pub fn electrical(&self) -> &Electrical {
        &self.elec
    }

    /// The supervisor (its expectation and how full its residual tests have been: the tools
    /// report how close a healthy run came to an alarm).
    pub fn supervisor(&self) -> &Supervisor {
        &self.sup
    }

    /// The last good temperatures the supervisor read, °C (what the controller acts on).
    pub fn measurements(&self) -> Measurements {
        self.sup.measurements()
    }

    /// This tick's estimates of the heated parts (PLA rod, TCA), °C ([`crate::part_limit`]).
    pub fn parts_c(&self) -> [f32; 2] {
        self.sup.parts_c()
    }

    /// Powers commanded in the last tick, W.
    pub fn powers(&self) -> Powers {
        self.powers
    }

    /// What the activity asked in the last tick before the allowance cut it, W: what the
    /// supply's scheduler shares out by.
    pub fn wanted(&self) -> Powers {
        self.wanted
    }

    /// Sets the most power each heater may take from the next tick on, W (the supply budget's
    /// share, [`crate::budget::allocate`]); every activity's powers are capped to it before
    /// they become duties, and the model strategies' observers are fed the capped powers.
    pub fn set_allowance(&mut self, allow_w: Powers) {
        let sane = |w: f32| if w.is_nan() { 0.0 } else { w.max(0.0) };
        self.allowance = Powers {
            pla_w: sane(allow_w.pla_w),
            tca_w: sane(allow_w.tca_w),
        };
    }

    /// The resistance each heater is reckoned with, Ω (measured where current is sensed):
    /// what the supply's scheduler turns allowances into duties and currents with.
    pub fn heater_ohm(&self) -> [f32; 2] {
        [Heater::Pla, Heater::Tca].map(|h| self.heater(h).resistance_ohm)
    }

    /// The supply voltage read in the last tick, V (NaN before the first).
    pub fn supply_v(&self) -> f32 {
        self.supply_v
    }

    /// What holds what runs now, W: in soften and bend the rod at its soft target, from soften
    /// to lock the TCA at its table power (each [`crate::budget::RESERVE_MARGIN`] times what
    /// the calibration says holds it), a TUNE or HEAT step at its own power. The supply's
    /// scheduler never cuts a link below it.
    pub fn reserve_w(&self) -> Powers {
        match self.doing() {
            Doing::Morph(phase) => {
                let tca_w = self.last.map_or(0.0, |l| l.power_w);
                self.morph_reserve_w(phase, tca_w)
            }
            Doing::Tune => crate::tune::TUNE_STEP_POWERS,
            Doing::Heat(_) => self.wanted,
            Doing::Idle => Powers::default(),
        }
    }

    /// What a morph to `radius_mm` reserves in soften, W (its admission under a shared
    /// budget); `None` for a radius outside the table.
    pub fn soften_reserve_w(&self, radius_mm: f32) -> Option<Powers> {
        let table_w = table::power_for_radius_w(radius_mm).ok()?;
        let tca_w = (table_w * self.settings.cal.power_scale()).min(HeaterConfig::TCA.max_power_w);
        Some(self.morph_reserve_w(Phase::Soften, tca_w))
    }

    /// [`Controller::reserve_w`] of a morph in `phase` whose table gave the TCA `tca_w`.
    fn morph_reserve_w(&self, phase: Phase, tca_w: f32) -> Powers {
        use crate::budget::RESERVE_MARGIN;
        let amb_c = self.sup.measurements().t_amb_c;
        let amb_c = if amb_c.is_finite() { amb_c } else { 20.0 };
        let rise_k = self.settings.morph.thresholds().pla_soft_target_c - amb_c;
        let r_pp = self.settings.cal.model_resistances().r_pp;
        let hold_w = (rise_k.max(0.0) / r_pp).min(HeaterConfig::PLA.max_power_w);
        // A resting morph keeps its soften's reserve: it was admitted with it.
        let pla_on = matches!(phase, Phase::Rest | Phase::Soften | Phase::Bend);
        let tca_on = matches!(
            phase,
            Phase::Rest | Phase::Soften | Phase::Bend | Phase::Lock
        );
        Powers {
            pla_w: if pla_on {
                (hold_w * RESERVE_MARGIN).min(HeaterConfig::PLA.max_power_w)
            } else {
                0.0
            },
            tca_w: if tca_on {
                (tca_w * RESERVE_MARGIN).min(HeaterConfig::TCA.max_power_w)
            } else {
                0.0
            },
        }
    }

    /// True while no morph runs and no fault is latched.
    pub fn idle(&self) -> bool {
        self.phase() == Phase::Idle
    }

    /// True while a morph, a `TUNE` or a `HEAT` pulse is under way (not idle, not faulted).
    pub fn busy(&self) -> bool {
        self.activity.busy()
    }

    /// Queues `e`; a full queue makes room by dropping its oldest event that is not an alarm
    /// (an alarm is the one line a stalled host must still see), or, holding only alarms,
    /// drops the new event unless it is an alarm too.
    fn push(&mut self, e: Event) {
        if self.events.is_full() {
            let n = self.events.len();
            let mut kept = false;
            for _ in 0..n {
                let Some(old) = self.events.pop_front() else {
                    break;
                };
                if !kept && !matches!(old, Event::Alarm(_)) {
                    kept = true; // dropped: the oldest non-alarm
                    continue;
                }
                let _ = self.events.push_back(old);
            }
            if !kept {
                if !matches!(e, Event::Alarm(_)) {
                    return;
                }
                self.events.pop_front();
            }
        }
        let _ = self.events.push_back(e);
    }

    /// Next unsolicited event, oldest first.
    pub fn pop_event(&mut self) -> Option<Event> {
        self.events.pop_front()
    }

    fn frame_of(&self, inputs: &Inputs) -> Frame {
        let t = &self.cfg.thermistor;
        Frame {
            readings: inputs.thermistor_counts.map(|c| t.classify(c)),
            supply_v: self.cfg.supply.volts(inputs.supply_counts),
            sample_ms: inputs.sample_ms,
        }
    }

    /// Ends what runs with both heaters off from this tick (ABORT, a trip): the one stop path.
    /// Returns what ran.
    fn stop(&mut self) -> Activity {
        let ran = self.activity.stop();
        self.seq.abort();
        self.powers = Powers::default();
        self.wanted = Powers::default();
        // Heaters off; the cut-off as it was (a trip opens it).
        self.outputs = Outputs {
            supply_on: self.outputs.supply_on && self.fault.is_none(),
            ..Outputs::default()
        };
        ran
    }

    /// True while this link's cut-off has failed: current flows with it open
    /// ([`Electrical::cutoff_failed`]).
    pub fn cutoff_failed(&self) -> bool {
        self.elec.cutoff_failed()
    }

    /// The supply inside each heater's pulse as the frame `inputs`' currents `c` give it, and
    /// the supply the same frame reads, V ([`Electrical::pulse_v`]).
    pub fn pulse_v(&self, c: &Currents, inputs: &Inputs) -> ([f32; 2], f32) {
        let supply_v = self.cfg.supply.volts(inputs.supply_counts);
        (self.elec.pulse_v(c, self.drive(), supply_v), supply_v)
    }

    /// The next step's on-samples of the heaters `sag` marks were taken in a sagging supply
    /// ([`Electrical::note_sag`]).
    pub fn note_sag(&mut self, sag: [bool; 2]) {
        self.elec.note_sag(sag);
    }

    /// What drove the heaters since the last tick: the currents of this tick's frame were
    /// sampled under it.
    fn drive(&self) -> Drive {
        Drive {
            duty: [self.outputs.pla_duty, self.outputs.tca_duty],
            supply_on: self.outputs.supply_on,
        }
    }

    /// Latches `fault`, found outside this link (the board's supply, [`crate::links`]), unless
    /// one is latched already: what runs stops, heaters off, and the alarm says why.
    pub fn trip_shared(&mut self, fault: Fault) {
        if self.fault().is_none() {
            self.trip(fault);
        }
    }

    /// Latches `fault`: what runs stops, its alarm is raised, then (for a TUNE) the tune's end.
    fn trip(&mut self, fault: Fault) {
        self.fault = Some(fault);
        let ran = self.stop();
        // The alarm first: `tune failed safety trip (see the alarm)` points back at it.
        self.alarm_once(fault);
        if matches!(ran, Activity::Tune(_)) {
            self.push(Event::Tune(TuneEvent::Failed(TuneFailure::Tripped)));
        }
    }

    /// Raises `fault`'s alarm unless the same code and subject has alarmed since RESET.
    fn alarm_once(&mut self, fault: Fault) {
        let key = (fault.code, fault.subject);
        if self.alarmed.contains(&Some(key)) {
            return;
        }
        self.alarmed[self.alarmed_next] = Some(key);
        self.alarmed_next = (self.alarmed_next + 1) % ALARMED_MAX;
        self.push(Event::Alarm(fault));
    }

    /// Commands `p` (W) at the measured supply `supply_v` (V): each heater's power scaled down
    /// to [`MODEL_KEEP_ALIVE_W`] as its part's estimate nears its ceiling
    /// ([`crate::part_limit::under_ceiling_w`]), whatever the activity asks, then turned into
    /// duties.
    fn apply(&mut self, p: Powers, supply_v: f32) {
        let parts_c = self.sup.parts_c();
        let capped = |h: Heater, w: f32| {
            let ceiling_c = crate::supervisor::limits(h.sensor()).max_c - CEILING_MARGIN_K;
            under_ceiling_w(w, parts_c[h.index()], ceiling_c, MODEL_KEEP_ALIVE_W)
        };
        let p = Powers {
            pla_w: capped(Heater::Pla, p.pla_w),
            tca_w: capped(Heater::Tca, p.tca_w),
        };
        self.wanted = p;
        let p = p.min(self.allowance);
        self.powers = p;
        // Where current is sensed every period keeps its off-window.
        let duty = |h: Heater, w: f32| {
            let most = if self.elec.ohm(h).is_some() {
                MAX_SENSED_DUTY
            } else {
                1.0
            };
            self.heater(h).duty(w, supply_v).min(most)
        };
        self.outputs = Outputs {
            pla_duty: duty(Heater::Pla, p.pla_w),
            tca_duty: duty(Heater::Tca, p.tca_w),
            supply_on: true,
        };
    }

    /// `h`'s heater as the watts are reckoned with: its configuration, at its measured
    /// resistance where current is sensed.
    fn heater(&self, h: Heater) -> HeaterConfig {
        let cfg = match h {
            Heater::Pla => self.cfg.pla_heater,
            Heater::Tca => self.cfg.tca_heater,
        };
        HeaterConfig {
            resistance_ohm: self.elec.ohm(h).unwrap_or(cfg.resistance_ohm),
            ..cfg
        }
    }

    /// What the last tick's duties deliver at the supply read now, W: the expectation's
    /// input (a heater at full duty gives less than was asked).
    fn delivered(&self) -> Powers {
        let w = |h: Heater, duty: f32| self.heater(h).power_w(duty, self.supply_v);
        Powers {
            pla_w: w(Heater::Pla, self.outputs.pla_duty),
            tca_w: w(Heater::Tca, self.outputs.tca_duty),
        }
    }

    /// The calibration in force was replaced (TUNE done, CONFIG SET or RESET, settings loaded
    /// or restored): a MEASURED report for an earlier morph no longer describes the link, and
    /// the supervisor takes the beads' shares the parts' limits are judged with from it.
    fn calibration_replaced(&mut self) {
        self.cal_epoch = self.cal_epoch.wrapping_add(1);
        self.sup.set_calibration(&self.settings.cal);
    }

    /// One control tick at `now_ms` with this tick's inputs; returns the duties to apply.
    /// The supervisor runs every tick, a latched fault included: STATUS stays live and a new
    /// fault alarms too (the first one found stays latched).
    /// Not inlined: the firmware calls it from one place, where inlining it only grows the
    /// control task's state machine (flash the L475 image does not have).
    #[inline(never)]
    pub fn step(&mut self, now_ms: u64, inputs: &Inputs) -> Outputs {
        let frame = self.frame_of(inputs);
        self.frame = Some(frame);
        self.supply_v = frame.supply_v;
        let mut faults = Faults::new();
        let currents = inputs.current.map(|c| Currents::of(&c, &self.cfg.shunt));
        self.elec
            .check(currents, self.drive(), frame.supply_v, &mut faults);
        if self.fault().is_some() {
            self.powers = Powers::default();
            self.outputs = Outputs::default();
        }
        let doing = self.doing();
        let tca_self_c = self.tca_self_c();
        self.sup.set_sensing(inputs.current.is_some(), tca_self_c);
        let m = self
            .sup
            .check_all(now_ms, &frame, self.delivered(), doing, &mut faults);
        // At rest: idle, a morph's rest, a tune's settle step (the reference a tune fits from).
        let tca_driven = !(matches!(doing, Doing::Idle | Doing::Morph(Phase::Rest))
            || self.tune_step() == Some(crate::tune::TuneStep::Settle));
        self.note_rest(tca_driven, &m);
        self.note_shape(tca_driven, &m);
        // Every tick, so a MORPH between ticks starts from this one's.
        self.seq.set_tca_self(
            self.tca_self_c().unwrap_or(f32::NAN),
            self.elec.rest_shape_per_m(),
        );
        for f in faults {
            if self.fault().is_none() {
                self.trip(f);
            } else {
                self.alarm_once(f);
            }
        }
        if self.fault().is_some() {
            return self.outputs;
        }
        // The checks passed with nothing latched: the heaters may have their supply.
        self.outputs.supply_on = true;
        match self.tick_activity(now_ms, &m, frame.supply_v) {
            Ok(p) => self.apply(p, frame.supply_v),
            Err(f) => self.trip(f),
        }
        self.outputs
    }

    /// Feeds the TCA's rest reference ([`Electrical::note_rest`]) with the link's shape.
    fn note_rest(&mut self, tca_driven: bool, m: &Measurements) {
        // A link that never morphed is as built: bent by its cold TCA alone (the model's
        // spring-back at rest is under 2 % of that curvature).
        let shape_per_m = match self.shape_per_m {
            Some(k) => k,
            None if m.t_amb_c.is_finite() => {
                self.shape_known = true;
                *self
                    .shape_per_m
                    .insert(crate::lumped::curvature_per_m(m.t_amb_c))
            }
            None => return,
        };
        self.elec
            .note_rest(tca_driven, m.t_tca_c, m.t_amb_c, shape_per_m);
    }

    /// Feeds the rest-shape sensor ([`crate::shape`]) a tick at rest after a morph's `done`
    /// (or as built), queues what a finished rest gave, and, where the reading agrees with the
    /// estimate, folds it into the calibration as a MEASURED would, weighted by its sigma.
    fn note_shape(&mut self, tca_driven: bool, m: &Measurements) {
        let Some(k) = self.shape_per_m else {
            return;
        };
        if tca_driven || self.fault().is_some() || !matches!(self.activity, Activity::Idle) {
            self.rest_shape.interrupted();
            return;
        }
        let sigma = match (self.shape_known, self.last.is_some()) {
            (false, _) => shape::estimate_sigma_per_m(k),
            (true, false) => shape::as_built_sigma_per_m(k),
            (true, true) => shape::known_sigma_per_m(k),
        };
        // With a gauge kept from before a reset, the link at boot is not known to be as built:
        // it may have been left bent, and only a MEASURED anchors it.
        let gauge = self.settings.cal.gauge();
        let known = self.shape_known && (self.last.is_some() || gauge.is_none());
        let tcr_per_k = self.settings.cal.tcr_per_k();
        let dt_s = TICK_MS as f32 * 1e-3;
        let r_ohm = match self.elec.on_a() {
            Some(_) => Ok(self.elec.raw_ohm(Heater::Tca)),
            None => Err(()),
        };
        let (t_tca, t_amb) = (m.t_tca_c, m.t_amb_c);
        let outcome = self.rest_shape.note(
            dt_s,
            r_ohm,
            (t_tca, t_amb),
            (k, sigma, known),
            tcr_per_k,
            gauge,
        );
        // A gauge is learnt only by a finished rest, which gives an outcome.
        let Some(outcome) = outcome else {
            return;
        };
        self.strain_from_gauge();
        let mut learnt = false;
        if let Outcome::Shape(r) = outcome {
            if r.learnable && !self.shape_known {
                let mut l = OutLine::new();
                self.fold_measured(r.radius_mm, Some(r.weight()), &mut l);
                learnt = !l.starts_with(protocol::ERROR_TAG);
            }
        }
        // As built (no morph since boot) the rest is the anchor; nobody asked for its shape.
        if self.last.is_some() {
            let (radius_mm, sigma_mm, none) = match outcome {
                Outcome::Shape(r) => (r.radius_mm, r.sigma_mm, None),
                Outcome::None(why) => (f32::NAN, f32::NAN, Some(why)),
            };
            self.push(Event::Shape(ShapeEvent {
                radius_mm,
                sigma_mm,
                none,
                learnt,
            }));
        }
    }

    /// A gauge just learnt goes into the calibration, which keeps it (SAVE stores it): it is
    /// the own thermometer's strain factor too (one quantity, the coil's resistance per 1/m of
    /// bend); one past the factor's bounds is not kept.
    fn strain_from_gauge(&mut self) {
        if let Some((g, var)) = self.rest_shape.take_new_gauge() {
            let _ = self.settings.cal.set_gauge(g, var);
        }
    }

    /// The rest-shape sensor ([`crate::shape`]): its anchor and gauge.
    pub fn rest_shape(&self) -> &RestShape {
        &self.rest_shape
    }

    /// Runs this tick of the activity in the slot: the powers it asks for, or the fault it
    /// ended in (a phase timeout). An activity that ends goes back to idle here.
    fn tick_activity(
        &mut self,
        now_ms: u64,
        m: &Measurements,
        supply_v: f32,
    ) -> Result<Powers, Fault> {
        let mut events: heapless::Vec<Event, 4> = heapless::Vec::new();
        let mut ended = false;
        let result = match &mut self.activity {
            Activity::Idle => Ok(Powers::default()),
            Activity::Morph => {
                self.seq.set_supply_v(supply_v);
                self.seq.set_allowance(self.allowance);
                let r = self.seq.step(now_ms, m, &mut |e| {
                    let _ = events.push(Event::Seq(e));
                });
                ended = !self.seq.busy();
                // A lock ends only on a PLA cool enough to hold the shape, so a lock timeout,
                // judged or by the clock, says how warm the rod stayed.
                r.map_err(|t| {
                    let reading = if t.0 == Phase::Lock {
                        m.t_pla_c
                    } else {
                        f32::NAN
                    };
                    t.fault(reading)
                })
            }
            Activity::Tune(t) => {
                let ratio = self.elec.tca_ratio();
                let r = t.tick(now_ms, m, ratio, &mut |e| {
                    let _ = events.push(Event::Tune(e));
                });
                Ok(match r {
                    TuneTick::Run(p) => p,
                    TuneTick::Done(cal) => {
                        self.settings.cal = cal;
                        self.calibration_replaced();
                        ended = true;
                        Powers::default()
                    }
                    TuneTick::Failed(_) => {
                        ended = true;
                        Powers::default()
                    }
                })
            }
            Activity::Heat(pulse) => Ok(pulse.powers(now_ms).unwrap_or_else(|| {
                ended = true;
                Powers::default()
            })),
        };
        if ended {
            self.activity.stop();
        }
        for e in events {
            self.push_seq(e);
        }
        result
    }

    /// Queues an activity's event, noting what a morph's say of the link: the radius `done`
    /// reports (for MEASURED) and the shape (unknown from soften until `done`).
    fn push_seq(&mut self, e: Event) {
        match e {
            Event::Seq(SeqEvent::Done { radius_mm, .. }) => {
                if let Some(last) = self.last.as_mut() {
                    last.done_mm = radius_mm;
                }
                self.shape_per_m = Some(1e3 / radius_mm);
                self.shape_known = false;
                self.rest_shape.moved();
            }
            Event::Seq(SeqEvent::Phase {
                phase: Phase::Soften,
                ..
            }) => {
                self.shape_per_m = Some(f32::NAN);
                self.rest_shape.moved();
            }
            _ => {}
        }
        self.push(e);
    }

    /// Handles one received line: writes zero or more `data:` lines and exactly one final reply
    /// through `out`, except for `SIM` commands, which are returned for the caller (a simulated
    /// build) to carry out and answer. Empty lines get no reply.
    pub fn handle_line(
        &mut self,
        now_ms: u64,
        line: &str,
        out: &mut dyn FnMut(&str),
    ) -> Option<SimCommand> {
        match protocol::parse_line(line) {
            Ok(None) => None,
            Ok(Some(Command::Sim(s))) => Some(s),
            Ok(Some(cmd)) => {
                self.handle(now_ms, cmd, out);
                None
            }
            Err(e) => {
                out(&protocol::format_error(&e));
                None
            }
        }
    }

    /// Carries out one command (not `SIM`), writing its reply lines through `out`.
    pub fn handle(&mut self, now_ms: u64, cmd: Command, out: &mut dyn FnMut(&str)) {
        let mut l = OutLine::new();
        match cmd {
            Command::Morph { radius_mm, mode } => self.morph(now_ms, radius_mm, mode, out),
            Command::Status => {
                self.write_status(&mut l);
                out(&l);
            }
            Command::Abort => {
                if matches!(self.stop(), Activity::Tune(_)) {
                    self.push(Event::Tune(TuneEvent::Failed(TuneFailure::Aborted)));
                }
                out(protocol::OK);
            }
            Command::Reset => self.reset(now_ms, out),
            Command::Range => {
                let (min, max) = table::range_mm();
                reply::range(&mut l, min, max);
                out(&l);
            }
            Command::Table => {
                for row in crate::link::TABLE.iter() {
                    l.clear();
                    reply::table_row(&mut l, row.power_w, row.radius_mm);
                    out(&l);
                }
                out(protocol::OK);
            }
            Command::Version => {
                reply::version(&mut l, VERSION);
                out(&l);
            }
            Command::Help => {
                let sim: &[&str] = if cfg!(feature = "sim") {
                    &reply::HELP_SIM
                } else {
                    &[]
                };
                let lines = reply::HELP.iter().chain(sim).chain(&reply::HELP_TAIL);
                for h in lines.chain(tune_reply::HELP.iter()) {
                    l.clear();
                    reply::help_line(&mut l, h);
                    out(&l);
                }
                out(protocol::OK);
            }
            Command::Stats => match &self.timing {
                Some(t) => {
                    t.write_stats(&mut l);
                    out(&l);
                }
                None => out(&protocol::format_error(&reply::ERR_STATS_UNSUPPORTED)),
            },
            Command::Sim(_) => out(&protocol::format_error(&reply::ERR_SIM_UNSUPPORTED)),
            Command::Config(c) => self.config(c, out),
            Command::Save => self.save(out),
            Command::Heat {
                heater,
                power_w,
                duration_s,
            } => self.heat(now_ms, heater, power_w, duration_s, out),
            Command::Tune => self.start_tune(now_ms, out),
            Command::Measured { radius_mm } => self.measured(radius_mm, out),
        }
    }

    /// `HEAT`: refused during a morph, with a fault latched or before the first reading; a
    /// pulse replaces a running one.
    fn heat(
        &mut self,
        now_ms: u64,
        heater: Heater,
        power_w: f32,
        duration_s: f32,
        out: &mut dyn FnMut(&str),
    ) {
        let mut l = OutLine::new();
        if self.refused(Start::Heat, &mut l) {
            return out(&l);
        }
        match Pulse::new(now_ms, heater, power_w, duration_s) {
            Ok(p) => match self.heat_budget.take(heater, duration_s, now_ms) {
                Ok(()) => {
                    self.activity = Activity::Heat(p);
                    out(protocol::OK);
                }
                Err(left_s) => {
                    reply::heat_budget(&mut l, heater, left_s);
                    out(&l);
                }
            },
            Err(_) => out(&protocol::format_error(&reply::ERR_HEAT_RANGE)),
        }
    }

    /// Whether `start` must be refused now (a fault latched, an activity in its way, or for
    /// heating no reading yet): if so, writes the refusal into `l`. Every command that starts
    /// an activity or changes what one runs with goes through it.
    fn refused(&self, start: Start, l: &mut OutLine) -> bool {
        let heats = matches!(start, Start::Morph | Start::Heat | Start::Tune);
        if let (Some(f), true) = (self.fault(), heats) {
            reply::fault_latched(l, f.code);
        } else if let Some(busy) = self.activity.refusal(start, self.seq.phase()) {
            match (start, busy) {
                (Start::Change, _) => reply::config_busy(l, self.phase()),
                (_, Busy::Morphing(phase)) => reply::busy_morphing(l, phase),
                (_, Busy::Tuning) => tune_reply::busy_tuning(l),
                (_, Busy::Heating) => *l = protocol::format_error(&reply::ERR_BUSY_HEATING),
            }
        } else if heats && (self.frame.is_none() || self.sup.measurements().t_pla_c.is_nan()) {
            reply::busy_no_reading(l);
        } else {
            return false;
        }
        true
    }

    /// Writes into `l` why a MORPH would be refused now (a fault latched, an activity
    /// running, no reading yet); returns whether it would be.
    pub fn morph_refusal(&self, l: &mut OutLine) -> bool {
        self.refused(Start::Morph, l)
    }

    /// The running `HEAT` pulse's heater, if one runs.
    pub fn heating(&self) -> Option<Heater> {
        self.activity.pulse().map(|p| p.heater)
    }

    fn morph(&mut self, now_ms: u64, radius_mm: f32, mode: Mode, out: &mut dyn FnMut(&str)) {
        let mut l = OutLine::new();
        if self.refused(Start::Morph, &mut l) {
            return out(&l);
        }
        let mode = self.settings.morph.resolve(mode);
        self.seq.set_limits(
            self.settings.morph.thresholds(),
            self.settings.morph.timeouts(),
        );
        match table::power_for_radius_w(radius_mm) {
            Err(r) => {
                reply::radius_out_of_range(&mut l, r.min_mm, r.max_mm);
                out(&l);
            }
            Ok(table_w) => {
                out(protocol::OK);
                let power_w =
                    (table_w * self.settings.cal.power_scale()).min(HeaterConfig::TCA.max_power_w);
                let mut first: heapless::Vec<SeqEvent, 2> = heapless::Vec::new();
                let m = self.sup.measurements();
                self.last = Some(LastMorph {
                    mode: crate::strategy::AnyStrategy::resolve(mode),
                    power_w,
                    ambient_c: m.t_amb_c,
                    map: self.settings.cal.map(),
                    done_mm: f32::NAN,
                    counted: false,
                    read: false,
                    epoch: self.cal_epoch,
                });
                let cal = self.settings.cal;
                self.seq
                    .start_from(now_ms, radius_mm, power_w, mode, &m, &cal, &mut |e| {
                        let _ = first.push(e);
                    });
                self.activity = Activity::Morph;
                for e in first {
                    self.push_seq(Event::Seq(e));
                }
            }
        }
    }

    fn reset(&mut self, now_ms: u64, out: &mut dyn FnMut(&str)) {
        let mut l = OutLine::new();
        let Some(latched) = self.fault() else {
            reply::reset_nothing(&mut l);
            return out(&l);
        };
        let check = match &self.frame {
            Some(frame) => self.sup.condition_clear(now_ms, frame),
            None => Err(latched),
        };
        match check {
            Ok(()) => {
                self.fault = None;
                self.sup.rearm();
                self.alarmed = [None; ALARMED_MAX];
                self.alarmed_next = 0;
                reply::reset_cleared(&mut l, latched.code);
                out(&l);
            }
            Err(still) => {
                reply::fault_active(&mut l, &still);
                out(&l);
            }
        }
    }

    fn write_status(&self, l: &mut OutLine) {
        let m = self.sup.live();
        let targets = self.seq.targets_c();
        let status = reply::StatusReport {
            phase: self.phase(),
            target_mm: self.seq.target_mm(),
            t_pla_c: m.t_pla_c,
            t_tca_c: m.t_tca_c,
            t_amb_c: m.t_amb_c,
            p_pla_w: self.powers.pla_w,
            p_tca_w: self.powers.tca_w,
            supply_v: self.supply_v,
            fault: self.fault().map(|f| f.code),
            pla_target_c: targets.pla_c,
            tca_target_c: targets.tca_c,
            mode: self.seq.mode_ran(),
            current_a: self.elec.on_a().unwrap_or([f32::NAN; 2]),
            resistance_ohm: [Heater::Pla, Heater::Tca]
                .map(|h| self.elec.ohm(h).unwrap_or(f32::NAN)),
            t_tca_self_c: self.tca_self_c().unwrap_or(f32::NAN),
            supply_on: self.outputs.supply_on,
            shape_mm: self
                .rest_shape
                .reading()
                .map_or([f32::NAN; 2], |r| [r.radius_mm, r.sigma_mm]),
        };
        reply::status(l, &status);
    }

    /// Formats the next queued event as a protocol line (`event: ...` or `alarm: ...`).
    pub fn pop_event_line(&mut self) -> Option<OutLine> {
        let e = self.pop_event()?;
        let mut l = OutLine::new();
        match e {
            Event::Seq(SeqEvent::Phase {
                phase,
                t_s,
                power_w,
            }) => reply::phase_event(&mut l, phase, t_s, power_w),
            Event::Seq(SeqEvent::Done {
                t_s,
                radius_mm,
                target_mm,
            }) => {
                let missed_mm = radius_mm - target_mm;
                let missed = missed_mm.abs() > crate::sequencer::DONE_MISS_SHARE * target_mm;
                reply::done_event(&mut l, t_s, radius_mm, missed.then_some(missed_mm))
            }
            Event::Alarm(f) => reply::alarm(&mut l, &f),
            Event::Config(ConfigEvent::Loaded { newest_skipped }) => reply::config_loaded_event(
                &mut l,
                self.settings.count(),
                newest_skipped.map(|why| why.as_str()),
            ),
            Event::Config(ConfigEvent::Defaults(why)) => {
                let setting = match why {
                    LoadError::OutOfRange(name) => Some(name),
                    _ => None,
                };
                reply::config_defaults_event(&mut l, why.as_str(), setting)
            }
            Event::Tune(e) => tune_reply::tune_event(&mut l, &e),
            Event::Shape(e) => tune_reply::shape_event(&mut l, &e),
        }
        Some(l)
    }

    // ---- Settings: the live values, CONFIG, SAVE and the stored settings at boot. ----

    /// The live settings.
    pub fn settings(&self) -> &Settings {
        &self.settings
    }

    /// Tells the controller the shell has settings storage: SAVE then queues a request the
    /// shell takes with [`Controller::take_save_request`] and answers with
    /// [`Controller::finish_save`]. Without it SAVE is `error: unsupported`.
    pub fn enable_storage(&mut self) {
        self.storage = true;
    }

    /// Puts the settings loaded at boot in force (or the defaults, if `loaded` says why not)
    /// and queues `event: config loaded` (with the reason, if they are an older SAVE's because
    /// the newest is damaged) or `event: config defaults reason=<why>`. Never heats: it only
    /// changes what the next morph runs with.
    pub fn load_settings(&mut self, loaded: Result<Loaded, LoadError>) {
        let e = match loaded {
            Ok(found) => {
                self.settings = found.settings;
                ConfigEvent::Loaded {
                    newest_skipped: found.newest_skipped,
                }
            }
            Err(why) => {
                self.settings = Settings::DEFAULT;
                ConfigEvent::Defaults(why)
            }
        };
        self.calibration_replaced();
        self.push(Event::Config(e));
    }

    /// The blob a SAVE asks the shell to write, once.
    pub fn take_save_request(&mut self) -> Option<Blob> {
        self.save_request.take()
    }

    /// The SAVE's final reply, once the shell has written (or failed to write) the blob.
    pub fn finish_save(
        &mut self,
        result: Result<SaveReport, StoreError>,
        out: &mut impl FnMut(&str),
    ) {
        let mut l = OutLine::new();
        match result {
            Ok(r) => reply::saved(&mut l, r.bytes, r.erases),
            Err(e) => reply::save_failed(&mut l, e.as_str()),
        }
        out(&l);
    }

    fn config(&mut self, c: protocol::ConfigCommand, out: &mut dyn FnMut(&str)) {
        use protocol::ConfigCommand;
        let mut l = OutLine::new();
        if !matches!(c, ConfigCommand::List) && self.refused(Start::Change, &mut l) {
            return out(&l);
        }
        match c {
            ConfigCommand::List => {
                self.settings.for_each(|spec, v| {
                    l.clear();
                    reply::config_row(&mut l, &row(spec, v));
                    out(&l);
                });
                l.clear();
                reply::config_end(&mut l, self.settings.count());
            }
            ConfigCommand::Reset => {
                self.settings = Settings::DEFAULT;
                self.calibration_replaced();
                reply::config_reset(&mut l);
            }
            ConfigCommand::Set { name, value } => {
                let view = self.settings.cal.self_sensed();
                match self.settings.set_text(name.as_str(), value.as_str()) {
                    Ok((spec, v)) => {
                        if CALIBRATION_SPECS.iter().any(|c| c.name == spec.name) {
                            self.calibration_replaced();
                        }
                        if self.settings.cal.self_sensed() != view {
                            // The map's reports were of the other view.
                            self.settings.cal.clear_map();
                        }
                        reply::config_set(&mut l, &row(&spec, v))
                    }
                    Err(SetError::UnknownName) => reply::config_unknown(&mut l, name.as_str()),
                    Err(SetError::Malformed(spec)) => {
                        reply::config_malformed(&mut l, &row(&spec, spec.default))
                    }
                    Err(SetError::OutOfRange(spec, v)) => {
                        reply::config_out_of_range(&mut l, &row(&spec, spec.default), v)
                    }
                    Err(SetError::Inconsistent(spec, v, why)) => reply::config_inconsistent(
                        &mut l,
                        &row(&spec, spec.default),
                        v,
                        &why,
                        if spec.name == "convection_w_m2k" {
                            v
                        } else {
                            self.settings.cal.convection_w_m2k
                        },
                    ),
                }
            }
        }
        out(&l);
    }

    /// SAVE: refused while a morph runs (a flash erase may stall the CPU for longer than a
    /// control tick, so it happens only with the heaters off); otherwise the shell writes.
    fn save(&mut self, out: &mut dyn FnMut(&str)) {
        let mut l = OutLine::new();
        if !self.storage {
            return out(&protocol::format_error(&reply::ERR_SAVE_UNSUPPORTED));
        }
        if self.refused(Start::Change, &mut l) {
            return out(&l);
        }
        // What a tune or a morph learnt while a fault built up is not to be kept.
        if let Some(f) = self.fault() {
            reply::fault_latched(&mut l, f.code);
            return out(&l);
        }
        self.save_request = Some(codec::encode(&self.settings));
    }
}

/// A setting and its value as `CONFIG` shows them.
fn row(spec: &Spec, value: f32) -> reply::SettingRow<'static> {
    reply::SettingRow {
        name: spec.name,
        unit: spec.unit,
        value,
        default: spec.default,
        min: spec.min,
        max: spec.max,
        decimals: spec.decimals,
        choices: spec.choices,
    }
}

/// TUNE, MEASURED and the calibration (see [`crate::tune`], [`crate::calibration`]).
impl Controller {
    /// This link's calibration.
    pub fn calibration(&self) -> Calibration {
        self.settings.cal
    }

    /// Replaces the calibration (a settings shell restoring a stored one): refused, changing
    /// nothing, unless every field is within its range.
    pub fn set_calibration(&mut self, cal: Calibration) -> Result<(), CalibrationError> {
        for i in 0..crate::calibration::FIELD_COUNT {
            let v = cal.get(i).ok_or(CalibrationError::NoSuchField)?;
            let f = crate::calibration::FIELDS[i];
            if !(v >= f.min && v <= f.max) {
                return Err(CalibrationError::OutOfRange(f));
            }
        }
        self.settings.cal = cal;
        self.calibration_replaced();
        Ok(())
    }

    /// True while a TUNE runs.
    pub fn tuning(&self) -> bool {
        self.activity.tune().is_some()
    }

    /// The step of the TUNE under way, if one runs.
    pub fn tune_step(&self) -> Option<crate::tune::TuneStep> {
        self.activity.tune().map(|t| t.step_now())
    }

    fn start_tune(&mut self, now_ms: u64, out: &mut dyn FnMut(&str)) {
        let mut l = OutLine::new();
        if self.refused(Start::Tune, &mut l) {
            return out(&l);
        }
        // TUNE judges every sensor's rise over ambient: all three must read.
        let m = self.sup.measurements();
        if !(m.t_tca_c.is_finite() && m.t_amb_c.is_finite()) {
            reply::busy_no_reading(&mut l);
            return out(&l);
        }
        for h in Heater::ALL {
            let rise_k = m.of(h.sensor()) - m.t_amb_c;
            if rise_k > crate::tune::TUNE_START_MAX_RISE_K {
                tune_reply::tune_link_warm(&mut l, h, rise_k);
                return out(&l);
            }
        }
        tune_reply::tune_started(&mut l, crate::tune::TUNE_TOTAL_S);
        out(&l);
        let mut first: heapless::Vec<TuneEvent, 2> = heapless::Vec::new();
        self.activity = Activity::Tune(Tune::new(now_ms, self.settings.cal, &mut |e| {
            let _ = first.push(e);
        }));
        for e in first {
            self.push(Event::Tune(e));
        }
    }

    fn measured(&mut self, radius_mm: f32, out: &mut dyn FnMut(&str)) {
        let mut l = OutLine::new();
        // The busy rule of CONFIG SET (the calibration is a setting), in MEASURED's words.
        if !self.refused(Start::Measured, &mut l) {
            self.fold_measured(radius_mm, None, &mut l);
        }
        out(&l);
    }

    /// Folds the radius `radius_mm` the last morph turned out to have into the calibration,
    /// the reply in `l`: measured by the user (`read` None) or read at rest with that weight
    /// against a caliper's ([`crate::shape::Reading::weight`]). A caliper's radius is then the
    /// link's known shape.
    fn fold_measured(&mut self, radius_mm: f32, read: Option<f32>, l: &mut OutLine) {
        use crate::strategy::model::target;
        let caliper = read.is_none();
        let (min_mm, max_mm) = table::range_mm();
        let (lo, hi) = (
            min_mm * (1.0 - MEASURED_RANGE_MARGIN),
            max_mm * (1.0 + MEASURED_RANGE_MARGIN),
        );
        if !(radius_mm >= lo && radius_mm <= hi) {
            tune_reply::measured_out_of_range(l, lo, hi);
            return;
        }
        let Some(last) = self.last.filter(|m| m.done_mm.is_finite()) else {
            tune_reply::measured_no_morph(l);
            return;
        };
        if if caliper { last.counted } else { last.read } {
            tune_reply::measured_twice(l);
            return;
        }
        if let (Some(r), true) = (self.rest_shape.reading(), caliper) {
            let both =
                r.sigma_mm * r.sigma_mm + shape::MEASURED_SIGMA_MM * shape::MEASURED_SIGMA_MM;
            let off = radius_mm - r.radius_mm;
            if off * off > shape::AGREE_SIGMAS * shape::AGREE_SIGMAS * both {
                return tune_reply::measured_contradicts(l, radius_mm, r.radius_mm, r.sigma_mm);
            }
        }
        if last.epoch != self.cal_epoch {
            tune_reply::measured_stale(l);
            return;
        }
        let amb = last.ambient_c;
        match last.mode {
            Mode::Boost | Mode::Closed => {
                // The estimate's rise at lock, undone from the reported radius through the map
                // that was in effect, and the rise the measured radius needs.
                let (a, b) = last.map;
                let reported_rise = target::lock_temp_for_final_radius_c(last.done_mm, amb) - amb;
                let x = (reported_rise - a) / b;
                let y = target::lock_temp_for_final_radius_c(radius_mm, amb) - amb;
                match self.settings.cal.fold_map(x, y, read.unwrap_or(1.0)) {
                    Ok((a, b)) => tune_reply::measured_map(l, a, b, self.settings.cal.map_count),
                    Err(why) => tune_reply::measured_implausible(l, why),
                }
            }
            _ => {
                let need = table::power_for_radius_w(radius_mm).unwrap_or(0.0);
                if !(need >= MEASURED_MIN_POWER_W) || !(last.power_w >= MEASURED_MIN_POWER_W) {
                    let why = ReportRejection::PowerTooSmall(MEASURED_MIN_POWER_W);
                    tune_reply::measured_implausible(l, why);
                    return;
                }
                match self.settings.cal.fold_power(last.power_w / need) {
                    Ok(scale) => {
                        tune_reply::measured_power(l, scale, self.settings.cal.power_count)
                    }
                    Err(why) => tune_reply::measured_implausible(l, why),
                }
            }
        }
        if !l.starts_with(protocol::ERROR_TAG) {
            if let Some(m) = self.last.as_mut() {
                if caliper {
                    m.counted = true;
                } else {
                    m.read = true;
                }
            }
            // The link's shape is now measured, not estimated: the rest reference at it, read
            // or still to be read, counts the next morph's strain from the measured shape.
            let (done, measured) = (1e3 / last.done_mm, 1e3 / radius_mm);
            if self.shape_per_m == Some(done) {
                self.shape_per_m = Some(measured);
                self.elec.retag_rest_shape(done, measured);
                if caliper {
                    self.shape_known = true;
                    let (tcr_per_k, gauge) =
                        (self.settings.cal.tcr_per_k(), self.settings.cal.gauge());
                    self.rest_shape.measured(measured, tcr_per_k, gauge);
                    self.strain_from_gauge();
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::supervisor::{FaultCode, Subject};
    use crate::vocab::Sensor;

    fn alarm(value: f32) -> Event {
        Event::Alarm(Fault {
            code: FaultCode::ThermistorOpen,
            subject: Subject::Sensor(Sensor::Pla),
            value,
        })
    }

    fn phase(t_s: f32) -> Event {
        Event::Seq(SeqEvent::Phase {
            phase: Phase::Bend,
            t_s,
            power_w: None,
        })
    }

    /// A host that reads no events for a while loses the oldest progress lines, never an
    /// alarm: a full queue drops its oldest non-alarm event, and with only alarms left, drops
    /// a new non-alarm event instead.
    #[test]
    fn a_full_event_queue_never_evicts_an_alarm() {
        let mut c = Controller::new(Config::DEFAULT);
        c.push(alarm(1.0));
        for k in 0..EVENT_QUEUE + 4 {
            c.push(phase(k as f32));
        }
        let first = c.pop_event();
        assert!(
            matches!(first, Some(Event::Alarm(f)) if f.value == 1.0),
            "{first:?}"
        );
        // The oldest progress lines went; the newest stayed, in order.
        let rest: std::vec::Vec<_> = core::iter::from_fn(|| c.pop_event()).collect();
        assert_eq!(rest.len(), EVENT_QUEUE - 1);
        assert!(
            matches!(rest.last(), Some(Event::Seq(SeqEvent::Phase { t_s, .. })) if *t_s == (EVENT_QUEUE + 3) as f32)
        );
        // All alarms: a progress line is dropped, an alarm replaces the oldest alarm.
        for k in 0..EVENT_QUEUE {
            c.push(alarm(k as f32));
        }
        c.push(phase(0.0));
        c.push(alarm(99.0));
        let all: std::vec::Vec<_> = core::iter::from_fn(|| c.pop_event()).collect();
        assert_eq!(all.len(), EVENT_QUEUE);
        assert!(all.iter().all(|e| matches!(e, Event::Alarm(_))));
        assert!(matches!(all.last(), Some(Event::Alarm(f)) if f.value == 99.0));
    }
}

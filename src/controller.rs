//! The controller: `step(now, inputs) -> outputs` once per control tick, and protocol lines in,
//! reply lines out. It owns the supervisor and the sequencer and is all the firmware, the
//! simulator and the emulated image need: they only move ADC counts in and duties out.
//!
//! Per tick: ADC counts → classified temperatures and supply volts → supervisor (a trip turns
//! both heaters off in this same tick and latches) → sequencer → watts → PWM duties.

use crate::calibration::{Calibration, CalibrationError};
use crate::heater::HeaterConfig;
use crate::protocol::{self, reply, tune_reply, Command, Mode, OutLine, SimCommand};
use crate::sequencer::{SeqEvent, Sequencer};
use crate::stats::LoopTiming;
use crate::supervisor::{Fault, FaultCode, Faults, Frame, Subject, Supervisor};
use crate::table;
use crate::thermistor::ThermistorConfig;
use crate::tune::{Tune, TuneEvent, TuneFailure, TuneTick};
use crate::vocab::{Heater, Phase, Powers};
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
}

impl Config {
    /// 10 kΩ B3950 NTCs with 10 kΩ pull-ups, 16× oversampled 12-bit ADC, 12 V supply sense,
    /// 30 Ω PLA wrap and 6.5 Ω TCA.
    pub const DEFAULT: Config = Config {
        thermistor: ThermistorConfig::DEFAULT.with_full_scale(FULL_SCALE_COUNTS),
        supply: SupplySense::DEFAULT,
        pla_heater: HeaterConfig::PLA,
        tca_heater: HeaterConfig::TCA,
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
}

/// One tick's outputs: PWM duties in [0, 1].
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Outputs {
    /// PLA heater duty.
    pub pla_duty: f32,
    /// TCA heater duty.
    pub tca_duty: f32,
}

/// Something to tell the user unprompted.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Event {
    /// Sequencer progress.
    Seq(SeqEvent),
    /// A safety trip.
    Alarm(Fault),
    /// `TUNE` progress.
    Tune(TuneEvent),
}

/// Depth of the unsolicited-line queue; a morph produces at most six events and a trip one.
pub const EVENT_QUEUE: usize = 16;

/// Longest reply to one command line, bytes: its `data:` lines and final line, each with a
/// `\n`. A bound for a shell that collects a reply before sending it; HELP, the longest, is
/// about 730 (checked in `tests/protocol.rs`).
pub const MAX_REPLY_BYTES: usize = 1024;

/// The controller state.
pub struct Controller {
    cfg: Config,
    seq: Sequencer,
    sup: Supervisor,
    frame: Option<Frame>,
    powers: Powers,
    outputs: Outputs,
    supply_v: f32,
    events: Deque<Event, EVENT_QUEUE>,
    timing: Option<LoopTiming>,
    /// The faults alarmed since the last RESET (code and subject): each alarms once, however
    /// long it stays present.
    alarmed: heapless::Vec<(FaultCode, Subject), ALARMED_MAX>,
    /// This link's calibration (TUNE, MEASURED), read by the strategies at MORPH.
    cal: Calibration,
    /// The tune under way, if any (the sequencer is idle meanwhile).
    tune: Option<Tune>,
    /// The last morph started, for MEASURED.
    last: Option<LastMorph>,
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
    /// A MEASURED report has been counted for it.
    counted: bool,
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
            powers: Powers::default(),
            outputs: Outputs::default(),
            supply_v: f32::NAN,
            events: Deque::new(),
            timing: None,
            alarmed: heapless::Vec::new(),
            cal: Calibration::DEFAULT,
            tune: None,
            last: None,
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

    /// Current phase (Fault while a fault is latched).
    pub fn phase(&self) -> Phase {
        self.seq.phase()
    }

    /// The latched fault, if any (the sequencer holds it: see [`Sequencer::fault`]).
    pub fn fault(&self) -> Option<Fault> {
        self.seq.fault()
    }

    /// Duties to apply now (also right after a command: ABORT zeroes them at once).
    pub fn outputs(&self) -> Outputs {
        self.outputs
    }

    /// Powers commanded in the last tick, W.
    pub fn powers(&self) -> Powers {
        self.powers
    }

    /// True while no morph runs and no fault is latched.
    pub fn idle(&self) -> bool {
        self.phase() == Phase::Idle
    }

    /// True while a morph is under way (not idle, not faulted).
    pub fn busy(&self) -> bool {
        self.seq.busy()
    }

    fn push(&mut self, e: Event) {
        if self.events.is_full() {
            self.events.pop_front();
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

    fn trip(&mut self, fault: Fault) {
        if self.tune.take().is_some() {
            self.push(Event::Tune(TuneEvent::Failed(TuneFailure::Tripped)));
        }
        self.seq.latch(fault);
        self.powers = Powers::default();
        self.outputs = Outputs::default();
        self.alarm_once(fault);
    }

    /// Raises `fault`'s alarm unless the same code and subject has alarmed since RESET.
    fn alarm_once(&mut self, fault: Fault) {
        let key = (fault.code, fault.subject);
        if self.alarmed.contains(&key) {
            return;
        }
        if self.alarmed.is_full() {
            self.alarmed.remove(0);
        }
        let _ = self.alarmed.push(key);
        self.push(Event::Alarm(fault));
    }

    /// One control tick at `now_ms` with this tick's inputs; returns the duties to apply.
    /// The supervisor runs every tick, a latched fault included: STATUS stays live and a new
    /// fault alarms too (the first one found stays latched).
    pub fn step(&mut self, now_ms: u64, inputs: &Inputs) -> Outputs {
        let frame = self.frame_of(inputs);
        self.frame = Some(frame);
        self.supply_v = frame.supply_v;
        if self.fault().is_some() {
            self.powers = Powers::default();
            self.outputs = Outputs::default();
        }
        let mut faults = Faults::new();
        let m = self
            .sup
            .check_all(now_ms, &frame, self.powers, self.seq.phase(), &mut faults);
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
        if let Some(mut t) = self.tune.take() {
            let mut tune_events: heapless::Vec<TuneEvent, 4> = heapless::Vec::new();
            let r = t.tick(now_ms, &m, &mut |e| {
                let _ = tune_events.push(e);
            });
            for e in tune_events {
                self.push(Event::Tune(e));
            }
            let p = match r {
                TuneTick::Run(p) => {
                    self.tune = Some(t);
                    p
                }
                TuneTick::Done(cal) => {
                    self.cal = cal;
                    Powers::default()
                }
                TuneTick::Failed(_) => Powers::default(),
            };
            self.powers = p;
            let v = frame.supply_v;
            self.outputs = Outputs {
                pla_duty: self.cfg.pla_heater.duty(p.pla_w, v),
                tca_duty: self.cfg.tca_heater.duty(p.tca_w, v),
            };
            return self.outputs;
        }
        let mut seq_events: heapless::Vec<SeqEvent, 4> = heapless::Vec::new();
        self.seq.set_supply_v(frame.supply_v);
        let result = self.seq.step(now_ms, &m, &mut |e| {
            let _ = seq_events.push(e);
        });
        for e in seq_events {
            if let (SeqEvent::Done { radius_mm, .. }, Some(last)) = (e, self.last.as_mut()) {
                last.done_mm = radius_mm;
            }
            self.push(Event::Seq(e));
        }
        match result {
            Ok(p) => {
                self.powers = p;
                let v = frame.supply_v;
                self.outputs = Outputs {
                    pla_duty: self.cfg.pla_heater.duty(p.pla_w, v),
                    tca_duty: self.cfg.tca_heater.duty(p.tca_w, v),
                };
            }
            // The sequencer has latched the timeout; report it and turn the heaters off.
            Err(_) => {
                if let Some(f) = self.seq.fault() {
                    self.trip(f);
                }
            }
        }
        self.outputs
    }

    /// Handles one received line: writes zero or more `data:` lines and exactly one final reply
    /// through `out`, except for `SIM` commands, which are returned for the caller (a simulated
    /// build) to carry out and answer. Empty lines get no reply.
    pub fn handle_line(
        &mut self,
        now_ms: u64,
        line: &str,
        out: &mut impl FnMut(&str),
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
    pub fn handle(&mut self, now_ms: u64, cmd: Command, out: &mut impl FnMut(&str)) {
        let mut l = OutLine::new();
        match cmd {
            Command::Morph { radius_mm, mode } => self.morph(now_ms, radius_mm, mode, out),
            Command::Status => {
                self.write_status(&mut l);
                out(&l);
            }
            Command::Abort => {
                if self.fault().is_none() {
                    self.seq.abort();
                }
                if self.tune.take().is_some() {
                    self.push(Event::Tune(TuneEvent::Failed(TuneFailure::Aborted)));
                }
                self.powers = Powers::default();
                self.outputs = Outputs::default();
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
                for h in reply::HELP.iter().chain(tune_reply::HELP.iter()) {
                    l.clear();
                    reply::data(&mut l, h);
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
            Command::Tune => self.start_tune(now_ms, out),
            Command::Measured { radius_mm } => self.measured(radius_mm, out),
        }
    }

    fn morph(&mut self, now_ms: u64, radius_mm: f32, mode: Mode, out: &mut impl FnMut(&str)) {
        let mut l = OutLine::new();
        if let Some(f) = self.fault() {
            reply::fault_latched(&mut l, f.code);
            return out(&l);
        }
        if self.seq.busy() {
            reply::busy_morphing(&mut l, self.seq.phase());
            return out(&l);
        }
        if self.tune.is_some() {
            tune_reply::busy_tuning(&mut l);
            return out(&l);
        }
        if self.frame.is_none() || self.sup.measurements().t_pla_c.is_nan() {
            reply::busy_no_reading(&mut l);
            return out(&l);
        }
        match table::power_for_radius_w(radius_mm) {
            Err(r) => {
                reply::radius_out_of_range(&mut l, r.min_mm, r.max_mm);
                out(&l);
            }
            Ok(table_w) => {
                out(protocol::OK);
                let power_w = (table_w * self.cal.power_scale()).min(HeaterConfig::TCA.max_power_w);
                let mut first: heapless::Vec<SeqEvent, 2> = heapless::Vec::new();
                let m = self.sup.measurements();
                self.last = Some(LastMorph {
                    mode: crate::strategy::AnyStrategy::resolve(mode),
                    power_w,
                    ambient_c: m.t_amb_c,
                    map: self.cal.map(),
                    done_mm: f32::NAN,
                    counted: false,
                });
                let cal = self.cal;
                self.seq
                    .start_from(now_ms, radius_mm, power_w, mode, &m, &cal, &mut |e| {
                        let _ = first.push(e);
                    });
                for e in first {
                    self.push(Event::Seq(e));
                }
            }
        }
    }

    fn reset(&mut self, now_ms: u64, out: &mut impl FnMut(&str)) {
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
                self.seq.clear_fault();
                self.sup.rearm();
                self.alarmed.clear();
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
            Event::Seq(SeqEvent::Done { t_s, radius_mm }) => {
                reply::done_event(&mut l, t_s, radius_mm)
            }
            Event::Alarm(f) => reply::alarm(&mut l, &f),
            Event::Tune(e) => tune_reply::tune_event(&mut l, &e),
        }
        Some(l)
    }
}

/// TUNE, MEASURED and the calibration (see [`crate::tune`], [`crate::calibration`]).
impl Controller {
    /// This link's calibration.
    pub fn calibration(&self) -> Calibration {
        self.cal
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
        self.cal = cal;
        Ok(())
    }

    /// True while a TUNE runs.
    pub fn tuning(&self) -> bool {
        self.tune.is_some()
    }

    /// The step of the TUNE under way, if one runs.
    pub fn tune_step(&self) -> Option<crate::tune::TuneStep> {
        self.tune.as_ref().map(|t| t.step_now())
    }

    fn start_tune(&mut self, now_ms: u64, out: &mut impl FnMut(&str)) {
        let mut l = OutLine::new();
        if let Some(f) = self.fault() {
            reply::fault_latched(&mut l, f.code);
            return out(&l);
        }
        if self.seq.busy() {
            reply::busy_morphing(&mut l, self.seq.phase());
            return out(&l);
        }
        if self.tune.is_some() {
            tune_reply::busy_tuning(&mut l);
            return out(&l);
        }
        let m = self.sup.measurements();
        if self.frame.is_none()
            || !(m.t_pla_c.is_finite() && m.t_tca_c.is_finite() && m.t_amb_c.is_finite())
        {
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
        self.tune = Some(Tune::new(now_ms, self.cal, &mut |e| {
            let _ = first.push(e);
        }));
        for e in first {
            self.push(Event::Tune(e));
        }
    }

    fn measured(&mut self, radius_mm: f32, out: &mut impl FnMut(&str)) {
        use crate::strategy::model::target;
        let mut l = OutLine::new();
        if self.seq.busy() {
            reply::busy_morphing(&mut l, self.seq.phase());
            return out(&l);
        }
        if self.tune.is_some() {
            tune_reply::busy_tuning(&mut l);
            return out(&l);
        }
        let (min_mm, max_mm) = table::range_mm();
        let (lo, hi) = (
            min_mm * (1.0 - MEASURED_RANGE_MARGIN),
            max_mm * (1.0 + MEASURED_RANGE_MARGIN),
        );
        if !(radius_mm >= lo && radius_mm <= hi) {
            tune_reply::measured_out_of_range(&mut l, lo, hi);
            return out(&l);
        }
        let Some(last) = self.last.filter(|m| m.done_mm.is_finite()) else {
            tune_reply::measured_no_morph(&mut l);
            return out(&l);
        };
        if last.counted {
            tune_reply::measured_twice(&mut l);
            return out(&l);
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
                match self.cal.fold_map(x, y) {
                    Ok((a, b)) => tune_reply::measured_map(&mut l, a, b, self.cal.map_count),
                    Err(()) => tune_reply::measured_implausible(&mut l),
                }
            }
            _ => {
                let need = table::power_for_radius_w(radius_mm).unwrap_or(0.0);
                if !(need >= MEASURED_MIN_POWER_W) || !(last.power_w >= MEASURED_MIN_POWER_W) {
                    tune_reply::measured_implausible(&mut l);
                    return out(&l);
                }
                match self.cal.fold_power(last.power_w / need) {
                    Ok(scale) => tune_reply::measured_power(&mut l, scale, self.cal.power_count),
                    Err(()) => tune_reply::measured_implausible(&mut l),
                }
            }
        }
        if !l.starts_with(protocol::ERROR_TAG) {
            if let Some(m) = self.last.as_mut() {
                m.counted = true;
            }
        }
        out(&l);
    }
}

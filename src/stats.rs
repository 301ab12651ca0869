//! Control-loop timing and reset cause, for the `STATS` reply and the boot event.
//!
//! Hardware-free: the firmware reads a free-running cycle counter (the Cortex-M DWT `CYCCNT`)
//! at the start of each control tick, when its ADC burst is done and when its duties are
//! applied, and passes the three counts here; the reset flags it reads from the chip are
//! decoded here too. Simulated builds record nothing, and `STATS` says so.

use crate::protocol::{reply, OutLine};
pub use crate::vocab::{ResetCause, ResetFlags};

/// Writes the line the firmware sends once at boot:
/// `event: boot reset=<cause> board=<name> version=<v>`.
pub fn write_boot_line(l: &mut OutLine, cause: ResetCause, board: &str) {
    reply::boot(l, cause, board, crate::vocab::VERSION);
}

/// Timing of the control loop, from cycle-counter readings. All durations are µs.
///
/// Counts are `u32` and wrap (every 51 s at 84 MHz); differences are taken modulo 2³², which is
/// exact as long as one tick is shorter than a wrap.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LoopTiming {
    cycles_per_us: u32,
    period_nominal_us: u32,
    reset: ResetCause,
    last_start: Option<u32>,
    ticks: u32,
    late_ticks: u32,
    step_last_us: u32,
    step_max_us: u32,
    adc_max_us: u32,
    period_min_us: u32,
    period_max_us: u32,
}

/// A tick counts as late when it starts this much after its nominal time, µs: a tenth of the
/// 100 ms tick, far beyond the executor's wake-up latency, so a late tick means something
/// held the CPU.
pub const LATE_TICK_US: u32 = 10_000;

impl LoopTiming {
    /// Empty statistics for a CPU clocked at `cpu_hz` running ticks every `period_nominal_us`,
    /// after a reset of the given cause.
    pub const fn new(cpu_hz: u32, period_nominal_us: u32, reset: ResetCause) -> Self {
        let per_us = cpu_hz / 1_000_000;
        LoopTiming {
            cycles_per_us: if per_us == 0 { 1 } else { per_us },
            period_nominal_us,
            reset,
            last_start: None,
            ticks: 0,
            late_ticks: 0,
            step_last_us: 0,
            step_max_us: 0,
            adc_max_us: 0,
            period_min_us: u32::MAX,
            period_max_us: 0,
        }
    }

    fn us(&self, from: u32, to: u32) -> u32 {
        to.wrapping_sub(from) / self.cycles_per_us
    }

    /// Records one tick: cycle counts at its start, when its ADC burst ended and when its
    /// duties were applied. The step time is ADC end → duties applied (the core's step and
    /// the PWM update); the period is start → start.
    pub fn record(&mut self, start: u32, adc_done: u32, applied: u32) {
        let step = self.us(adc_done, applied);
        self.step_last_us = step;
        self.step_max_us = self.step_max_us.max(step);
        self.adc_max_us = self.adc_max_us.max(self.us(start, adc_done));
        if let Some(prev) = self.last_start {
            let period = self.us(prev, start);
            self.period_min_us = self.period_min_us.min(period);
            self.period_max_us = self.period_max_us.max(period);
            if period > self.period_nominal_us + LATE_TICK_US {
                self.late_ticks += 1;
            }
        }
        self.last_start = Some(start);
        self.ticks = self.ticks.wrapping_add(1);
    }

    /// Largest deviation of a tick period from nominal since boot, µs (0 before two ticks).
    pub fn jitter_max_us(&self) -> u32 {
        if self.period_max_us == 0 {
            return 0;
        }
        let early = self.period_nominal_us.saturating_sub(self.period_min_us);
        let late = self.period_max_us.saturating_sub(self.period_nominal_us);
        early.max(late)
    }

    /// Writes the `STATS` reply:
    /// `ok ticks= step_us= step_max_us= adc_max_us= period_min_us= period_max_us= jitter_max_us= late= reset=`.
    pub fn write_stats(&self, l: &mut OutLine) {
        let (pmin, pmax) = if self.period_max_us == 0 {
            (0, 0)
        } else {
            (self.period_min_us, self.period_max_us)
        };
        let report = reply::StatsReport {
            ticks: self.ticks,
            step_us: self.step_last_us,
            step_max_us: self.step_max_us,
            adc_max_us: self.adc_max_us,
            period_min_us: pmin,
            period_max_us: pmax,
            jitter_max_us: self.jitter_max_us(),
            late: self.late_ticks,
            reset: self.reset,
        };
        reply::stats(l, &report);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Only the tests need this (the firmware never reads it back).
    impl LoopTiming {
        /// Ticks recorded since boot.
        fn ticks(&self) -> u32 {
            self.ticks
        }

        /// Longest step (ADC end → duties applied) since boot, µs.
        fn step_max_us(&self) -> u32 {
            self.step_max_us
        }
    }

    const MHZ84: u32 = 84_000_000;

    #[test]
    fn most_specific_reset_flag_wins() {
        let pin_and = |f: ResetFlags| ResetCause::from_flags(ResetFlags { pin: true, ..f });
        let d = ResetFlags::default();
        assert_eq!(ResetCause::from_flags(d), ResetCause::Unknown);
        assert_eq!(pin_and(d), ResetCause::Pin);
        let watchdog = ResetFlags {
            watchdog: true,
            ..d
        };
        assert_eq!(pin_and(watchdog), ResetCause::Watchdog);
        let sw = ResetFlags {
            software: true,
            ..d
        };
        assert_eq!(pin_and(sw), ResetCause::Software);
        let por = ResetFlags {
            power_on: true,
            ..d
        };
        assert_eq!(pin_and(por), ResetCause::PowerOn);
        let lp = ResetFlags {
            low_power: true,
            ..d
        };
        assert_eq!(pin_and(lp), ResetCause::LowPower);
        let ww = ResetFlags {
            window_watchdog: true,
            software: true,
            ..d
        };
        assert_eq!(pin_and(ww), ResetCause::WindowWatchdog);
    }

    #[test]
    fn records_step_period_and_jitter() {
        let mut t = LoopTiming::new(MHZ84, 100_000, ResetCause::PowerOn);
        let c = |us: u32| us * 84;
        // Tick 1 at 0: ADC 16 ms, step 50 µs.
        t.record(c(0), c(16_000), c(16_050));
        assert_eq!(t.jitter_max_us(), 0);
        // Tick 2 at 100.2 ms (200 µs late), step 80 µs.
        t.record(c(100_200), c(116_200), c(116_280));
        // Tick 3 at 199.9 ms (300 µs early relative to tick 2's start).
        t.record(c(199_900), c(215_900), c(215_930));
        assert_eq!(t.ticks(), 3);
        assert_eq!(t.step_max_us(), 80);
        assert_eq!(t.jitter_max_us(), 300);
        let mut l = OutLine::new();
        t.write_stats(&mut l);
        assert_eq!(
            l.as_str(),
            "ok ticks=3 step_us=30 step_max_us=80 adc_max_us=16000 period_min_us=99700 \
             period_max_us=100200 jitter_max_us=300 late=0 reset=power-on"
        );
    }

    #[test]
    fn counter_wrap_is_harmless_and_late_ticks_count() {
        let mut t = LoopTiming::new(MHZ84, 100_000, ResetCause::Watchdog);
        let start = u32::MAX - 84 * 10; // 10 µs before the wrap
        t.record(
            start,
            start.wrapping_add(84 * 20),
            start.wrapping_add(84 * 60),
        );
        assert_eq!(t.step_max_us(), 40);
        let next = start.wrapping_add(84 * 115_000); // 15 ms late
        t.record(next, next.wrapping_add(84), next.wrapping_add(2 * 84));
        assert_eq!(t.jitter_max_us(), 15_000);
        let mut l = OutLine::new();
        t.write_stats(&mut l);
        assert!(l.contains("late=1 reset=watchdog"), "{l}");
    }

    #[test]
    fn before_any_tick_reports_zeros() {
        let t = LoopTiming::new(MHZ84, 100_000, ResetCause::Pin);
        let mut l = OutLine::new();
        t.write_stats(&mut l);
        assert_eq!(
            l.as_str(),
            "ok ticks=0 step_us=0 step_max_us=0 adc_max_us=0 period_min_us=0 period_max_us=0 \
             jitter_max_us=0 late=0 reset=pin"
        );
    }

    #[test]
    fn boot_line() {
        let mut l = OutLine::new();
        write_boot_line(&mut l, ResetCause::Software, "nucleo-f401re");
        let rest = l
            .strip_prefix("event: boot reset=software board=nucleo-f401re version=")
            .unwrap();
        assert_eq!(rest, crate::vocab::VERSION);
    }

    #[test]
    fn stats_command_through_the_controller() {
        use crate::controller::{Config, Controller};
        let mut c = Controller::new(Config::DEFAULT);
        let mut replies: heapless::Vec<OutLine, 2> = heapless::Vec::new();
        let mut out = |l: &str| {
            let _ = replies.push(l.try_into().unwrap());
        };
        c.handle_line(0, "stats", &mut out);
        assert!(
            replies[0].starts_with("error: unsupported "),
            "{:?}",
            replies
        );
        c.enable_timing(LoopTiming::new(MHZ84, 100_000, ResetCause::Watchdog));
        c.record_timing(0, 84 * 16_000, 84 * 16_070);
        let mut replies: heapless::Vec<OutLine, 2> = heapless::Vec::new();
        let mut out = |l: &str| {
            let _ = replies.push(l.try_into().unwrap());
        };
        c.handle_line(0, "STATS", &mut out);
        assert_eq!(replies.len(), 1);
        assert!(
            replies[0].starts_with("ok ticks=1 step_us=70 "),
            "{:?}",
            replies
        );
        assert!(c
            .handle_line(0, "STATS now", &mut |l| assert!(
                l.starts_with("error: bad-argument")
            ))
            .is_none());
    }
}

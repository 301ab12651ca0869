//! The serial session: what the firmware's serial task decides, host-tested. Bytes in
//! ([`Session::buffer`], [`Session::received`]), one line answered at a time
//! ([`Session::answer_next`]), replies, events and alarms out ([`Session::output`]).
//!
//! It holds the rules of [`crate::protocol::serial`] together with the controller: an ABORT
//! acts the moment its bytes are read, before the lines ahead of it are answered; behind a
//! flood a reply that will be dropped is not built at all (an empty line stands for it, so it
//! is still counted); a command that changed the duties (ABORT) says so, so the shell applies
//! them at once instead of at the next tick; a SAVE is handed to the shell, which writes the
//! flash with the heaters off and hands the result back ([`Session::finish_save`]). The shell
//! only moves bytes between the port and this type, and carries out the SAVE.

use crate::budget::SUPPLY_RECORD_BYTES;
use crate::controller::{Controller, Inputs, Outputs, MAX_REPLY_BYTES};
use crate::links::{LinkOutputs, Links};
use crate::protocol::serial::{is_abort, Outbox, SerialInput};
use crate::protocol::{format_error, Command, OutLine, SimCommand};
use crate::settings::codec::Blob;
use crate::settings::store::{SaveReport, StoreError};

/// What the firmware's shell serves: one link's [`Controller`] (a one-link image, exactly as
/// before several links existed) or a board's [`Links`]. The session and the firmware's tasks
/// are written once against it; each image monomorphises them for its own.
pub trait Served {
    /// The outputs, compared before and after a line (an ABORT changes them).
    type Out: PartialEq;
    /// How many links.
    fn count(&self) -> usize;
    /// Link `k`'s controller (0-based): its settings, storage and loop timing.
    fn link_mut(&mut self, k: usize) -> &mut Controller;
    /// ABORT as soon as its line is read: every link's heaters off.
    fn abort(&mut self, now_ms: u64);
    /// Runs one command line; a `SIM` command is handed back to the shell with its link
    /// (0-based).
    fn handle_line(
        &mut self,
        now_ms: u64,
        line: &str,
        out: &mut dyn FnMut(&str),
    ) -> Option<(usize, SimCommand)>;
    /// One control tick: `inputs[k]` is link `k`'s frame, `out[k]` gets its duties and
    /// cut-off (each duty already clipped to its PWM window where a budget binds).
    fn tick(&mut self, now_ms: u64, inputs: &[Inputs], out: &mut [Outputs]);
    /// Link `k`'s outputs now (right after a command too).
    fn link_outputs(&self, k: usize) -> Outputs;
    /// Every link's outputs now.
    fn outputs_now(&self) -> Self::Out;
    /// The SAVE a line asked for, once: the link (0-based) whose settings the blob holds.
    fn take_save_request(&mut self) -> Option<(usize, Blob)>;
    /// The SAVE handed out is done: its final reply.
    fn finish_save(&mut self, result: Result<SaveReport, StoreError>, out: &mut dyn FnMut(&str));
    /// The next event or alarm line.
    fn pop_event_line(&mut self) -> Option<OutLine>;
    /// True if `line` starts heating, so that read ahead of an ABORT it is refused: MORPH,
    /// TUNE and HEAT ([`crate::protocol::serial::starts_heating`]); several links add GAIT and
    /// their addressed lines.
    fn starts_heating(line: &str) -> bool {
        crate::protocol::serial::starts_heating(line)
    }
    /// The board's own settings SAVE writes beside link `k`'s (several links' supply budget,
    /// with link 1's: [`Links::board_record`]); a one-link image has none.
    fn board_record(&self, k: usize) -> Option<[u8; SUPPLY_RECORD_BYTES]> {
        let _ = k;
        None
    }
    /// Puts the board's own settings a SAVE kept in force at boot ([`Links::load_board`]); a
    /// one-link image has none.
    fn load_board(&mut self, stored: Result<Option<&[u8]>, ()>) {
        let _ = stored;
    }
}

impl Served for Controller {
    type Out = Outputs;

    fn count(&self) -> usize {
        1
    }

    fn link_mut(&mut self, _: usize) -> &mut Controller {
        self
    }

    fn abort(&mut self, now_ms: u64) {
        self.handle(now_ms, Command::Abort, &mut |_| {});
    }

    fn handle_line(
        &mut self,
        now_ms: u64,
        line: &str,
        out: &mut dyn FnMut(&str),
    ) -> Option<(usize, SimCommand)> {
        Controller::handle_line(self, now_ms, line, out).map(|s| (0, s))
    }

    fn tick(&mut self, now_ms: u64, inputs: &[Inputs], out: &mut [Outputs]) {
        out[0] = self.step(now_ms, &inputs[0]);
    }

    fn link_outputs(&self, _: usize) -> Outputs {
        self.outputs()
    }

    fn outputs_now(&self) -> Self::Out {
        self.outputs()
    }

    fn take_save_request(&mut self) -> Option<(usize, Blob)> {
        Controller::take_save_request(self).map(|b| (0, b))
    }

    fn finish_save(&mut self, result: Result<SaveReport, StoreError>, out: &mut dyn FnMut(&str)) {
        Controller::finish_save(self, result, &mut |l: &str| out(l));
    }

    fn pop_event_line(&mut self) -> Option<OutLine> {
        Controller::pop_event_line(self)
    }
}

impl<const N: usize> Served for Links<N> {
    type Out = [LinkOutputs; N];

    fn count(&self) -> usize {
        Links::count(self)
    }

    fn link_mut(&mut self, k: usize) -> &mut Controller {
        Links::link_mut(self, k)
    }

    fn abort(&mut self, now_ms: u64) {
        self.abort_all(now_ms);
    }

    fn handle_line(
        &mut self,
        now_ms: u64,
        line: &str,
        out: &mut dyn FnMut(&str),
    ) -> Option<(usize, SimCommand)> {
        Links::handle_line(self, now_ms, line, out)
    }

    fn tick(&mut self, now_ms: u64, inputs: &[Inputs], out: &mut [Outputs]) {
        let mut links = [LinkOutputs::default(); N];
        let n = out.len().min(N);
        self.step(now_ms, inputs, &mut links[..n]);
        for (o, l) in out.iter_mut().zip(links) {
            *o = l.out;
        }
    }

    fn link_outputs(&self, k: usize) -> Outputs {
        self.outputs(k).out
    }

    fn outputs_now(&self) -> [LinkOutputs; N] {
        core::array::from_fn(|k| {
            if k < Links::count(self) {
                self.outputs(k)
            } else {
                LinkOutputs::default()
            }
        })
    }

    fn take_save_request(&mut self) -> Option<(usize, Blob)> {
        Links::take_save_request(self)
    }

    fn finish_save(&mut self, result: Result<SaveReport, StoreError>, out: &mut dyn FnMut(&str)) {
        Links::finish_save(self, result, out);
    }

    fn pop_event_line(&mut self) -> Option<OutLine> {
        Links::pop_event_line(self)
    }

    fn board_record(&self, k: usize) -> Option<[u8; SUPPLY_RECORD_BYTES]> {
        Links::board_record(self, k)
    }

    fn starts_heating(line: &str) -> bool {
        crate::protocol::links::starts_heating(line)
    }

    fn load_board(&mut self, stored: Result<Option<&[u8]>, ()>) {
        Links::load_board(self, stored);
    }
}

/// The firmware's output queue, bytes: two of the longest replies.
pub const OUT_BYTES: usize = 2 * MAX_REPLY_BYTES;

/// One reply under construction (the longest one, HELP, fits: [`MAX_REPLY_BYTES`]).
type Reply = heapless::String<MAX_REPLY_BYTES>;

/// What the shell must do once a line has been answered.
#[derive(Debug, Default)]
pub struct Answered {
    /// The command changed the duties (ABORT): apply them now, not at the next tick.
    pub apply_now: bool,
    /// A SAVE to carry out (only ever while nothing heats): write it, then call
    /// [`Session::finish_save`], which queues the reply. `None`: the reply is queued already.
    /// With the link (0-based) whose settings the blob holds.
    pub save: Option<(usize, Blob)>,
}

/// The serial session over an `RX`-byte receive buffer and an `OUT`-byte output queue.
pub struct Session<const RX: usize, const OUT: usize> {
    input: SerialInput<RX>,
    out: Outbox<OUT>,
    reply: Reply,
    /// The reply waiting for a SAVE's result: whether it is an ABORT's and whether it is built.
    waiting: Option<(bool, bool)>,
}

/// Appends `line` and its `\n` to `reply`; a line that does not fit is dropped (the bound is
/// the core's: no reply is longer).
fn push_line(reply: &mut Reply, line: &str) {
    let _ = reply.push_str(line).and_then(|()| reply.push('\n'));
}

impl<const RX: usize, const OUT: usize> Session<RX, OUT> {
    /// A session whose first output is the boot line `boot`.
    pub fn new(boot: &str) -> Self {
        let mut out = Outbox::new();
        out.push_line(boot);
        Session {
            input: SerialInput::new(),
            out,
            reply: Reply::new(),
            waiting: None,
        }
    }

    /// True while received bytes wait to be answered (then the shell answers before it
    /// receives again: [`Session::buffer`] would overwrite them).
    pub fn has_input(&self) -> bool {
        !self.input.is_drained()
    }

    /// Where the next read goes.
    pub fn buffer(&mut self) -> &mut [u8] {
        self.input.buffer()
    }

    /// Reports a read of `len` bytes into [`Session::buffer`] (`lost_after` if input was lost
    /// right after them). A whole ABORT line among them stops what runs now; returns true if
    /// so (apply the duties now). The line is still answered in its turn.
    pub fn received<C: Served>(
        &mut self,
        c: &mut C,
        now_ms: u64,
        len: usize,
        lost_after: bool,
    ) -> bool {
        let abort = self.input.received(len, lost_after);
        if abort {
            c.abort(now_ms);
        }
        abort
    }

    /// Answers the next received line, if a whole one is there: runs it (`sim` carries out a
    /// `SIM` command for a simulated build, writing its reply through the given sink) and
    /// queues its reply, or counts it as dropped. `None` when no whole line is there yet.
    pub fn answer_next<C: Served>(
        &mut self,
        c: &mut C,
        now_ms: u64,
        sim: impl FnOnce(&mut C, u64, (usize, SimCommand), &mut dyn FnMut(&str)),
    ) -> Option<Answered> {
        let out = &self.out;
        let reply = &mut self.reply;
        let answered = self.input.next_line_with(
            |line| {
                reply.clear();
                // Behind a flood the reply will be dropped: not built at all, so a long one (HELP)
                // does not hold the control task up (an ABORT's always is).
                let build = !out.drops_replies() || line.is_ok_and(is_abort);
                let before = c.outputs_now();
                let mut sink = |l: &str| {
                    if build {
                        push_line(reply, l);
                    } else if reply.is_empty() {
                        let _ = reply.push('\n');
                    }
                };
                let abort = match line {
                    Ok(l) => {
                        if let Some(s) = c.handle_line(now_ms, l, &mut sink) {
                            sim(c, now_ms, s, &mut sink);
                        }
                        is_abort(l)
                    }
                    Err(e) => {
                        sink(&format_error(e));
                        false
                    }
                };
                (abort, build, c.outputs_now() != before)
            },
            C::starts_heating,
        )?;
        let (abort, build, changed) = answered;
        let save = c.take_save_request();
        if save.is_some() {
            self.waiting = Some((abort, build));
        } else {
            self.queue_reply(c, abort, build);
        }
        Some(Answered {
            apply_now: changed || abort,
            save,
        })
    }

    /// The SAVE handed out by [`Session::answer_next`] is done (`result`): its reply is queued.
    pub fn finish_save<C: Served>(&mut self, c: &mut C, result: Result<SaveReport, StoreError>) {
        let reply = &mut self.reply;
        c.finish_save(result, &mut |l| push_line(reply, l));
        let (abort, build) = self.waiting.take().unwrap_or((false, true));
        self.queue_reply(c, abort, build);
    }

    fn queue_reply<C: Served>(&mut self, c: &mut C, abort: bool, build: bool) {
        if build {
            self.out.push_reply(&self.reply, abort);
        } else if !self.reply.is_empty() {
            self.out.drop_reply();
        }
        // A MORPH's first event follows its `ok`.
        self.refill(c);
    }

    /// Queues the controller's waiting events and alarms, as room allows.
    pub fn refill<C: Served>(&mut self, c: &mut C) {
        self.out.refill(|| c.pop_event_line());
    }

    /// True while output waits for the port.
    pub fn has_output(&self) -> bool {
        !self.out.is_empty()
    }

    /// The next bytes to write (empty when nothing waits).
    pub fn output(&self) -> &[u8] {
        self.out.chunk()
    }

    /// [`Session::buffer`] and [`Session::output`] at once: the shell reads and writes the port
    /// together while it waits.
    pub fn buffer_and_output(&mut self) -> (&mut [u8], &[u8]) {
        (self.input.buffer(), self.out.chunk())
    }

    /// The port took `n` bytes of [`Session::output`].
    pub fn sent(&mut self, n: usize) {
        self.out.sent(n);
    }

    /// A write failed: the rest of its line is dropped.
    pub fn send_failed(&mut self) {
        self.out.send_failed();
    }

    /// Replies dropped for want of room so far.
    pub fn dropped(&self) -> u32 {
        self.out.dropped()
    }
}

#[cfg(test)]
mod tests {
    extern crate std;
    use super::*;
    use crate::controller::{Config, Inputs, TICK_MS};
    use std::string::String;
    use std::vec::Vec;

    type S = Session<64, OUT_BYTES>;

    /// A controller that has read one healthy frame (22 °C everywhere, 12 V).
    fn controller() -> Controller {
        let cfg = Config::DEFAULT;
        let mut c = Controller::new(cfg);
        let counts = cfg.thermistor.counts_for_temp(22.0);
        let inputs = Inputs {
            thermistor_counts: [counts; 3],
            supply_counts: cfg.supply.counts(12.0),
            sample_ms: 0,
            current: None,
        };
        c.step(0, &inputs);
        c
    }

    fn no_sim(_: &mut Controller, _: u64, _: (usize, SimCommand), out: &mut dyn FnMut(&str)) {
        out("error: unsupported SIM");
    }

    /// Feeds `bytes` in one read, answers every line, drains the output; returns the text and
    /// what each answer asked of the shell.
    fn run(s: &mut S, c: &mut Controller, bytes: &[u8]) -> (String, Vec<bool>) {
        let n = bytes.len().min(s.buffer().len());
        s.buffer()[..n].copy_from_slice(&bytes[..n]);
        let mut apply = Vec::new();
        if s.received(c, 0, n, false) {
            apply.push(true);
        }
        while s.has_input() {
            if let Some(a) = s.answer_next(c, 0, no_sim) {
                apply.push(a.apply_now);
            }
        }
        (drain(s), apply)
    }

    #[test]
    fn the_boot_line_goes_first_and_each_line_gets_its_reply() {
        let mut c = controller();
        let mut s = S::new("event: boot");
        let (text, _) = run(&mut s, &mut c, b"VERSION\nBOGUS\n");
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines[0], "event: boot");
        assert!(lines[1].starts_with("ok version="), "{lines:?}");
        assert!(lines[2].starts_with("error: "), "{lines:?}");
        assert_eq!(lines.len(), 3);
    }

    #[test]
    fn an_abort_stops_the_heaters_when_read_and_asks_for_the_duties_at_once() {
        let mut c = controller();
        let mut s = S::new("event: boot");
        run(&mut s, &mut c, b"HEAT pla 1 10\n");
        assert!(c.busy());
        // Step once so the pulse drives its heater.
        let cfg = Config::DEFAULT;
        let counts = cfg.thermistor.counts_for_temp(22.0);
        c.step(
            TICK_MS,
            &Inputs {
                thermistor_counts: [counts; 3],
                supply_counts: cfg.supply.counts(12.0),
                sample_ms: TICK_MS,
                current: None,
            },
        );
        assert!(c.outputs().pla_duty > 0.0);
        // An ABORT behind a MORPH: the heaters stop on receipt, the MORPH read ahead of it is
        // not run, and the shell is told to apply the duties now.
        let bytes = b"MORPH 38\nABORT\n";
        let n = bytes.len();
        s.buffer()[..n].copy_from_slice(bytes);
        assert!(s.received(&mut c, TICK_MS, n, false));
        assert_eq!(c.outputs().pla_duty, 0.0);
        assert!(!c.busy());
        let first = s.answer_next(&mut c, TICK_MS, no_sim).unwrap();
        let second = s.answer_next(&mut c, TICK_MS, no_sim).unwrap();
        assert!(second.apply_now);
        assert!(!first.apply_now);
        assert!(!c.busy(), "the MORPH read ahead of the ABORT ran");
    }

    /// Every byte the session has to write, as the port would take it.
    fn drain(s: &mut S) -> String {
        let mut text = String::new();
        while s.has_output() {
            let chunk = s.output();
            text.push_str(core::str::from_utf8(chunk).unwrap());
            let n = chunk.len();
            s.sent(n);
        }
        text
    }

    #[test]
    fn behind_a_flood_replies_are_counted_not_built_and_an_abort_still_answers() {
        let mut c = controller();
        let mut s = S::new("event: boot");
        // Five HELPs while the port takes nothing: the queue holds two of the longest
        // replies, so later ones are dropped (counted) until it empties; the ABORT's is queued.
        for line in ["HELP\n", "HELP\n", "HELP\n", "HELP\n", "HELP\n", "ABORT\n"] {
            let b = line.as_bytes();
            s.buffer()[..b.len()].copy_from_slice(b);
            s.received(&mut c, 0, b.len(), false);
            while s.has_input() {
                s.answer_next(&mut c, 0, no_sim);
            }
        }
        let dropped = s.dropped();
        assert!(dropped >= 3, "{dropped}");
        let mut text = drain(&mut s);
        s.refill(&mut c);
        text.push_str(&drain(&mut s));
        assert!(text.contains("\nok\n"), "{text:?}");
        assert!(
            text.contains(&std::format!("{dropped} replies dropped")),
            "{text:?}"
        );
    }

    #[test]
    fn a_save_is_handed_to_the_shell_and_its_reply_follows_the_result() {
        let mut c = controller();
        c.enable_storage();
        let mut s = S::new("event: boot");
        let b = b"SAVE\n";
        s.buffer()[..b.len()].copy_from_slice(b);
        s.received(&mut c, 0, b.len(), false);
        let a = s.answer_next(&mut c, 0, no_sim).unwrap();
        let (link, blob) = a.save.expect("SAVE handed out");
        assert_eq!(link, 0);
        assert!(!blob.as_bytes().is_empty());
        // Nothing but the boot line until the shell reports the write.
        let before = core::str::from_utf8(s.output()).unwrap().to_string();
        assert_eq!(before, "event: boot\n");
        s.finish_save(
            &mut c,
            Ok(SaveReport {
                bytes: blob.as_bytes().len() as u32,
                erases: 0,
            }),
        );
        let after = core::str::from_utf8(s.output()).unwrap().to_string();
        assert!(after.starts_with("event: boot\nok saved"), "{after:?}");
    }

    #[test]
    fn on_several_links_gait_and_addressed_heating_lines_ahead_of_an_abort_are_refused() {
        let cfg = Config::DEFAULT;
        let mut links: Links<2> = Links::new(cfg, 2);
        let counts = cfg.thermistor.counts_for_temp(22.0);
        let frame = Inputs {
            thermistor_counts: [counts; 3],
            supply_counts: cfg.supply.counts(12.0),
            sample_ms: 0,
            current: None,
        };
        let mut out = [crate::links::LinkOutputs::default(); 2];
        links.step(0, &[frame, frame], &mut out);
        let mut s = S::new("event: boot");
        let bytes = b"GAIT 34 42\n@2 MORPH 38\n@* HEAT pla 1 5\n@1 STATUS\nABORT\n";
        s.buffer()[..bytes.len()].copy_from_slice(bytes);
        assert!(s.received(&mut links, 0, bytes.len(), false));
        let no_sim = |_: &mut Links<2>, _, _, out: &mut dyn FnMut(&str)| out("error: no SIM");
        while s.has_input() {
            s.answer_next(&mut links, 0, no_sim);
        }
        let text = drain(&mut s);
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 6, "{text}");
        for l in &lines[1..4] {
            assert!(l.starts_with("error: aborted "), "{text}");
        }
        assert!(lines[4].starts_with("ok phase=idle "), "{text}");
        assert_eq!(lines[5], "ok");
        assert!(
            links.idle(),
            "a line read ahead of the ABORT started a link"
        );
        // One link's grammar is unchanged: an addressed line is not its.
        assert!(!<Controller as Served>::starts_heating("@2 MORPH 38"));
        assert!(<Links<2> as Served>::starts_heating("@2 MORPH 38"));
        assert!(!<Links<2> as Served>::starts_heating("@2 STATUS"));
    }

    #[test]
    fn a_save_without_storage_is_answered_at_once() {
        let mut c = controller();
        let mut s = S::new("event: boot");
        let (text, _) = run(&mut s, &mut c, b"SAVE\n");
        assert!(text.contains("error: unsupported"), "{text:?}");
    }
}

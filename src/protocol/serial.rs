//! The serial path's decisions, for any byte stream: received bytes into lines
//! ([`SerialInput`], with the ABORT-first scan [`AbortScan`]) and replies, events and alarms
//! out ([`Outbox`], the bounded queue that drops and counts replies rather than input). The
//! firmware's serial task only moves bytes between these and the board's port
//! (docs/firmware.md, "The serial path under a flood"); the host tests drive them directly.

use super::reply::{replies_dropped, ERR_ABORTED_AHEAD, ERR_OVERRUN};
use super::{
    parse_line, Assembled, Command, LineAssembler, OutLine, Overrun, ProtoError, ERR_INVALID_LINE,
    ERR_LINE_TOO_LONG, OUT_LINE_BYTES,
};

/// Room for one queued line and its `\n`, bytes: [`OutLine`]'s capacity and one.
pub const LINE_ROOM: usize = OUT_LINE_BYTES + 1;

/// Room an [`Outbox`] keeps free of replies, bytes: two maximal lines with their endings, for
/// event and alarm lines, the dropped-replies notice and an ABORT's reply, so none of them
/// waits behind a flood of replies.
pub const OUT_RESERVE: usize = 2 * LINE_ROOM;

/// Room event lines always leave free in an [`Outbox`], bytes: an ABORT's reply (`ok` and its
/// `\n`), so events queued behind a flood can never crowd it out.
pub const ABORT_REPLY_BYTES: usize = super::OK.len() + 1;

/// Most bytes [`Outbox::chunk`] offers the port in one write, so the serial task yields to the
/// control task between writes (a port may take fewer: the emulated one takes one byte).
pub const TX_CHUNK: usize = 64;
const _: () = assert!(TX_CHUNK > 0 && TX_CHUNK <= LINE_ROOM);

/// Longest line the ABORT-first scan considers, bytes: `ABORT` with room for surrounding
/// blanks; a longer ABORT line is still run, in its turn.
pub const ABORT_SCAN_BYTES: usize = 16;
const _: () = assert!(ABORT_SCAN_BYTES >= "ABORT".len());

/// True if `line` (without its ending) is the ABORT command.
pub fn is_abort(line: &str) -> bool {
    matches!(parse_line(line), Ok(Some(Command::Abort)))
}

/// True if `line` is a command that starts heating: MORPH, TUNE or HEAT (a board of several
/// links adds its own: `session::Served::starts_heating`).
pub fn starts_heating(line: &str) -> bool {
    matches!(
        parse_line(line),
        Ok(Some(
            Command::Morph { .. } | Command::Tune | Command::Heat { .. }
        ))
    )
}

/// The ABORT-first scan: fed every received read as it arrives, it says whether (and where) an `ABORT`
/// line ended in it, so the shell can stop the heaters before answering the lines read ahead
/// of it. It follows line boundaries itself (`\r`, `\n`, `\r\n`), so an ABORT split across
/// two reads is found in the second; after lost input it ignores the line in progress, as
/// [`LineAssembler`] makes that line an overrun.
#[derive(Clone, Debug)]
pub struct AbortScan {
    line: [u8; ABORT_SCAN_BYTES],
    len: u8,
    /// The line in progress cannot be an ABORT (too long, or it lost bytes).
    skip: bool,
}

impl Default for AbortScan {
    fn default() -> Self {
        Self::new()
    }
}

impl AbortScan {
    /// A scan at a line start.
    pub const fn new() -> Self {
        Self {
            line: [0; ABORT_SCAN_BYTES],
            len: 0,
            skip: false,
        }
    }

    /// Scans one read: where the last whole ABORT line (started here or in an earlier read)
    /// ending in `bytes` ends, the offset just past its line-end byte, or `None` if no ABORT
    /// line ends in them. `lost_after`: input was lost right after them.
    pub fn scan(&mut self, bytes: &[u8], lost_after: bool) -> Option<usize> {
        let mut found = None;
        for (i, &b) in bytes.iter().enumerate() {
            if b == b'\r' || b == b'\n' {
                let len = usize::from(self.len);
                if !self.skip && crate::fixed::ascii_str(&self.line[..len]).is_some_and(is_abort) {
                    found = Some(i + 1);
                }
                self.len = 0;
                self.skip = false;
            } else if !self.skip {
                match self.line.get_mut(usize::from(self.len)) {
                    Some(slot) => {
                        *slot = b;
                        self.len += 1;
                    }
                    None => self.skip = true,
                }
            }
        }
        if lost_after {
            self.len = 0;
            self.skip = true;
        }
        found
    }
}

/// Received bytes on their way to lines: one read's buffer of `N` bytes, the
/// [`LineAssembler`] and the [`AbortScan`]. The shell receives into [`SerialInput::buffer`]
/// only when [`SerialInput::is_drained`], reports it with [`SerialInput::received`], then
/// takes lines one at a time with [`SerialInput::next_line`], doing other work between them.
pub struct SerialInput<const N: usize> {
    buf: [u8; N],
    pos: usize,
    len: usize,
    lost: bool,
    /// Where the last ABORT line of this read ends (offset past its line end): lines that end
    /// before it and would start heating are refused ([`ERR_ABORTED_AHEAD`]).
    abort_end: Option<usize>,
    lines: LineAssembler,
    scan: AbortScan,
}

impl<const N: usize> Default for SerialInput<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> SerialInput<N> {
    /// Nothing received, at a line start.
    pub const fn new() -> Self {
        Self {
            buf: [0; N],
            pos: 0,
            len: 0,
            lost: false,
            abort_end: None,
            lines: LineAssembler::new(),
            scan: AbortScan::new(),
        }
    }

    /// True once every received byte has been through the assembler (and a loss after them
    /// marked): time to receive again.
    pub fn is_drained(&self) -> bool {
        self.pos >= self.len && !self.lost
    }

    /// Where the next read goes (only while [`SerialInput::is_drained`]: the bytes not yet
    /// assembled would be overwritten).
    pub fn buffer(&mut self) -> &mut [u8] {
        &mut self.buf
    }

    /// Reports a read of `len` bytes into [`SerialInput::buffer`], `lost_after` if input was
    /// lost right after them. True if an ABORT line ended in them: the shell acts on it now;
    /// the line is still answered in its turn, and a MORPH, TUNE or HEAT line read ahead of it
    /// is answered [`ERR_ABORTED_AHEAD`] instead of run (the user's ABORT stops what was
    /// sent before it, not only what already runs).
    pub fn received(&mut self, len: usize, lost_after: bool) -> bool {
        self.pos = 0;
        self.len = len.min(N);
        self.lost = lost_after;
        self.abort_end = self.scan.scan(&self.buf[..self.len], lost_after);
        self.abort_end.is_some()
    }

    /// Assembles up to the end of the next line and hands `f` what to do with it: the line to
    /// run (without its ending, maybe blank) or the error that answers it (too long, not text,
    /// or it lost bytes: never run). `None` when the received bytes end without a line end.
    pub fn next_line<R>(
        &mut self,
        f: impl FnOnce(Result<&str, &'static ProtoError>) -> R,
    ) -> Option<R> {
        self.next_line_with(f, starts_heating)
    }

    /// As [`SerialInput::next_line`], with `heats` saying which lines start heating (refused
    /// when read ahead of an ABORT).
    pub fn next_line_with<R>(
        &mut self,
        f: impl FnOnce(Result<&str, &'static ProtoError>) -> R,
        heats: impl Fn(&str) -> bool,
    ) -> Option<R> {
        let mut answer = None;
        while self.pos < self.len {
            let byte = self.buf[self.pos];
            self.pos += 1;
            if let Some(line) = self.lines.push_checked(byte) {
                let ahead_of_abort = self.abort_end.is_some_and(|end| self.pos < end);
                answer = Some(f(match line {
                    Ok(Assembled::Line(l)) if ahead_of_abort && heats(l) => Err(&ERR_ABORTED_AHEAD),
                    Ok(Assembled::Line(l)) => Ok(l),
                    Ok(Assembled::TooLong) => Err(&ERR_LINE_TOO_LONG),
                    Ok(Assembled::Invalid) => Err(&ERR_INVALID_LINE),
                    Err(Overrun) => Err(&ERR_OVERRUN),
                }));
                break;
            }
        }
        if self.pos >= self.len && self.lost {
            self.lines.overrun();
            self.lost = false;
        }
        answer
    }
}

/// Replies, events and alarms waiting for the serial port, in an `N`-byte queue, and the
/// replies dropped for want of room (their commands were run).
///
/// A reply goes in whole only if [`OUT_RESERVE`] bytes stay free after it; once one is
/// dropped, every later one is too until the queue has emptied, and then one
/// `error: busy <n> replies dropped` notice goes out, so the notice counts the replies right
/// before it. Input never waits for this queue: a flood costs replies, never commands.
///
/// The queue is a ring of bytes copied a slice at a time (not byte by byte), and
/// [`Outbox::drops_replies`] says before a command runs that its reply will be dropped, so the
/// shell need not build it: a flood of long replies (HELP) then costs the CPU little more than
/// the commands themselves, and the control task is not held up.
pub struct Outbox<const N: usize> {
    buf: [u8; N],
    /// Index of the oldest queued byte.
    head: usize,
    /// Queued bytes.
    len: usize,
    dropped: u32,
    /// The byte at `head` starts a line (the port's last byte was a `\n`, or none was sent).
    at_line_start: bool,
}

impl<const N: usize> Default for Outbox<N> {
    fn default() -> Self {
        Self::new()
    }
}

impl<const N: usize> Outbox<N> {
    /// An empty queue. `N` must hold a maximal line beyond [`OUT_RESERVE`].
    pub const fn new() -> Self {
        const { assert!(N >= OUT_RESERVE + LINE_ROOM) };
        Self {
            buf: [0; N],
            head: 0,
            len: 0,
            dropped: 0,
            at_line_start: true,
        }
    }

    /// True when nothing waits for the port.
    pub fn is_empty(&self) -> bool {
        self.len == 0
    }

    /// Replies dropped since the last notice went out.
    pub fn dropped(&self) -> u32 {
        self.dropped
    }

    /// True if the reply to the next command will be dropped whatever its length (a flood is
    /// being counted and the queue has not emptied yet), unless it is an ABORT's. The shell
    /// then runs the command without building its reply and counts it with
    /// [`Outbox::drop_reply`].
    pub fn drops_replies(&self) -> bool {
        self.dropped > 0
    }

    /// Counts one reply as dropped without queueing it (see [`Outbox::drops_replies`]).
    pub fn drop_reply(&mut self) {
        self.dropped += 1;
    }

    fn room(&self) -> usize {
        N - self.len
    }

    /// Appends `bytes` (they fit: checked by the caller) in at most two slice copies.
    fn append(&mut self, bytes: &[u8]) {
        let tail = (self.head + self.len) % N;
        let first = bytes.len().min(N - tail);
        self.buf[tail..tail + first].copy_from_slice(&bytes[..first]);
        self.buf[..bytes.len() - first].copy_from_slice(&bytes[first..]);
        self.len += bytes.len();
    }

    /// Queues all of `s` if at least `keep` bytes stay free after it; else nothing.
    fn offer(&mut self, s: &str, keep: usize) -> bool {
        if s.len() + keep > self.room() {
            return false;
        }
        self.append(s.as_bytes());
        true
    }

    /// Queues one unsolicited line (the boot line, an event) and its `\n` if it fits; says so.
    pub fn push_line(&mut self, line: &str) -> bool {
        let fits = self.offer(line, 1);
        if fits {
            self.append(b"\n");
        }
        fits
    }

    /// Queues the whole reply to one command (its lines with their endings) or counts it as
    /// dropped. An ABORT's reply may use the reserved room, so it is never dropped behind a
    /// flood.
    pub fn push_reply(&mut self, reply: &str, abort: bool) {
        let queued = if abort {
            self.offer(reply, 0)
        } else {
            self.dropped == 0 && self.offer(reply, OUT_RESERVE)
        };
        if !queued && !reply.is_empty() {
            self.dropped += 1;
        }
    }

    /// Queues the dropped-replies notice once everything before it is out, then as many event
    /// and alarm lines from `next_event` as there is room for.
    pub fn refill(&mut self, mut next_event: impl FnMut() -> Option<OutLine>) {
        if self.dropped > 0 && self.is_empty() {
            let mut l = OutLine::new();
            replies_dropped(&mut l, self.dropped);
            if self.push_line(&l) {
                self.dropped = 0;
            }
        }
        while self.room() >= LINE_ROOM + ABORT_REPLY_BYTES {
            let Some(line) = next_event() else {
                break;
            };
            self.push_line(&line);
        }
    }

    /// The oldest queued bytes, at most [`TX_CHUNK`] (empty when nothing is queued).
    pub fn chunk(&self) -> &[u8] {
        let n = self.len.min(N - self.head).min(TX_CHUNK);
        &self.buf[self.head..self.head + n]
    }

    /// Removes the `n` oldest bytes: the port took them.
    pub fn sent(&mut self, n: usize) {
        let n = n.min(self.len);
        if n > 0 {
            self.at_line_start = self.buf[(self.head + n - 1) % N] == b'\n';
        }
        self.head = (self.head + n) % N;
        self.len -= n;
    }

    /// The port failed to send the current [`Outbox::chunk`]: drops it and the rest of the line
    /// it ends in, and if the port had already taken the start of that line, ends the line
    /// there with a `\n`, so the host sees a cut line, never two lines run together.
    pub fn send_failed(&mut self) {
        let started_mid_line = !self.at_line_start;
        let mut n = self.chunk().len();
        while n < self.len && self.buf[(self.head + n - 1) % N] != b'\n' {
            n += 1;
        }
        self.sent(n);
        if started_mid_line && n > 0 {
            // Dropping freed at least one byte: room for the `\n` in front.
            self.head = (self.head + N - 1) % N;
            self.buf[self.head] = b'\n';
            self.len += 1;
            self.at_line_start = true;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use std::{string::String, vec::Vec};

    /// Everything in `out`, sent as the port would take it.
    fn drain<const N: usize>(out: &mut Outbox<N>) -> String {
        let mut sent = Vec::new();
        while !out.is_empty() {
            let c = out.chunk();
            assert!(!c.is_empty() && c.len() <= TX_CHUNK);
            sent.extend_from_slice(c);
            let n = c.len();
            out.sent(n);
        }
        String::from_utf8(sent).unwrap()
    }

    const SMALL: usize = OUT_RESERVE + 2 * LINE_ROOM;

    #[test]
    fn a_full_queue_drops_and_counts_replies_and_sends_one_notice_per_flood() {
        let mut out: Outbox<SMALL> = Outbox::new();
        let reply = "ok phase=idle t_pla_c=22.0 t_tca_c=22.0 with some more words\n";
        let fits = (SMALL - OUT_RESERVE) / reply.len();
        for _ in 0..fits + 5 {
            out.push_reply(reply, false);
        }
        assert_eq!(out.dropped(), 5);
        // The notice waits until everything queued before it is out.
        out.refill(|| None);
        assert_eq!(out.dropped(), 5);
        // Room again, but the flood is not over until the queue is empty: still dropped.
        out.sent(reply.len());
        out.push_reply(reply, false);
        assert_eq!(out.dropped(), 6);
        let rest = drain(&mut out);
        assert_eq!(rest.matches("ok phase=").count(), fits - 1);
        out.refill(|| None);
        let notice = drain(&mut out);
        assert!(
            notice.starts_with("error: busy 6 replies dropped"),
            "{notice}"
        );
        assert_eq!(notice.matches('\n').count(), 1);
        assert_eq!(out.dropped(), 0);
        // A second flood is counted afresh; an empty reply (a blank line) is never counted.
        out.push_reply("", false);
        out.push_reply(reply, false);
        assert_eq!(out.dropped(), 0);
        assert_eq!(drain(&mut out), reply);
    }

    #[test]
    fn an_abort_reply_and_events_use_the_reserve_behind_a_flood() {
        let mut out: Outbox<SMALL> = Outbox::new();
        let reply = "x".repeat(LINE_ROOM - 1) + "\n";
        while out.dropped() == 0 {
            out.push_reply(&reply, false);
        }
        out.push_reply("ok\n", true);
        assert_eq!(out.dropped(), 1, "the ABORT's ok is queued");
        let mut events = ["event: phase bend", "alarm: x"].into_iter().map(|e| {
            let mut l = OutLine::new();
            l.push_str(e).unwrap();
            l
        });
        out.refill(|| events.next());
        let sent = drain(&mut out);
        assert!(
            sent.ends_with("ok\nevent: phase bend\nalarm: x\n"),
            "{sent}"
        );
    }

    #[test]
    fn drops_replies_says_ahead_that_a_reply_goes_uncounted_until_the_flood_ends() {
        let mut out: Outbox<SMALL> = Outbox::new();
        let reply = "x".repeat(LINE_ROOM - 1) + "\n";
        assert!(!out.drops_replies(), "an empty queue takes replies");
        while out.dropped() == 0 {
            assert!(!out.drops_replies());
            out.push_reply(&reply, false);
        }
        assert!(out.drops_replies());
        // Counted like a queued-then-dropped reply, and the notice counts both kinds.
        out.drop_reply();
        out.push_reply("ok\n", false);
        assert_eq!(out.dropped(), 3);
        drain(&mut out);
        assert!(out.drops_replies(), "until the notice is queued");
        out.refill(|| None);
        assert!(drain(&mut out).starts_with("error: busy 3 replies dropped"));
        assert!(!out.drops_replies());
    }

    #[test]
    fn the_ring_keeps_bytes_in_order_across_its_end() {
        let mut out: Outbox<SMALL> = Outbox::new();
        let mut want = String::new();
        let mut got = String::new();
        // Lines of lengths that do not divide the ring, sent in uneven pieces, wrap many times.
        for i in 0..200usize {
            let line = std::format!("{i}:{}", "y".repeat(i % 37));
            if out.push_line(&line) {
                want.push_str(&line);
                want.push('\n');
            }
            let n = out.chunk().len().min(7 + i % 60);
            got.push_str(core::str::from_utf8(&out.chunk()[..n]).unwrap());
            out.sent(n);
        }
        got.push_str(&drain(&mut out));
        assert_eq!(got, want);
        assert!(want.len() > 3 * SMALL, "the ring wrapped");
    }

    #[test]
    fn a_failed_send_drops_its_line_and_never_runs_two_lines_together() {
        let mut out: Outbox<SMALL> = Outbox::new();
        let long = "y".repeat(TX_CHUNK + 10);
        // At a line start: the failed chunk's whole line goes, the next line is intact.
        assert!(out.push_line(&long) && out.push_line("next"));
        out.send_failed();
        assert_eq!(drain(&mut out), "next\n");
        // Mid-line (the port took the line's first 5 bytes): the rest of the line goes and a
        // `\n` ends what the host has, so it reads a cut line, then the next one.
        assert!(out.push_line(&long) && out.push_line("next"));
        out.sent(5);
        out.send_failed();
        assert_eq!(drain(&mut out), "\nnext\n");
        assert!(
            !out.push_line(&"z".repeat(SMALL)),
            "a line that cannot fit is refused"
        );
        assert!(out.is_empty());
    }

    #[test]
    fn events_never_crowd_out_an_aborts_reply() {
        let mut out: Outbox<SMALL> = Outbox::new();
        let long = "e".repeat(LINE_ROOM - 1);
        // As many maximal event lines as refill will queue.
        out.refill(|| {
            let mut l = OutLine::new();
            l.push_str(&long).unwrap();
            Some(l)
        });
        out.push_reply("ok\n", true);
        assert_eq!(out.dropped(), 0, "the ABORT's ok is queued");
        assert!(drain(&mut out).ends_with("ok\n"));
    }

    /// Feeds `reads` (bytes, lost after them) and collects, per read, whether the scan found
    /// an ABORT and the lines (`Err` for an error reply's code) assembled from it.
    fn feed(reads: &[(&[u8], bool)]) -> Vec<(bool, Vec<Result<String, &'static str>>)> {
        let mut input: SerialInput<128> = SerialInput::new();
        let mut got = Vec::new();
        for &(bytes, lost) in reads {
            assert!(input.is_drained());
            input.buffer()[..bytes.len()].copy_from_slice(bytes);
            let abort = input.received(bytes.len(), lost);
            let mut lines = Vec::new();
            while !input.is_drained() {
                if let Some(l) =
                    input.next_line(|l| l.map(String::from).map_err(|e| e.code.as_str()))
                {
                    lines.push(l);
                }
            }
            got.push((abort, lines));
        }
        got
    }

    #[test]
    fn an_abort_in_the_middle_of_a_read_is_found_before_the_lines_ahead_are_answered() {
        let got = feed(&[(b"STATUS\nSTATUS\nabort \nSTATUS\nSTA", false)]);
        assert!(got[0].0);
        assert_eq!(got[0].1.len(), 4, "ABORT is still answered in its turn");
        assert_eq!(got[0].1[2], Ok(String::from("abort ")));
        // Not a whole ABORT line: no early abort.
        for bytes in [
            &b"STATUS\nABORTX\n"[..],
            b"ABORT 1\n",
            b"XABORT\n",
            b"ABORT",
        ] {
            assert!(!feed(&[(bytes, false)])[0].0, "{bytes:?}");
        }
    }

    #[test]
    fn a_heating_command_read_ahead_of_an_abort_is_refused_and_others_still_run() {
        let got = feed(&[(
            b"MORPH 38\r\nHEAT pla 1 5\nTUNE\nSTATUS\nABORT\nMORPH 38\n",
            false,
        )]);
        assert!(got[0].0);
        assert_eq!(
            got[0].1,
            [
                Err("aborted"),
                Err("aborted"),
                Err("aborted"),
                Ok(String::from("STATUS")),
                Ok(String::from("ABORT")),
                Ok(String::from("MORPH 38"))
            ]
        );
        // Answered before the ABORT arrived, a MORPH ran (the ABORT then stops it); one whose
        // line ends in the ABORT's read is refused.
        let got = feed(&[(b"MORPH 38\n", false), (b"ABORT\n", false)]);
        assert_eq!(got[0].1, [Ok(String::from("MORPH 38"))]);
        let got = feed(&[(b"MORPH", false), (b" 38\nABORT\n", false)]);
        assert_eq!(got[1].1, [Err("aborted"), Ok(String::from("ABORT"))]);
    }

    #[test]
    fn an_abort_split_across_two_reads_is_found_in_the_second() {
        let got = feed(&[(b"STATUS\nAB", false), (b"ORT\nSTATUS\n", false)]);
        assert!(!got[0].0 && got[1].0);
        assert_eq!(
            got[1].1,
            [Ok(String::from("ABORT")), Ok(String::from("STATUS"))]
        );
        // Split before its line end, and a CRLF split between CR and LF.
        assert!(feed(&[(b"ABORT", false), (b"\n", false)])[1].0);
        let got = feed(&[(b"ABORT\r", false), (b"\nSTATUS\n", false)]);
        assert!(got[0].0 && !got[1].0);
        assert_eq!(got[1].1, [Ok(String::from("STATUS"))]);
    }

    #[test]
    fn cr_lf_and_crlf_each_end_an_abort_line() {
        for ending in ["\n", "\r", "\r\n"] {
            let stream = std::format!("STATUS{ending}ABORT{ending}STATS{ending}");
            let got = feed(&[(stream.as_bytes(), false)]);
            assert!(got[0].0, "{ending:?}");
            assert_eq!(
                got[0].1,
                [
                    Ok(String::from("STATUS")),
                    Ok(String::from("ABORT")),
                    Ok(String::from("STATS"))
                ],
                "{ending:?}"
            );
        }
    }

    #[test]
    fn after_lost_input_no_line_is_formed_from_two_and_no_abort_is_guessed() {
        // "STAT" then input lost (the rest of STATUS and the start of "ABORT" gone): the
        // remains "ORT" end as an overrun, never as a command or an early abort.
        let got = feed(&[(b"STAT", true), (b"ORT\nSTATUS\n", false)]);
        assert!(!got[0].0 && !got[1].0);
        assert_eq!(got[1].1, [Err("overrun"), Ok(String::from("STATUS"))]);
        // Lost right after a line end: the next line may be a lost line's tail, so an error.
        let got = feed(&[(b"STATUS\n", true), (b"ABORT\nABORT\n", false)]);
        assert!(got[1].0, "the second, whole ABORT line is found");
        assert_eq!(got[0].1, [Ok(String::from("STATUS"))]);
        assert_eq!(got[1].1, [Err("overrun"), Ok(String::from("ABORT"))]);
        // Too long and invalid text answer with their errors.
        let long = [b'x'; 80];
        let got = feed(&[(&long, false), (b"\n\xff\n", false)]);
        assert_eq!(got[1].1, [Err("line-too-long"), Err("bad-argument")]);
    }

    /// Lines of a stream: commands, an ABORT in any case and spacing, blanks, junk, long lines.
    fn line() -> impl Strategy<Value = String> {
        prop_oneof![
            4 => Just(String::from("STATUS")),
            1 => Just(String::from("MORPH 38")),
            2 => Just(String::from("ABORT")),
            1 => Just(String::from(" abort ")),
            1 => Just(String::from("AB")),
            1 => Just(String::from("ORT")),
            1 => Just(String::new()),
            1 => "[A-Z ]{0,20}",
            1 => "x{60,90}",
        ]
    }

    proptest! {
        /// Whatever the split into reads and wherever input is lost: the lines run are
        /// exactly the sent lines that arrived whole after a line end that arrived (never
        /// pieces of two; any other line is answered with an error), less the MORPH lines
        /// that end ahead of a whole ABORT line in the same read, and the scan finds an ABORT
        /// exactly in the read where such an ABORT line ends.
        #[test]
        fn lines_survive_any_split_and_loss_whole_or_as_errors(
            lines in prop::collection::vec(line(), 1..30),
            endings in prop::collection::vec(prop::sample::select(vec!["\n", "\r", "\r\n"]), 30),
            cuts in prop::collection::vec((1usize..100, any::<bool>(), 1usize..12), 1..40),
        ) {
            let mut stream = Vec::new();
            let mut spans = Vec::new(); // (first byte, first ending byte) of each line
            for (i, (l, e)) in lines.iter().zip(&endings).enumerate() {
                // A CR ending and an empty LF line after it would be one CRLF: end it with LF.
                if l.is_empty() && i > 0 && endings[i - 1] == "\r" && stream.last() == Some(&b'\r') {
                    *stream.last_mut().unwrap() = b'\n';
                }
                spans.push((stream.len(), stream.len() + l.len()));
                stream.extend_from_slice(l.as_bytes());
                stream.extend_from_slice(e.as_bytes());
            }
            // Reads of `take` bytes; after a read marked lost, `skip` bytes never arrive.
            let mut reads = Vec::new(); // (from, to, lost)
            let mut at = 0;
            for &(take, lost, skip) in &cuts {
                if at >= stream.len() {
                    break;
                }
                let to = (at + take).min(stream.len());
                let lost = lost && to < stream.len();
                reads.push((at, to, lost));
                at = if lost { (to + skip).min(stream.len()) } else { to };
            }
            if at < stream.len() {
                reads.push((at, stream.len(), false));
            }
            let mut arrived = vec![false; stream.len()];
            let mut gaps = Vec::new(); // input lost right before these offsets
            for &(from, to, lost) in &reads {
                arrived[from..to].iter_mut().for_each(|a| *a = true);
                if lost {
                    gaps.push(to);
                }
            }
            let clean = |&(s, e): &(usize, usize)| {
                (s == 0 || arrived[s - 1]) && !gaps.iter().any(|g| (s..=e).contains(g))
            };
            let is_abort_line = |l: &String| {
                l.len() <= ABORT_SCAN_BYTES && l.trim().eq_ignore_ascii_case("abort")
            };
            let mut input: SerialInput<64> = SerialInput::new();
            let mut run: Vec<String> = Vec::new();
            // Lines refused as read ahead of an ABORT (index into `lines`).
            let mut refused = vec![false; lines.len()];
            for &(from, to, lost) in &reads {
                for c_from in (from..to).step_by(64) {
                    let c_to = (c_from + 64).min(to);
                    let chunk = &stream[c_from..c_to];
                    input.buffer()[..chunk.len()].copy_from_slice(chunk);
                    let abort = input.received(chunk.len(), lost && c_to == to);
                    let expect = lines.iter().zip(&spans).any(|(l, span)| {
                        (c_from..c_to).contains(&span.1) && clean(span) && is_abort_line(l)
                    });
                    prop_assert_eq!(abort, expect, "read {:?}", String::from_utf8_lossy(chunk));
                    // Where the last whole ABORT line of this read ends: a MORPH line ending
                    // before it in the same read is refused.
                    let abort_end = lines
                        .iter()
                        .zip(&spans)
                        .filter(|(l, span)| (c_from..c_to).contains(&span.1) && clean(span) && is_abort_line(l))
                        .map(|(_, span)| span.1)
                        .max();
                    for (i, (l, span)) in lines.iter().zip(&spans).enumerate() {
                        if l == "MORPH 38" && (c_from..c_to).contains(&span.1) && abort_end.is_some_and(|e| span.1 < e) {
                            refused[i] = true;
                        }
                    }
                    while !input.is_drained() {
                        if let Some(Ok(l)) = input.next_line(|l| l.map(String::from)) {
                            run.push(l);
                        }
                    }
                }
            }
            let want: Vec<String> = lines
                .iter()
                .zip(&spans)
                .zip(&refused)
                .filter(|((l, span), refused)| {
                    l.len() <= crate::protocol::MAX_LINE && clean(span) && !**refused
                })
                .map(|((l, _), _)| l.clone())
                .collect();
            prop_assert_eq!(run, want);
        }
    }
}

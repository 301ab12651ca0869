//! The live view (`morph --live`, `watch`): a terminal UI (ratatui on crossterm) with the
//! temperatures against their targets (and the TCA's own, from its resistance, where the board
//! senses current), the heater powers with their currents and resistances, the supply and its
//! cut-off, the radius (target, the controller's estimate at done, the simulator's truth), the
//! phase and the time left, and the events.
//! Key `a` aborts, `q` quits (with ABORT if a morph this morphctl started still runs).
//!
//! The state ([`LiveState`]) is updated from the lines and samples alone and drawn by [`draw`]
//! onto any ratatui backend, so both are tested without a terminal; [`run`] is the thin shell
//! that polls the link and the keyboard.

use crate::link::{field, Link, LinkError, REPLY_TIMEOUT_S};
use crate::sim_time_and_radius;
use crate::telemetry::Sample;
use morphlink::heater::HeaterConfig;
use morphlink::protocol::client::{classify, LineKind};
use morphlink::protocol::{Mode, MODES};
use morphlink::strategy::{AnyStrategy, Start};
use morphlink::vocab::{Measurements, Phase};
use ratatui::crossterm::event::{self, Event, KeyCode, KeyEventKind, KeyModifiers};
use ratatui::layout::{Constraint, Layout};
use ratatui::style::{Color, Modifier, Style};
use ratatui::symbols::Marker;
use ratatui::text::{Line, Span};
use ratatui::widgets::{Axis, Block, Chart, Dataset, Gauge, GraphType, LegendPosition, Paragraph};
use ratatui::Frame;
use std::collections::VecDeque;
use std::time::{Duration, Instant};

/// Event lines the view keeps (the newest shown at the bottom).
const EVENTS_KEPT: usize = 6;
/// Temperature points the chart keeps per series: at 2 Hz, the last 20 min of a run.
const HISTORY_KEPT: usize = 2400;
/// How long a wait for a key lasts before the link is read again, ms: keys feel immediate and
/// the link's lines are taken well within their reply timeout.
const KEY_POLL_MS: u64 = 20;

/// What the user asked for with a key.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Action {
    /// Nothing (another key).
    None,
    /// Send ABORT and confirm the heaters off.
    Abort,
    /// Leave the view (with ABORT first if a morph this morphctl started still runs).
    Quit,
}

/// The action of a key press: `a` aborts; `q`, Esc and Ctrl-C quit (raw mode turns Ctrl-C into
/// a key, so it must still stop a morph).
pub fn key_action(code: KeyCode, modifiers: KeyModifiers) -> Action {
    match code {
        KeyCode::Char('c') if modifiers.contains(KeyModifiers::CONTROL) => Action::Quit,
        KeyCode::Char('a') | KeyCode::Char('A') => Action::Abort,
        KeyCode::Char('q') | KeyCode::Char('Q') | KeyCode::Esc => Action::Quit,
        _ => Action::None,
    }
}

/// How a morph in view ended.
#[derive(Clone, Debug, PartialEq)]
pub enum Outcome {
    /// `event: done`, with the controller's radius estimate, mm.
    Done(f64),
    /// A gait: every link's `event: done`.
    EveryLinkDone,
    /// An alarm line: the controller has turned the heaters off.
    Alarm(String),
}

/// Everything the view shows, updated from STATUS samples and the device's lines.
#[derive(Clone, Debug)]
pub struct LiveState {
    /// Title: what was sent and to which device.
    pub title: String,
    /// True if this morphctl started the morph (then `q` aborts it).
    pub started: bool,
    /// The latest sample.
    pub last: Option<Sample>,
    /// Link time the current phase began, s (same clock as the samples).
    pub phase_since_s: f64,
    /// PLA and TCA thermistors and the TCA's self-sensed temperature against time, °C.
    pub history: [VecDeque<(f64, f64)>; 3],
    /// The latest events and alarms.
    pub events: VecDeque<String>,
    /// How the morph ended, once it has.
    pub outcome: Option<Outcome>,
    /// morphctl's own limit on the morph, s of link time.
    pub timeout_s: f64,
    /// A note from morphctl (aborting, the heaters confirmed off).
    pub note: Option<String>,
    /// True once the morph this morphctl started has ended and a sample has shown it (the log
    /// and the plot end there; the view goes on until `q`).
    pub ended: bool,
}

impl LiveState {
    /// An empty view titled `title`.
    pub fn new(title: String, started: bool, timeout_s: f64) -> LiveState {
        LiveState {
            title,
            started,
            last: None,
            phase_since_s: 0.0,
            history: [VecDeque::new(), VecDeque::new(), VecDeque::new()],
            events: VecDeque::new(),
            outcome: None,
            timeout_s,
            note: None,
            ended: false,
        }
    }

    /// Takes in one STATUS sample (with the simulator's radius if known). Returns whether it
    /// belongs to the morph's record (`--log`, `--plot`): every sample until the first one
    /// after the morph this morphctl started ended; for `watch`, every sample.
    pub fn sample(&mut self, s: Sample) -> bool {
        let recorded = !self.ended;
        if self.last.as_ref().is_none_or(|l| l.phase != s.phase) {
            self.phase_since_s = s.t_s;
        }
        let temps_c = [s.temps_c[0], s.temps_c[1], s.t_tca_self_c];
        for (h, temp_c) in self.history.iter_mut().zip(temps_c) {
            if temp_c.is_finite() {
                if h.len() == HISTORY_KEPT {
                    h.pop_front();
                }
                h.push_back((s.t_s, temp_c));
            }
        }
        self.last = Some(s);
        if self.started && !self.morphing() {
            self.ended = true;
        }
        recorded
    }

    /// Takes in one unsolicited line (event, done, alarm, boot).
    pub fn line(&mut self, l: &str) {
        match classify(l) {
            LineKind::Done => {
                let r = field(l, "radius_mm").and_then(|v| v.parse().ok());
                self.outcome = Some(Outcome::Done(r.unwrap_or(f64::NAN)));
            }
            LineKind::Alarm => self.outcome = Some(Outcome::Alarm(l.to_string())),
            _ => {}
        }
        if self.events.len() == EVENTS_KEPT {
            self.events.pop_front();
        }
        self.events.push_back(l.to_string());
    }

    /// True while the morph this view follows runs (a morph started and not ended, or, for
    /// `watch`, the device in a morphing phase).
    pub fn morphing(&self) -> bool {
        let phase = self.last.as_ref().map(|s| s.phase.as_str());
        self.outcome.is_none() && !matches!(phase, Some("idle") | Some("fault"))
    }

    /// Seconds left before the current phase's timeout trips, if known.
    pub fn phase_time_left_s(&self) -> Option<f64> {
        let s = self.last.as_ref()?;
        let limit = phase_timeout_s(&s.mode, &s.phase)?;
        Some(limit - (s.t_s - self.phase_since_s))
    }
}

/// The firmware's timeout of `phase` in a morph of strategy `mode`, s (a strategy's own, else
/// the sequencer's); None for an unknown mode or a phase without one.
pub fn phase_timeout_s(mode: &str, phase: &str) -> Option<f64> {
    let mode = *MODES.iter().find(|m| m.as_str() == mode)?;
    let phase = [Phase::Soften, Phase::Bend, Phase::Lock, Phase::Release]
        .into_iter()
        .find(|p| p.as_str() == phase)?;
    let m = Measurements {
        t_pla_c: 22.0,
        t_tca_c: 22.0,
        t_amb_c: 22.0,
    };
    let start = Start {
        now_ms: 0,
        radius_mm: 40.0,
        tca_power_w: 0.5,
        m: &m,
        cal: &morphlink::calibration::Calibration::DEFAULT,
        pla_target_c: morphlink::strategy::model::PLA_SOFT_TARGET_C,
        tca_self_c: f32::NAN,
        rest_shape_per_m: f32::NAN,
    };
    let own = AnyStrategy::new(mode, &start).get().timeout_s(phase);
    use morphlink::sequencer::{
        BEND_TIMEOUT_S, LOCK_TIMEOUT_S, RELEASE_TIMEOUT_S, SOFTEN_TIMEOUT_S,
    };
    let default = match phase {
        Phase::Soften => SOFTEN_TIMEOUT_S,
        Phase::Bend => BEND_TIMEOUT_S,
        Phase::Lock => LOCK_TIMEOUT_S,
        _ => RELEASE_TIMEOUT_S,
    };
    let _: Mode = mode;
    Some(own.unwrap_or(default) as f64)
}

/// `12.34` or `-` for NaN, with `unit`.
pub fn val(v: f64, decimals: usize, unit: &str) -> String {
    if v.is_finite() {
        format!("{v:.decimals$} {unit}")
    } else {
        "-".into()
    }
}

/// The events panel in `area`: the newest of `events` that fit, at the bottom, alarms red and
/// `done` green.
pub fn events_panel(frame: &mut Frame, area: ratatui::layout::Rect, events: &VecDeque<String>) {
    let fit = area.height.saturating_sub(2) as usize;
    let lines: Vec<Line> = events
        .iter()
        .skip(events.len().saturating_sub(fit))
        .map(|e| match classify(e) {
            LineKind::Alarm => Line::styled(e.clone(), Style::default().fg(Color::Red)),
            LineKind::Done => Line::styled(e.clone(), Style::default().fg(Color::Green)),
            _ => Line::raw(e.clone()),
        })
        .collect();
    frame.render_widget(
        Paragraph::new(lines).block(Block::bordered().title("events")),
        area,
    );
}

/// Rows the view needs with its temperature chart (at least 8 rows high); a smaller terminal
/// (80×24) gets every reading and the events, without the chart.
pub const ROWS_WITH_CHART: u16 = 4 + 5 + 4 + 3 + 8 + EVENTS_KEPT as u16 + 2 + 1;

/// Draws the view into `frame`.
pub fn draw(frame: &mut Frame, st: &LiveState) {
    let with_chart = frame.area().height >= ROWS_WITH_CHART;
    let [head, temps, powers, radius, chart, events, keys] = Layout::vertical([
        Constraint::Length(4),
        Constraint::Length(5),
        Constraint::Length(4),
        Constraint::Length(3),
        if with_chart {
            Constraint::Min(8)
        } else {
            Constraint::Length(0)
        },
        if with_chart {
            Constraint::Length(EVENTS_KEPT as u16 + 2)
        } else {
            Constraint::Min(3)
        },
        Constraint::Length(1),
    ])
    .areas(frame.area());
    let chart = if with_chart {
        chart
    } else {
        ratatui::layout::Rect::default()
    };
    let bold = Style::default().add_modifier(Modifier::BOLD);
    let s = st.last.as_ref();
    let num = |f: &dyn Fn(&Sample) -> f64| s.map_or(f64::NAN, f);

    // Phase and time.
    let phase = s.map_or("-", |s| s.phase.as_str());
    let mode = s.map_or("-", |s| s.mode.as_str());
    let t = num(&|s| s.t_s);
    let mut status = vec![
        Span::styled(format!("phase {phase}"), bold),
        Span::raw(format!("  ·  mode {mode}")),
    ];
    // Time since MORPH only for a morph this morphctl sent; `watch` saw no MORPH.
    if st.started {
        status.push(Span::raw(format!("  ·  {} since MORPH", val(t, 1, "s"))));
    }
    if st.morphing() {
        if let Some(left) = st.phase_time_left_s() {
            status.push(Span::raw(format!("  ·  phase timeout in {left:.0} s")));
        }
        status.push(Span::raw(format!(
            "  ·  morphctl gives up in {:.0} s",
            st.timeout_s - t
        )));
    }
    let head_text = match &st.outcome {
        Some(Outcome::Done(r)) => Line::styled(
            format!("done: the controller estimates {}", val(*r, 2, "mm")),
            bold.fg(Color::Green),
        ),
        Some(Outcome::Alarm(a)) => Line::styled(a.clone(), bold.fg(Color::Red)),
        // A morph's view never holds a gait's outcome.
        Some(Outcome::EveryLinkDone) | None => Line::from(status),
    };
    frame.render_widget(
        Paragraph::new(head_text)
            .wrap(ratatui::widgets::Wrap { trim: true })
            .block(Block::bordered().title(st.title.as_str())),
        head,
    );

    // Temperatures against targets.
    let row = |name: &str, i: usize| -> Line {
        let temp = num(&|s| s.temps_c[i]);
        let target = if i < 2 {
            num(&|s| s.targets_c[i])
        } else {
            f64::NAN
        };
        let mut spans = vec![
            Span::styled(format!("{name:<8}"), bold),
            Span::raw(format!("{:>10}", val(temp, 1, "°C"))),
        ];
        if i < 2 {
            spans.push(Span::raw(format!("   target {:>10}", val(target, 1, "°C"))));
            let off = if temp.is_finite() && target.is_finite() {
                format!("{:+.1} K", temp - target)
            } else {
                String::new()
            };
            spans.push(Span::raw(format!("   {off:>8}")));
        }
        // The TCA as its own thermometer, on the thermistor's row to compare at a glance.
        let own = num(&|s| s.t_tca_self_c);
        if i == 1 && own.is_finite() {
            spans.push(Span::raw(format!(
                "   self-sensed {:>8}",
                val(own, 1, "°C")
            )));
        }
        Line::from(spans)
    };
    frame.render_widget(
        Paragraph::new(vec![row("PLA", 0), row("TCA", 1), row("ambient", 2)])
            .block(Block::bordered().title("temperatures")),
        temps,
    );

    // Powers as gauges of the heater caps; the supply and its cut-off in the title.
    let mut title = vec![Span::raw(format!(
        "powers (supply {}",
        val(num(&|s| s.supply_v), 2, "V")
    ))];
    match s.and_then(|s| s.cutoff_closed) {
        Some(true) => title.push(Span::raw(" · cut-off closed")),
        Some(false) => title.push(Span::styled(
            " · cut-off OPEN: no heater supply",
            bold.fg(Color::Red),
        )),
        None => {}
    }
    title.push(Span::raw(")"));
    let powers_block = Block::bordered().title(Line::from(title));
    let [pla_area, tca_area] = Layout::vertical([Constraint::Length(1), Constraint::Length(1)])
        .areas(powers_block.inner(powers));
    frame.render_widget(powers_block, powers);
    for (i, (area, cap, name, colour)) in [
        (
            pla_area,
            HeaterConfig::PLA.max_power_w,
            "PLA heater",
            Color::Red,
        ),
        (
            tca_area,
            HeaterConfig::TCA.max_power_w,
            "TCA heater",
            Color::Blue,
        ),
    ]
    .into_iter()
    .enumerate()
    {
        let p = num(&|s| s.powers_w[i]);
        let ratio = if p.is_finite() {
            (p / cap as f64).clamp(0.0, 1.0)
        } else {
            0.0
        };
        let mut label = format!("{name} {} of {cap:.1} W", val(p, 2, "W"));
        // What the board measured of the heater, where it senses current.
        for (v, decimals, unit) in [
            (num(&|s| s.currents_a[i]), 3, "A"),
            (num(&|s| s.resistances_ohm[i]), 2, "Ω"),
        ] {
            if v.is_finite() {
                label.push_str(&format!("  ·  {}", val(v, decimals, unit)));
            }
        }
        frame.render_widget(
            Gauge::default()
                .gauge_style(Style::default().fg(colour))
                .ratio(ratio)
                .label(label),
            area,
        );
    }

    // The radius.
    let estimate = match st.outcome {
        Some(Outcome::Done(r)) => val(r, 2, "mm"),
        _ => "at done".into(),
    };
    frame.render_widget(
        Paragraph::new(Line::from(vec![
            Span::raw(format!("target {}", val(num(&|s| s.target_mm), 2, "mm"))),
            Span::raw(format!("  ·  controller's estimate {estimate}")),
            Span::raw(format!(
                "  ·  true (sim) {}",
                val(num(&|s| s.radius_mm), 2, "mm")
            )),
        ]))
        .block(Block::bordered().title("radius")),
        radius,
    );

    // Temperatures against time, with the targets.
    let series: Vec<Vec<(f64, f64)>> = st
        .history
        .iter()
        .map(|h| h.iter().copied().collect())
        .collect();
    let t_lo = series
        .iter()
        .flatten()
        .map(|p| p.0)
        .fold(f64::INFINITY, f64::min);
    let t_hi = series
        .iter()
        .flatten()
        .map(|p| p.0)
        .fold(f64::NEG_INFINITY, f64::max);
    let (t_lo, t_hi) = if t_lo.is_finite() {
        (t_lo, t_hi.max(t_lo + 1.0))
    } else {
        (0.0, 1.0)
    };
    let targets: Vec<Vec<(f64, f64)>> = (0..2)
        .map(|i| {
            let v = num(&|s| s.targets_c[i]);
            if v.is_finite() {
                vec![(t_lo, v), (t_hi, v)]
            } else {
                Vec::new()
            }
        })
        .collect();
    let ys = series
        .iter()
        .chain(&targets)
        .flatten()
        .map(|p| p.1)
        .chain([20.0]);
    let (y_lo, y_hi) = ys.fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
        (a.min(v), b.max(v))
    });
    let (y_lo, y_hi) = ((y_lo - 2.0).floor(), (y_hi + 2.0).ceil());
    let mut sets = vec![
        Dataset::default()
            .name("PLA")
            .marker(Marker::Braille)
            .graph_type(GraphType::Line)
            .style(Style::default().fg(Color::Red))
            .data(&series[0]),
        Dataset::default()
            .name("TCA")
            .marker(Marker::Braille)
            .graph_type(GraphType::Line)
            .style(Style::default().fg(Color::Blue))
            .data(&series[1]),
    ];
    if !series[2].is_empty() {
        sets.push(
            Dataset::default()
                .name("TCA self-sensed")
                .marker(Marker::Braille)
                .graph_type(GraphType::Line)
                .style(Style::default().fg(Color::Magenta))
                .data(&series[2]),
        );
    }
    for (i, (name, colour)) in [
        ("PLA target", Color::LightRed),
        ("TCA target", Color::LightBlue),
    ]
    .into_iter()
    .enumerate()
    {
        if !targets[i].is_empty() {
            sets.push(
                Dataset::default()
                    .name(name)
                    .marker(Marker::Dot)
                    .graph_type(GraphType::Line)
                    .style(Style::default().fg(colour))
                    .data(&targets[i]),
            );
        }
    }
    frame.render_widget(
        Chart::new(sets)
            .legend_position(Some(LegendPosition::TopLeft))
            .hidden_legend_constraints((Constraint::Ratio(1, 2), Constraint::Ratio(2, 3)))
            .block(Block::bordered().title(if st.started {
                "temperature (°C) against time since MORPH (s)"
            } else {
                "temperature (°C) against time since watch began (s)"
            }))
            .x_axis(
                Axis::default()
                    .bounds([t_lo, t_hi])
                    .labels([format!("{t_lo:.0}"), format!("{t_hi:.0}")]),
            )
            .y_axis(
                Axis::default()
                    .bounds([y_lo, y_hi])
                    .labels([format!("{y_lo:.0}"), format!("{y_hi:.0}")]),
            ),
        chart,
    );

    events_panel(frame, events, &st.events);

    let help = if st.started && st.morphing() {
        "a: abort   q: quit (aborts the morph)"
    } else {
        "a: abort   q: quit"
    };
    let footer = match &st.note {
        Some(n) => format!("{help}   ·   {n}"),
        None => help.to_string(),
    };
    frame.render_widget(Paragraph::new(footer), keys);
}

/// How the view ended.
#[derive(Debug)]
pub enum LiveEnd {
    /// The user quit with nothing left to stop; the outcome seen, if any.
    Quit(Option<Outcome>),
    /// The user asked for ABORT (`a`, or `q` during a morph this morphctl started).
    Abort,
    /// The link failed (a signal, a lost reply, a closed link, garbage).
    Broken(LinkError),
    /// morphctl's own limit on the morph ran out.
    TimedOut,
}

/// What the view's loop drives ([`run_view`]): a state fed the device's lines and its polls,
/// drawn on each pass. One morph ([`run`]) and a gait (`gait_view`) are two of them.
pub trait View {
    /// Takes in one unsolicited line (event, done, alarm, boot).
    fn line(&mut self, l: &str);
    /// Polls the device once; lines that arrive meanwhile go to `on_event`.
    fn poll(&mut self, link: &mut Link, on_event: &mut dyn FnMut(&str)) -> Result<(), LinkError>;
    /// Draws the view into `frame`.
    fn draw(&self, frame: &mut Frame);
    /// True while something this morphctl started still runs (`q` then aborts it).
    fn running(&self) -> bool;
    /// True once morphctl's own limit on what it started has run out.
    fn timed_out(&self) -> bool;
    /// How what the view follows ended, once it has.
    fn outcome(&self) -> Option<Outcome>;
}

/// One morph (or `watch`) as a [`View`]: STATUS (and SIM STATE on a simulator) per poll, each
/// sample also to `record` until the morph ends.
struct MorphView<'a> {
    st: &'a mut LiveState,
    start: Instant,
    sim_start: Option<f64>,
    record: &'a mut dyn FnMut(&Sample),
}

impl View for MorphView<'_> {
    fn line(&mut self, l: &str) {
        self.st.line(l);
    }

    fn poll(&mut self, link: &mut Link, on_event: &mut dyn FnMut(&str)) -> Result<(), LinkError> {
        let sim = sim_time_and_radius(link, on_event)?;
        let (_, status) = link.command("STATUS", REPLY_TIMEOUT_S, on_event)?;
        let t_s = match sim {
            Some((t, _)) => t - *self.sim_start.get_or_insert(t),
            None => self.start.elapsed().as_secs_f64(),
        };
        let s = Sample::from_status(t_s, &status, sim.map_or(f64::NAN, |x| x.1));
        // The record ends with the morph: the view stays until `q`, the log does not.
        if self.st.sample(s.clone()) {
            (self.record)(&s);
        }
        Ok(())
    }

    fn draw(&self, frame: &mut Frame) {
        draw(frame, self.st);
    }

    fn running(&self) -> bool {
        self.st.started && self.st.morphing()
    }

    fn timed_out(&self) -> bool {
        self.running()
            && self
                .st
                .last
                .as_ref()
                .is_some_and(|s| s.t_s > self.st.timeout_s)
    }

    fn outcome(&self) -> Option<Outcome> {
        self.st.outcome.clone()
    }
}

/// The view's loop on `terminal` for one morph or `watch`: STATUS (and SIM STATE on a
/// simulator) every `poll`, the device's lines and the keys in between. Each sample also goes
/// to `record`.
pub fn run(
    terminal: &mut ratatui::DefaultTerminal,
    link: &mut Link,
    st: &mut LiveState,
    poll: Duration,
    pending: Vec<String>,
    record: &mut dyn FnMut(&Sample),
) -> LiveEnd {
    let mut view = MorphView {
        st,
        start: Instant::now(),
        sim_start: None,
        record,
    };
    run_view(terminal, link, &mut view, poll, pending)
}

/// The loop of any [`View`] on `terminal`: a poll every `poll`, the device's lines and the
/// keys in between (`a` aborts; `q` quits, aborting what this morphctl started and still runs).
pub fn run_view(
    terminal: &mut ratatui::DefaultTerminal,
    link: &mut Link,
    view: &mut dyn View,
    poll: Duration,
    pending: Vec<String>,
) -> LiveEnd {
    let mut lines = pending;
    let mut next_poll = Instant::now();
    loop {
        for l in lines.drain(..) {
            view.line(&l);
        }
        if Instant::now() >= next_poll {
            next_poll = Instant::now() + poll;
            if let Err(e) = view.poll(link, &mut |l| lines.push(l.to_string())) {
                return LiveEnd::Broken(e);
            }
            if view.timed_out() {
                return LiveEnd::TimedOut;
            }
        }
        if let Err(e) = terminal.draw(|f| view.draw(f)) {
            return LiveEnd::Broken(LinkError::Closed(format!("cannot draw the live view: {e}")));
        }
        match event::poll(Duration::from_millis(KEY_POLL_MS)) {
            Ok(true) => {
                if let Ok(Event::Key(k)) = event::read() {
                    if k.kind == KeyEventKind::Press {
                        match key_action(k.code, k.modifiers) {
                            Action::Abort => return LiveEnd::Abort,
                            Action::Quit if view.running() => return LiveEnd::Abort,
                            Action::Quit => return LiveEnd::Quit(view.outcome()),
                            Action::None => {}
                        }
                    }
                }
            }
            Ok(false) => {}
            Err(e) => {
                return LiveEnd::Broken(LinkError::Closed(format!("cannot read the keyboard: {e}")))
            }
        }
        match link.recv(Duration::from_millis(1)) {
            Ok(Some(l)) => lines.push(l),
            Ok(None) => {}
            Err(e) => return LiveEnd::Broken(e),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ratatui::backend::TestBackend;
    use ratatui::Terminal;

    fn status(phase: &str, pla: f64, p_pla: f64, targets: &str) -> String {
        format!("ok phase={phase} target_mm=38.00 t_pla_c={pla} t_tca_c=50.00 t_amb_c=22.00 p_pla_w={p_pla} p_tca_w=1.000 supply_v=12.00 fault=none {targets}")
    }

    /// The current sense of a board that has it, and its cut-off closed.
    const SENSED: &str = "i_pla_a=0.409 i_tca_a=1.773 r_pla_ohm=29.51 r_tca_ohm=6.75 t_tca_self_c=58.12 cutoff=closed";

    fn screen(st: &LiveState) -> String {
        screen_of(st, 110, 40)
    }

    fn screen_of(st: &LiveState, w: u16, h: u16) -> String {
        let mut t = Terminal::new(TestBackend::new(w, h)).unwrap();
        t.draw(|f| draw(f, st)).unwrap();
        let buf = t.backend().buffer();
        let w = buf.area.width as usize;
        let cells: Vec<&str> = buf.content().iter().map(|c| c.symbol()).collect();
        cells
            .chunks(w)
            .map(|r| r.concat())
            .collect::<Vec<_>>()
            .join("\n")
    }

    #[test]
    fn keys_abort_and_quit_and_ctrl_c_quits() {
        assert_eq!(
            key_action(KeyCode::Char('a'), KeyModifiers::NONE),
            Action::Abort
        );
        assert_eq!(
            key_action(KeyCode::Char('q'), KeyModifiers::NONE),
            Action::Quit
        );
        assert_eq!(key_action(KeyCode::Esc, KeyModifiers::NONE), Action::Quit);
        assert_eq!(
            key_action(KeyCode::Char('c'), KeyModifiers::CONTROL),
            Action::Quit
        );
        assert_eq!(
            key_action(KeyCode::Char('c'), KeyModifiers::NONE),
            Action::None
        );
        assert_eq!(key_action(KeyCode::Enter, KeyModifiers::NONE), Action::None);
    }

    #[test]
    fn the_state_follows_samples_and_lines() {
        let t = "pla_target_c=75.00 tca_target_c=57.50 mode=closed";
        let mut st = LiveState::new("MORPH 38 auto on test".into(), true, 900.0);
        assert!(st.morphing(), "a started morph runs until told otherwise");
        st.sample(Sample::from_status(
            0.0,
            &status("soften", 22.0, 5.0, t),
            53.0,
        ));
        st.sample(Sample::from_status(
            3.0,
            &status("soften", 60.0, 5.0, t),
            52.0,
        ));
        st.line("event: phase bend t=3.4 power_w=0.698");
        st.sample(Sample::from_status(
            4.0,
            &status("bend", 70.0, 3.0, t),
            45.0,
        ));
        assert_eq!(st.phase_since_s, 4.0);
        assert_eq!(st.history[0].len(), 3);
        // closed's bend times out after the sequencer's 120 s.
        assert_eq!(st.phase_time_left_s(), Some(120.0));
        st.sample(Sample::from_status(
            14.0,
            &status("bend", 74.0, 2.0, t),
            38.2,
        ));
        assert_eq!(st.phase_time_left_s(), Some(110.0));
        assert!(st.morphing() && st.outcome.is_none());
        st.line("event: done t=23.0 radius_mm=38.01");
        assert_eq!(st.outcome, Some(Outcome::Done(38.01)));
        assert!(!st.morphing());
        for i in 0..10 {
            st.line(&format!("event: phase x t={i}"));
        }
        assert_eq!(st.events.len(), EVENTS_KEPT);
        assert_eq!(st.events.back().unwrap(), "event: phase x t=9");
        let mut st = LiveState::new("t".into(), true, 900.0);
        st.line("alarm: over-temperature pla ...");
        assert!(matches!(st.outcome, Some(Outcome::Alarm(_))) && !st.morphing());
        // watch: nothing started, the device's phase says whether a morph runs.
        let mut st = LiveState::new("watch".into(), false, 900.0);
        st.sample(Sample::from_status(
            0.0,
            &status("idle", 22.0, 0.0, ""),
            f64::NAN,
        ));
        assert!(!st.morphing());
    }

    #[test]
    fn paper_has_its_own_phase_timeouts() {
        assert_eq!(phase_timeout_s("closed", "lock"), Some(600.0));
        let paper = phase_timeout_s("paper", "soften").unwrap();
        assert!(paper < 60.0, "{paper}");
        assert_eq!(phase_timeout_s("-", "bend"), None);
        assert_eq!(phase_timeout_s("closed", "idle"), None);
    }

    #[test]
    fn the_view_draws_temperatures_targets_powers_radius_phase_and_keys() {
        let t = &format!("pla_target_c=75.00 tca_target_c=57.50 mode=closed {SENSED}");
        let mut st = LiveState::new("MORPH 38 auto on morph-sim".into(), true, 900.0);
        st.sample(Sample::from_status(
            0.0,
            &status("soften", 22.0, 5.0, t),
            53.0,
        ));
        st.line("event: phase bend t=3.4 power_w=0.698");
        st.sample(Sample::from_status(
            4.0,
            &status("bend", 70.12, 2.5, t),
            44.5,
        ));
        let s = screen(&st);
        for want in [
            "MORPH 38 auto on morph-sim",
            "phase bend",
            "mode closed",
            "4.0 s since MORPH",
            "phase timeout in 120 s",
            "70.1 °C",
            "target    75.0 °C",
            "-4.9 K",
            "target    57.5 °C",
            "PLA heater 2.50 W of 5.0 W  ·  0.409 A  ·  29.51 Ω",
            "TCA heater 1.00 W of 2.0 W  ·  1.773 A  ·  6.75 Ω",
            "supply 12.00 V · cut-off closed",
            "self-sensed  58.1 °C",
            "target 38.00 mm",
            "controller's estimate at done",
            "true (sim) 44.50 mm",
            "event: phase bend t=3.4",
            "PLA target",
            "TCA self-sensed",
            "a: abort   q: quit (aborts the morph)",
        ] {
            assert!(s.contains(want), "`{want}` not on screen:\n{s}");
        }
        assert_eq!(st.history[2].len(), 2, "the self-sensed TCA is charted");
        st.line("event: done t=23.0 radius_mm=38.01");
        st.note = Some("heaters off".into());
        let s = screen(&st);
        assert!(s.contains("done: the controller estimates 38.01 mm"), "{s}");
        assert!(s.contains("a: abort   q: quit   ·   heaters off"), "{s}");
        // An alarm opened the cut-off.
        let open = t.replace("cutoff=closed", "cutoff=open");
        st.line("alarm: heater-open tca heater carries 0.00 A while driven; ...");
        st.sample(Sample::from_status(
            9.0,
            &status("fault", 60.0, 0.0, &open),
            44.5,
        ));
        let s = screen(&st);
        assert!(s.contains("cut-off OPEN: no heater supply"), "{s}");
        // A board without current sense: the cut-off, nothing it does not measure.
        let bare =
            "mode=closed i_pla_a=- i_tca_a=- r_pla_ohm=- r_tca_ohm=- t_tca_self_c=- cutoff=closed";
        let mut st = LiveState::new("bare".into(), false, 900.0);
        st.sample(Sample::from_status(
            0.0,
            &status("idle", 22.0, 0.0, bare),
            f64::NAN,
        ));
        let s = screen(&st);
        assert!(s.contains("supply 12.00 V · cut-off closed)"), "{s}");
        for gone in ["self-sensed", " A ", "Ω"] {
            assert!(
                !s.contains(gone),
                "`{gone}` on a board without current sense:\n{s}"
            );
        }
        // A board: no truth, no targets from an older firmware.
        let mut st = LiveState::new("board".into(), false, 900.0);
        st.sample(Sample::from_status(
            0.0,
            &status("idle", 22.0, 0.0, ""),
            f64::NAN,
        ));
        let s = screen(&st);
        assert!(
            s.contains("true (sim) -") && s.contains("target          -"),
            "{s}"
        );
        // ... nor a cut-off: the title of before.
        assert!(
            s.contains("powers (supply 12.00 V)") && !s.contains("cut-off"),
            "{s}"
        );
        // watch sent no MORPH: no time since one.
        assert!(!s.contains("since MORPH"), "{s}");
    }

    #[test]
    fn every_reading_fits_an_80_by_24_terminal() {
        // The widest a TCA row gets: a three-digit miss beside its own reading.
        let sensed = SENSED.replace("t_tca_self_c=58.12", "t_tca_self_c=128.12");
        let t = &format!("pla_target_c=75.00 tca_target_c=157.50 mode=closed {sensed}");
        let mut st = LiveState::new(
            "MORPH 37.5 auto on morph-sim (plant hifi)".into(),
            true,
            900.0,
        );
        st.line("event: phase soften t=0.0 power_w=5.000");
        st.line("event: phase bend t=3.4 power_w=0.698");
        st.sample(Sample::from_status(
            4.0,
            &status("bend", 70.12, 2.5, t),
            37.46,
        ));
        let s = screen_of(&st, 80, 24);
        for want in [
            "phase bend",
            "70.1 °C",
            "PLA heater 2.50 W of 5.0 W",
            // The TCA's row, its power and the ambient row were cut off at 80×24.
            "50.0 °C",
            "target   157.5 °C",
            "-107.5 K",
            "self-sensed 128.1 °C",
            "TCA heater 1.00 W of 2.0 W  ·  1.773 A  ·  6.75 Ω",
            "PLA heater 2.50 W of 5.0 W  ·  0.409 A  ·  29.51 Ω",
            "ambient",
            "22.0 °C",
            "supply 12.00 V · cut-off closed",
            "target 38.00 mm",
            // Was cut to `37.` at 80 columns.
            "true (sim) 37.46 mm",
            "event: phase bend t=3.4",
            "a: abort   q: quit (aborts the morph)",
        ] {
            assert!(s.contains(want), "`{want}` not on an 80×24 screen:\n{s}");
        }
        st.line("alarm: heater-short tca ...");
        let open = t.replace("cutoff=closed", "cutoff=open");
        st.sample(Sample::from_status(
            5.0,
            &status("fault", 70.12, 0.0, &open),
            37.46,
        ));
        let s = screen_of(&st, 80, 24);
        assert!(
            s.contains("supply 12.00 V · cut-off OPEN: no heater supply)"),
            "{s}"
        );
    }

    #[test]
    fn the_record_ends_with_the_morph_the_view_does_not() {
        let t = "pla_target_c=75.00 tca_target_c=57.50 mode=closed";
        let mut st = LiveState::new("MORPH 38 auto on test".into(), true, 900.0);
        assert!(st.sample(Sample::from_status(
            0.0,
            &status("soften", 22.0, 5.0, t),
            53.0
        )));
        assert!(st.sample(Sample::from_status(
            20.0,
            &status("lock", 60.0, 0.0, t),
            38.0
        )));
        st.line("event: done t=20.3 radius_mm=38.01");
        // The sample that shows the end is the record's last.
        assert!(st.sample(Sample::from_status(
            20.5,
            &status("idle", 59.0, 0.0, ""),
            38.0
        )));
        for i in 0..300 {
            let later = Sample::from_status(21.0 + i as f64, &status("idle", 50.0, 0.0, ""), 38.0);
            assert!(!st.sample(later), "sample {i} after done was recorded");
        }
        assert_eq!(
            st.last.as_ref().unwrap().t_s,
            320.0,
            "the view still follows"
        );
        // watch records on (it has no morph of its own to end).
        let mut w = LiveState::new("watch".into(), false, f64::INFINITY);
        for i in 0..3 {
            assert!(w.sample(Sample::from_status(
                i as f64,
                &status("idle", 22.0, 0.0, ""),
                f64::NAN
            )));
        }
    }
}

//! The live view of a gait (`gait --live`): a row per link (phase, temperatures, power, radius
//! against its target, how it ended), the supply's total power against its budget, and the
//! events. The state is fed the device's lines and polls alone and drawn onto any ratatui
//! backend, so it is tested without a terminal; the loop is the live view's own
//! ([`crate::live::run_view`]).

use crate::gait::{self, Clock, End, GaitSample};
use crate::link::{field, Link, LinkError};
use crate::live::{events_panel, val, Outcome, View};
use morphlink::protocol::client::{classify, link_of, LineKind};
use ratatui::layout::{Constraint, Layout};
use ratatui::style::{Color, Modifier, Style};
use ratatui::text::Line;
use ratatui::widgets::{Block, Gauge, Paragraph};
use ratatui::Frame;
use std::collections::VecDeque;

/// Event lines the view keeps.
const EVENTS_KEPT: usize = 8;

/// A gait in view: what each link last reported and how it ended.
pub struct GaitView<'a> {
    /// Title: what was sent and to which device.
    pub title: String,
    /// Each link's last sample.
    pub rows: Vec<Option<GaitSample>>,
    /// How each link's morph stands, with its `done` radius (the controller's estimate, mm).
    pub ends: Vec<(End, f64)>,
    /// The latest events and alarms.
    pub events: VecDeque<String>,
    /// morphctl's own limit on the gait, s of link time.
    pub timeout_s: f64,
    clock: Clock,
    /// Each sample also goes here until every link has ended (`--log`, `--plot`).
    record: &'a mut dyn FnMut(&GaitSample),
}

impl<'a> GaitView<'a> {
    /// The view of a gait of `links` links just started, titled `title`.
    pub fn new(
        title: String,
        links: usize,
        timeout_s: f64,
        record: &'a mut dyn FnMut(&GaitSample),
    ) -> GaitView<'a> {
        GaitView {
            title,
            rows: vec![None; links],
            ends: vec![(End::Running, f64::NAN); links],
            events: VecDeque::new(),
            timeout_s,
            clock: Clock::new(),
            record,
        }
    }

    /// Takes in one poll's samples.
    pub fn take(&mut self, poll: Vec<GaitSample>) {
        let recorded = self.running();
        for s in poll {
            if recorded {
                (self.record)(&s);
            }
            if let Some(r) = self.rows.get_mut(s.link) {
                *r = Some(s);
            }
        }
    }

    fn time_s(&self) -> f64 {
        self.rows
            .iter()
            .flatten()
            .map(|s| s.sample.t_s)
            .fold(f64::NAN, f64::max)
    }
}

impl View for GaitView<'_> {
    fn line(&mut self, l: &str) {
        let end = match classify(l) {
            LineKind::Done => Some(End::Done),
            LineKind::Alarm => Some(End::Alarm),
            _ => None,
        };
        if let Some(end) = end {
            let r = field(l, "radius_mm")
                .and_then(|v| v.parse().ok())
                .unwrap_or(f64::NAN);
            match link_of(l).0 {
                Some(k) if k < self.ends.len() => self.ends[k] = (end, r),
                // An unaddressed alarm is the board's: every link has stopped.
                _ => self.ends.iter_mut().for_each(|e| *e = (end, r)),
            }
        }
        if self.events.len() == EVENTS_KEPT {
            self.events.pop_front();
        }
        self.events.push_back(l.to_string());
    }

    fn poll(&mut self, link: &mut Link, on_event: &mut dyn FnMut(&str)) -> Result<(), LinkError> {
        let poll = gait::poll(link, &mut self.clock, on_event)?;
        self.take(poll);
        Ok(())
    }

    fn draw(&self, frame: &mut Frame) {
        draw(frame, self);
    }

    fn running(&self) -> bool {
        self.ends.iter().any(|e| e.0 == End::Running)
    }

    fn timed_out(&self) -> bool {
        self.running() && self.time_s() > self.timeout_s
    }

    fn outcome(&self) -> Option<Outcome> {
        if self.running() {
            return None;
        }
        let alarm = self
            .events
            .iter()
            .rev()
            .find(|l| classify(l) == LineKind::Alarm);
        match alarm {
            Some(a) if self.ends.iter().any(|e| e.0 == End::Alarm) => {
                Some(Outcome::Alarm(a.clone()))
            }
            _ => Some(Outcome::EveryLinkDone),
        }
    }
}

/// One link's row: its phase, temperatures, power, radius against target, and its end.
fn row(k: usize, s: Option<&GaitSample>, end: (End, f64)) -> Line<'static> {
    let nan = f64::NAN;
    let get = |f: &dyn Fn(&GaitSample) -> f64| s.map_or(nan, f);
    let phase = s.map_or("-".to_string(), |s| s.sample.phase.clone());
    let text = format!(
        "@{}  {:<8} PLA {:>9}  TCA {:>9}  power {:>7}  radius {:>9} → {:>9}  {}",
        k + 1,
        phase,
        val(get(&|s| s.sample.temps_c[0]), 1, "°C"),
        val(get(&|s| s.sample.temps_c[1]), 1, "°C"),
        val(get(&|s| s.sample.powers_w.iter().sum()), 2, "W"),
        val(get(&|s| s.sample.radius_mm), 2, "mm"),
        val(get(&|s| s.sample.target_mm), 2, "mm"),
        match end.0 {
            End::Running => String::new(),
            End::Done => format!("done {}", val(end.1, 2, "mm")),
            End::Alarm => "alarm".into(),
        }
    );
    match end.0 {
        End::Running => Line::raw(text),
        End::Done => Line::styled(text, Style::default().fg(Color::Green)),
        End::Alarm => Line::styled(text, Style::default().fg(Color::Red)),
    }
}

/// Draws the gait's view into `frame`.
pub fn draw(frame: &mut Frame, v: &GaitView) {
    let links = v.rows.len() as u16;
    let [head, rows, supply, events, keys] = Layout::vertical([
        Constraint::Length(3),
        Constraint::Length(links + 2),
        Constraint::Length(3),
        Constraint::Min(3),
        Constraint::Length(1),
    ])
    .areas(frame.area());
    let bold = Style::default().add_modifier(Modifier::BOLD);
    let t = v.time_s();
    let head_text = match v.outcome() {
        Some(Outcome::Alarm(a)) => Line::styled(a, bold.fg(Color::Red)),
        Some(_) => Line::styled("done: every link", bold.fg(Color::Green)),
        None => Line::styled(
            format!(
                "{} since GAIT  ·  morphctl gives up in {:.0} s",
                val(t, 1, "s"),
                v.timeout_s - t
            ),
            bold,
        ),
    };
    frame.render_widget(
        Paragraph::new(head_text).block(Block::bordered().title(v.title.as_str())),
        head,
    );
    let lines: Vec<Line> = (0..v.rows.len())
        .map(|k| row(k, v.rows[k].as_ref(), v.ends[k]))
        .collect();
    frame.render_widget(
        Paragraph::new(lines).block(Block::bordered().title("links")),
        rows,
    );
    let first = v.rows.iter().flatten().next();
    let total = first.map_or(f64::NAN, |s| s.total_w);
    let budget = first.map_or(f64::NAN, |s| s.budget_w);
    let ratio = if total.is_finite() && budget > 0.0 {
        (total / budget).clamp(0.0, 1.0)
    } else {
        0.0
    };
    frame.render_widget(
        Gauge::default()
            .block(Block::bordered().title("supply: every heater's power against the budget"))
            .gauge_style(Style::default().fg(Color::Yellow))
            .ratio(ratio)
            .label(format!("{} of {}", val(total, 2, "W"), val(budget, 2, "W"))),
        supply,
    );
    events_panel(frame, events, &v.events);
    let help = if v.running() {
        "a: abort every link   q: quit (aborts the gait)"
    } else {
        "a: abort   q: quit"
    };
    frame.render_widget(Paragraph::new(help), keys);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::telemetry::Sample;
    use ratatui::backend::TestBackend;
    use ratatui::Terminal;

    fn sample(link: usize, t_s: f64, phase: &str, p_pla: f64) -> GaitSample {
        let status = format!(
            "ok phase={phase} target_mm={} t_pla_c=70.00 t_tca_c=30.00 t_amb_c=22.00 p_pla_w={p_pla:.3} p_tca_w=0.500 supply_v=12.00 fault=none",
            34 + 8 * link
        );
        GaitSample {
            link,
            sample: Sample::from_status(t_s, &status, 50.0),
            total_w: 6.0,
            budget_w: 8.0,
        }
    }

    fn screen(v: &GaitView) -> String {
        let mut t = Terminal::new(TestBackend::new(110, 24)).unwrap();
        t.draw(|f| draw(f, v)).unwrap();
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
    fn a_row_per_link_and_the_total_against_the_budget() {
        let mut recorded = 0;
        let mut record = |_: &GaitSample| recorded += 1;
        let mut v = GaitView::new("GAIT 34 42 auto on test".into(), 2, 600.0, &mut record);
        v.take(vec![
            sample(0, 5.0, "bend", 4.0),
            sample(1, 5.0, "soften", 1.0),
        ]);
        let text = screen(&v);
        assert!(text.contains("@1  bend"), "{text}");
        assert!(text.contains("@2  soften"), "{text}");
        assert!(
            text.contains("4.50 W") && text.contains("42.00 mm"),
            "{text}"
        );
        assert!(text.contains("6.00 W of 8.00 W"), "{text}");
        assert!(v.running() && v.outcome().is_none());

        v.line("@1 event: done t=30.0 radius_mm=34.02");
        assert!(v.running(), "link 2 still runs");
        v.line("@2 alarm: thermistor-open pla thermistor reads open circuit");
        assert!(!v.running());
        assert!(matches!(v.outcome(), Some(Outcome::Alarm(a)) if a.starts_with("@2 alarm")));
        let text = screen(&v);
        assert!(
            text.contains("done 34.02 mm") && text.contains("alarm"),
            "{text}"
        );
        // After every link ended the samples are no longer recorded.
        v.take(vec![sample(0, 40.0, "idle", 0.0)]);
        drop(v);
        assert_eq!(recorded, 2);
    }

    #[test]
    fn every_link_done_is_the_gaits_success_and_time_runs_out_only_while_running() {
        let mut record = |_: &GaitSample| {};
        let mut v = GaitView::new("t".into(), 2, 10.0, &mut record);
        v.take(vec![
            sample(0, 11.0, "bend", 1.0),
            sample(1, 11.0, "bend", 1.0),
        ]);
        assert!(v.timed_out());
        v.line("@1 event: done t=9.0 radius_mm=34.00");
        v.line("@2 event: done t=9.5 radius_mm=42.00");
        assert!(!v.timed_out());
        assert_eq!(v.outcome(), Some(Outcome::EveryLinkDone));
    }
}

//! The status bar (router, counts, pads, teleop, e-stop, robots with their
//! fleet safety layer off, and whether this TUI is attached or embedded,
//! as which operator), the bottom line
//! (key hints or the prompt), the error box under a bad command line, and
//! the e-stop banner.

use ratatui::buffer::Buffer;
use ratatui::layout::Rect;
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Clear, Paragraph, Widget};

use super::app::{App, Prompt, PromptError, RobotsView};
use super::theme::Theme;
use super::view::{LinkState, Security};

/// Top line.
#[derive(Debug)]
pub struct StatusBar<'a> {
    pub app: &'a App,
    pub theme: Theme,
}

impl Widget for StatusBar<'_> {
    fn render(self, area: Rect, buf: &mut Buffer) {
        let wide = wide_line(self.app, &self.theme);
        let line = if wide.width() <= usize::from(area.width) {
            wide
        } else {
            narrow_line(self.app, &self.theme)
        };
        Paragraph::new(line)
            .style(self.theme.bar())
            .render(area, buf);
    }
}

/// How this TUI reaches its station, and as whom: `attached gcs.sock as
/// alice` or `embedded as alice`; `short`, for a narrow bar, `alice@gcs.sock`
/// or `alice@embedded`.
pub fn session(app: &App, short: bool) -> String {
    // A replay has no station: where it is in the recording says more.
    if let Some(clock) = app.fleet.replay {
        return clock.label();
    }
    let at = app.session.attached.as_deref();
    let op = app.session.operator.as_str();
    match (short, at, op.is_empty()) {
        (false, Some(a), false) => format!("attached {a} as {op}"),
        (false, Some(a), true) => format!("attached {a}"),
        (false, None, false) => format!("embedded as {op}"),
        (false, None, true) | (true, None, true) => "embedded".into(),
        (true, Some(a), false) => format!("{op}@{a}"),
        (true, Some(a), true) => a.to_string(),
        (true, None, false) => format!("{op}@embedded"),
    }
}

/// The alarm for robots whose safety layer is off: ` SAFETY OFF robot_2 `
/// (two names at most, then a count), or nothing.
fn safety_alarm<'a>(app: &App, t: &Theme) -> Span<'a> {
    let off: Vec<&str> = app
        .fleet
        .robots
        .iter()
        .filter(|r| r.safety.is_some_and(|s| s.alarm))
        .map(|r| r.name.as_str())
        .collect();
    match off.len() {
        0 => Span::raw(""),
        1 | 2 => Span::styled(format!(" SAFETY OFF {} ", off.join(" ")), t.alarm()),
        n => Span::styled(format!(" SAFETY OFF {n} robots "), t.alarm()),
    }
}

/// The parts both bars share: e-stop (with the safety alarm), security,
/// refusals, teleop.
fn parts<'a>(app: &App, t: &Theme) -> (Vec<Span<'a>>, Span<'a>, Span<'a>, String) {
    let estop = vec![
        if app.fleet.estop {
            Span::styled(" E-STOP ENGAGED ", t.alarm())
        } else {
            Span::raw(" e-stop off ")
        },
        safety_alarm(app, t),
    ];
    // Unsigned on the network is an alarm; the loopback demo is said
    // plainly; refusals are counted.
    let security = match app.fleet.security {
        Security::Authenticated => Span::raw(""),
        Security::LoopbackOnly => Span::raw(" unsigned, loopback │"),
        Security::Unauthenticated => Span::styled(" UNAUTHENTICATED ", t.alarm()),
    };
    let rejected = if app.fleet.rejected > 0 {
        Span::styled(format!(" rejected {} ", app.fleet.rejected), t.warn())
    } else {
        Span::raw("")
    };
    let teleop = if app.manual.keys_on {
        format!("{} ON", app.manual.key_channel)
    } else {
        "key off".to_string()
    };
    (estop, security, rejected, teleop)
}

/// The status bar when the terminal is wide enough for all of it.
fn wide_line<'a>(app: &App, t: &Theme) -> Line<'a> {
    let count = |l: LinkState| app.fleet.robots.iter().filter(|r| r.link == l).count();
    let (estop, security, rejected, teleop) = parts(app, t);
    let mut spans = vec![
        Span::styled(" MECH ", t.title()),
        Span::raw(format!(
            "│ {} │ robots {} ({} ok {} stale {} lost) │ sel {} │ pads {} │ {} │",
            app.session.router_addr,
            app.fleet.robots.len(),
            count(LinkState::Connected),
            count(LinkState::Stale),
            count(LinkState::Lost),
            app.cards.selection.len(),
            app.pads().len(),
            teleop,
        )),
    ];
    spans.extend(estop);
    spans.extend([
        security,
        rejected,
        Span::raw(format!("│ {} │ ? help", session(app, false))),
    ]);
    Line::from(spans)
}

/// The status bar on a narrow terminal: the e-stop first, the session in
/// place of the router's address.
fn narrow_line<'a>(app: &App, t: &Theme) -> Line<'a> {
    let ok = app
        .fleet
        .robots
        .iter()
        .filter(|r| r.link == LinkState::Connected)
        .count();
    let (mut spans, security, rejected, teleop) = parts(app, t);
    spans.extend([
        security,
        rejected,
        Span::raw(format!(
            "│ {} │ {}/{} ok │ sel {} │ pads {} │ {} │ ? help",
            session(app, true),
            ok,
            app.fleet.robots.len(),
            app.cards.selection.len(),
            app.pads().len(),
            teleop,
        )),
    ]);
    Line::from(spans)
}

/// Bottom line: prompt when typing, otherwise key hints.
#[derive(Debug)]
pub struct BottomBar<'a> {
    pub app: &'a App,
    pub theme: Theme,
}

impl Widget for BottomBar<'_> {
    fn render(self, area: Rect, buf: &mut Buffer) {
        let t = self.theme;
        let line = match &self.app.prompt.open {
            Some(Prompt::Command(s)) => Line::from(vec![
                Span::raw(":"),
                Span::raw(s.as_str()),
                Span::styled(" ", t.selected()),
            ]),
            Some(Prompt::Waypoint(s)) => Line::from(vec![
                Span::styled("waypoint x,y[,t]: ", t.title()),
                Span::raw(s.as_str()),
                Span::styled(" ", t.selected()),
            ]),
            Some(Prompt::Filter(s)) => Line::from(vec![
                Span::raw("/"),
                Span::raw(s.as_str()),
                Span::styled(" ", t.selected()),
                Span::styled("  name, route or state │ Enter keep │ Esc clear", t.dim()),
            ]),
            None if self.app.waypoints.placing => Line::styled(
                "WAYPOINTS click map │ e type x,y │ ⌫ remove │ Del clear │ Enter send │ Esc done │ X E-STOP",
                t.dim(),
            ),
            None if self.app.manual.keys_on => Line::styled(
                "TELEOP key/0 arrows/WASD drive │ Q E strafe │ Space stop │ t off │ X E-STOP",
                t.warn(),
            ),
            None if self.app.screen.robots_view == RobotsView::Table => Line::styled(
                "v map │ ↑↓ select │ Space mark │ Enter detail │ / filter │ < > sort │ r reverse │ Tab panel │ ? help │ X E-STOP",
                t.dim(),
            ),
            None => Line::styled(
                "q quit │ ? help │ : cmd │ X E-STOP │ n/p select │ v table │ / filter │ f waypoints │ c cluster │ Tab panel │ t teleop │ +/- zoom │ 0 fit",
                t.dim(),
            ),
        };
        Paragraph::new(line).render(area, buf);
    }
}

/// Two lines above the bottom bar: the rejected line and a caret under the
/// mistake with the message.
#[derive(Debug)]
pub struct PromptErrorBox<'a> {
    pub error: &'a PromptError,
    pub theme: Theme,
}

impl Widget for PromptErrorBox<'_> {
    fn render(self, area: Rect, buf: &mut Buffer) {
        Clear.render(area, buf);
        let e = self.error;
        let col = e.column.unwrap_or(0).min(e.line.len());
        let caret_col = e.line.get(..col).map_or(col, |s| s.chars().count()) + 1;
        let lines = vec![
            Line::raw(format!(" {}", e.line)),
            Line::styled(
                format!("{}^ {}", " ".repeat(caret_col), e.message),
                self.theme.warn(),
            ),
        ];
        Paragraph::new(lines).render(area, buf);
    }
}

/// The e-stop banner, shown over the top of the map until released.
#[derive(Debug)]
pub struct EStopBanner {
    pub theme: Theme,
}

impl Widget for EStopBanner {
    fn render(self, area: Rect, buf: &mut Buffer) {
        Clear.render(area, buf);
        let block = Block::bordered().style(self.theme.alarm());
        Paragraph::new(Line::from(
            "E-STOP ENGAGED: every robot holds. Ctrl+R or :release to release",
        ))
        .centered()
        .style(self.theme.alarm())
        .block(block)
        .render(area, buf);
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ui::fixture;

    /// The status bar of `app` on a `width`-column terminal, as text.
    fn bar(app: &App, width: u16) -> String {
        let area = Rect::new(0, 0, width, 1);
        let mut buf = Buffer::empty(area);
        StatusBar {
            app,
            theme: Theme::new(true),
        }
        .render(area, &mut buf);
        (0..width).map(|x| buf[(x, 0)].symbol()).collect()
    }

    #[test]
    fn the_bar_says_attached_or_embedded_and_as_whom_at_any_width() {
        let mut app = fixture::app(6, 80, 24);
        app.session.operator = "alice".into();
        assert!(bar(&app, 200).contains("│ embedded as alice │ ? help"));
        assert!(bar(&app, 80).contains("│ alice@embedded │"));
        app.session.attached = Some("gcs.sock".into());
        let wide = bar(&app, 200);
        assert!(
            wide.contains("│ attached gcs.sock as alice │ ? help"),
            "{wide}"
        );
        assert!(wide.contains("127.0.0.1:7700"), "{wide}");
        let narrow = bar(&app, 80);
        assert!(narrow.contains("│ alice@gcs.sock │"), "{narrow}");
        assert!(
            narrow.trim_end().ends_with("? help"),
            "80 columns fit: {narrow}"
        );
        // Too narrow for the long form: the short one, not a cut-off line.
        let mid = bar(&app, 120);
        assert!(
            mid.contains("alice@gcs.sock") && mid.contains("? help"),
            "{mid}"
        );
        app.session.operator.clear();
        assert_eq!(session(&app, false), "attached gcs.sock");
        app.session.attached = None;
        assert_eq!(session(&app, true), "embedded");
    }
}

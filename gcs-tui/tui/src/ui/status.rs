//! The status bar (router, counts, pads, teleop, e-stop), the bottom line
//! (key hints or the prompt), the error box under a bad command line, and
//! the e-stop banner.

use ratatui::buffer::Buffer;
use ratatui::layout::Rect;
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Clear, Paragraph, Widget};

use super::app::{App, Prompt, PromptError};
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
        let app = self.app;
        let t = self.theme;
        let count = |l: LinkState| app.robots.iter().filter(|r| r.link == l).count();
        let estop = if app.estop {
            Span::styled(" E-STOP ENGAGED ", t.alarm())
        } else {
            Span::raw(" e-stop off ")
        };
        // Unsigned on the network is an alarm; the loopback demo is said
        // plainly; refusals are counted.
        let security = match app.security {
            Security::Authenticated => Span::raw(""),
            Security::LoopbackOnly => Span::raw(" unsigned, loopback │"),
            Security::Unauthenticated => Span::styled(" UNAUTHENTICATED ", t.alarm()),
        };
        let rejected = if app.rejected > 0 {
            Span::styled(format!(" rejected {} ", app.rejected), t.warn())
        } else {
            Span::raw("")
        };
        let pads = app.pads();
        let teleop = if app.key_teleop_on {
            format!("{} ON", app.key_channel)
        } else {
            "key off".to_string()
        };
        // A replay shows where it is instead of a router.
        let source = app
            .replay
            .map_or_else(|| app.router_addr.clone(), |c| c.label());
        let line = if area.width >= 110 {
            Line::from(vec![
                Span::styled(" MECH ", t.title()),
                Span::raw(format!(
                    "│ {} │ robots {} ({} ok {} stale {} lost) │ sel {} │ pads {} │ {} │",
                    source,
                    app.robots.len(),
                    count(LinkState::Connected),
                    count(LinkState::Stale),
                    count(LinkState::Lost),
                    app.selection.len(),
                    pads.len(),
                    teleop,
                )),
                estop,
                security,
                rejected,
                Span::raw("│ ? help"),
            ])
        } else {
            Line::from(vec![
                estop,
                security,
                rejected,
                Span::raw(format!(
                    "│ {} │ {}/{} ok │ sel {} │ pads {} │ {} │ ? help",
                    source,
                    count(LinkState::Connected),
                    app.robots.len(),
                    app.selection.len(),
                    pads.len(),
                    teleop,
                )),
            ])
        };
        Paragraph::new(line).style(t.bar()).render(area, buf);
    }
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
        let line = match &self.app.prompt {
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
            None if self.app.waypoint_mode => Line::styled(
                "WAYPOINTS click map │ e type x,y │ ⌫ remove │ Del clear │ Enter send │ Esc done │ X E-STOP",
                t.dim(),
            ),
            None if self.app.key_teleop_on => Line::styled(
                "TELEOP key/0 arrows/WASD drive │ Q E strafe │ Space stop │ t off │ X E-STOP",
                t.warn(),
            ),
            None => Line::styled(
                "q quit │ ? help │ : cmd │ X E-STOP │ n/p select │ f waypoints │ c cluster │ Tab panel │ t teleop │ +/- zoom │ 0 fit",
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

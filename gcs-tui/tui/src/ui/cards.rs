//! Robot cards: one three-line card per robot with identity, pose, speed,
//! heading, mode, route, computation, link, failsafe, battery and mission.

use ratatui::buffer::Buffer;
use ratatui::layout::Rect;
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Paragraph, Widget};

use super::app::{App, Focus};
use super::layout::CARD_HEIGHT;
use super::theme::Theme;
use super::view::{LinkState, RobotView, failsafe_str, health_str, link_label, mode_str};
use mech_proto::{Computation, FailsafeState, Health};

/// The cards panel.
#[derive(Debug)]
pub struct CardsPanel<'a> {
    pub app: &'a App,
    pub theme: Theme,
}

impl Widget for CardsPanel<'_> {
    fn render(self, area: Rect, buf: &mut Buffer) {
        let app = self.app;
        let t = self.theme;
        let border = if app.focus == Focus::Cards {
            t.focused_border()
        } else {
            ratatui::style::Style::new()
        };
        let title = format!(
            " Robots {}/{} ",
            app.robots
                .iter()
                .filter(|r| r.link == LinkState::Connected)
                .count(),
            app.robots.len()
        );
        let block = Block::bordered().title(title).border_style(border);
        let inner = block.inner(area);
        block.render(area, buf);
        let visible = usize::from(inner.height) / CARD_HEIGHT;
        let mut lines: Vec<Line> = Vec::with_capacity(visible * CARD_HEIGHT);
        for (i, r) in app
            .robots
            .iter()
            .enumerate()
            .skip(app.cards_scroll)
            .take(visible)
        {
            card(r, i, app.selection.contains(&r.name), &t, &mut lines);
        }
        if app.robots.is_empty() {
            lines.push(Line::styled("no robots yet", t.dim()));
        }
        Paragraph::new(lines).render(inner, buf);
    }
}

fn link_style(l: LinkState, t: &Theme) -> ratatui::style::Style {
    match l {
        LinkState::Connected => t.ok(),
        LinkState::Stale => t.warn(),
        LinkState::Lost => t.alarm(),
    }
}

fn card<'a>(r: &'a RobotView, i: usize, selected: bool, t: &Theme, out: &mut Vec<Line<'a>>) {
    let colour = ratatui::style::Style::new().fg(t.robot(i));
    let name_style = if selected {
        colour.patch(t.selected())
    } else {
        colour.patch(t.title())
    };
    let marker = if selected { "▶" } else { "●" };
    out.push(Line::from(vec![
        Span::styled(marker, colour),
        Span::styled(r.name.as_str(), name_style),
        Span::raw(format!(" #{} ", r.id)),
        Span::styled(link_label(r.link), link_style(r.link, t)),
        Span::raw(format!(" {}", r.platform)),
        Span::styled(if r.remote.is_some() { " remote" } else { "" }, t.dim()),
    ]));
    out.push(Line::raw(format!(
        " x{:6.2} y{:6.2} z{:5.2} {:4.0}° {:.2}m/s",
        r.pose.x,
        r.pose.y,
        r.pose.z,
        r.heading_deg(),
        r.speed()
    )));
    let route = if r.route.channel.is_empty() {
        "none".to_string()
    } else if r.route.acknowledged {
        format!("{}✓", r.route.channel)
    } else {
        format!("{}…", r.route.channel)
    };
    let comp = match r.computation {
        Computation::Onboard => "on",
        Computation::Offboard => "off",
    };
    let fs_style = match r.failsafe {
        FailsafeState::Ok => t.ok(),
        FailsafeState::ChannelSilent => t.dim(),
        _ => t.alarm(),
    };
    let mut spans = vec![
        Span::raw(format!(" {} {} ", mode_str(r.mode), route)),
        Span::styled(failsafe_str(r.failsafe), fs_style),
    ];
    if r.health != Health::Ok {
        spans.push(Span::styled(format!(" {}", health_str(r.health)), t.warn()));
    }
    if let Some(m) = r.mission {
        if m.next >= m.total {
            spans.push(Span::styled(
                format!(" wp {}/{} arrived", m.total, m.total),
                t.ok(),
            ));
        } else {
            spans.push(Span::raw(format!(" wp {}/{}", m.next + 1, m.total)));
        }
    }
    if let Some(b) = r.battery {
        spans.push(Span::raw(format!(" {:.0}%", b * 100.0)));
    }
    spans.push(Span::raw(format!(" {comp}board")));
    out.push(Line::from(spans));
}

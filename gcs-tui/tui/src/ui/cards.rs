//! Robot cards: one four-line card per robot with identity (the alarm
//! `SAFETY OFF` when its fleet safety layer is off, and for a robot flown
//! by an autopilot whether it is armed and its flight mode), pose, speed
//! (measured or commanded), heading, mode, route, computation, link,
//! failsafe, what the safety layer limits (`fence`, `separation`...), the
//! fault text, battery, mission and the link's quality (rates each way,
//! loss, round trip). A robot the router no longer hears has its
//! telemetry's lines greyed, and its card says how old they are: what it
//! last said, not what it does.

use ratatui::buffer::Buffer;
use ratatui::layout::Rect;
use ratatui::text::{Line, Span};
use ratatui::widgets::{Block, Paragraph, Widget};

use super::app::{App, Focus};
use super::layout::CARD_HEIGHT;
use super::theme::Theme;
use super::view::{
    AutopilotState, LinkQuality, LinkState, RobotView, failsafe_str, health_str, intervention_str,
    link_label, mode_str, velocity_source_str,
};
use mech_proto::{Computation, FailsafeState, Health, Intervention};

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
        let border = if app.screen.focus == Focus::Cards {
            t.focused_border()
        } else {
            ratatui::style::Style::new()
        };
        let title = format!(
            " Robots {}/{} ",
            app.fleet
                .robots
                .iter()
                .filter(|r| r.link == LinkState::Connected)
                .count(),
            app.fleet.robots.len()
        );
        let block = Block::bordered().title(title).border_style(border);
        let inner = block.inner(area);
        block.render(area, buf);
        let visible = usize::from(inner.height) / CARD_HEIGHT;
        let mut lines: Vec<Line> = Vec::with_capacity(visible * CARD_HEIGHT);
        for (i, r) in app
            .fleet
            .robots
            .iter()
            .enumerate()
            .skip(app.cards.scroll)
            .take(visible)
        {
            card(r, i, app.cards.selection.contains(&r.name), &t, &mut lines);
        }
        if app.fleet.robots.is_empty() {
            lines.push(Line::styled("no robots yet", t.dim()));
        }
        Paragraph::new(lines).render(inner, buf);
    }
}

/// Height (m) from which a card shows a robot's `z`.
const AIRBORNE: f64 = 0.05;

/// How a link state is styled (ok, warn, alarm).
pub fn link_style(l: LinkState, t: &Theme) -> ratatui::style::Style {
    match l {
        LinkState::Connected => t.ok(),
        LinkState::Stale => t.warn(),
        LinkState::Lost => t.alarm(),
    }
}

/// How a loss figure is styled: a warning from 5 %, an alarm from 20 %
/// (the 2017 system had 12 % of its packets unusable at 40 Hz).
pub fn loss_style(q: &LinkQuality, t: &Theme) -> ratatui::style::Style {
    match q.loss {
        Some(l) if l >= 0.20 => t.alarm(),
        Some(l) if l >= 0.05 => t.warn(),
        _ => ratatui::style::Style::new(),
    }
}

/// The card's last line: ` rx 21/s tx 4/s loss 0.0% rtt 0.42ms`.
fn quality_line<'a>(q: &LinkQuality, t: &Theme) -> Line<'a> {
    if !q.measured() {
        return Line::styled(" link not measured yet", t.dim());
    }
    Line::from(vec![
        Span::raw(format!(" rx {:.0}/s tx {:.0}/s loss ", q.rx_hz, q.tx_hz)),
        Span::styled(q.loss_text(), loss_style(q, t)),
        Span::raw(format!(" rtt {}", q.rtt_text())),
    ])
}

/// One robot's card, [`CARD_HEIGHT`] lines; `i` is its place in the fleet
/// (its colour).
pub fn card<'a>(r: &'a RobotView, i: usize, selected: bool, t: &Theme, out: &mut Vec<Line<'a>>) {
    out.push(identity_line(r, i, selected, t));
    let (pose, state) = (pose_line(r), state_line(r, t));
    if r.stale_for.is_some() {
        out.push(greyed(pose, t));
        out.push(greyed(state, t));
    } else {
        out.push(pose);
        out.push(state);
    }
    out.push(quality_line(&r.quality, t));
}

/// A line of what telemetry said, greyed: the robot is not heard, so it
/// is history, not the robot's state now.
fn greyed<'a>(line: Line<'a>, t: &Theme) -> Line<'a> {
    Line::from(
        line.spans
            .into_iter()
            .map(|s| Span::styled(s.content, t.dim()))
            .collect::<Vec<_>>(),
    )
}

/// An autopilot's state as a card shows it: armed in the warning colour
/// (its propellers may spin), disarmed dim, lost as an alarm.
fn autopilot_span<'a>(a: &AutopilotState, t: &Theme) -> Span<'a> {
    let style = if a.lost {
        t.alarm()
    } else if a.armed == Some(true) {
        t.warn()
    } else {
        t.dim()
    };
    Span::styled(format!(" {}", a.label()), style)
}

/// The card's first line: `●robot_1 #1 Connected diff-drive` (`▶`
/// selected), with `SAFETY OFF` after the id while the robot's layer is
/// off (before anything the card may cut).
fn identity_line<'a>(r: &'a RobotView, i: usize, selected: bool, t: &Theme) -> Line<'a> {
    let colour = ratatui::style::Style::new().fg(t.robot(i));
    let name_style = if selected {
        colour.patch(t.selected())
    } else {
        colour.patch(t.title())
    };
    let marker = if selected { "▶" } else { "●" };
    let mut spans = vec![
        Span::styled(marker, colour),
        Span::styled(r.name.as_str(), name_style),
        // Another station's robot: its id is that station's router's.
        match r.remote {
            Some(_) => Span::styled(" remote ", t.dim()),
            None => Span::raw(format!(" #{} ", r.id)),
        },
        if r.safety.is_some_and(|s| s.alarm) {
            Span::styled("SAFETY OFF", t.alarm())
        } else {
            Span::raw("")
        },
        if r.safety.is_some_and(|s| s.alarm) {
            Span::raw(" ")
        } else {
            Span::raw("")
        },
        Span::styled(link_label(r.link), link_style(r.link, t)),
    ];
    if let Some(age) = r.stale_for {
        spans.push(Span::styled(
            format!(" {age:.0}s ago"),
            link_style(r.link, t),
        ));
    }
    spans.push(Span::raw(format!(" {}", r.platform)));
    if let Some(a) = &r.autopilot {
        spans.push(autopilot_span(a, t));
    }
    Line::from(spans)
}

/// The card's second line: ` x  1.00 y  2.00   90° 0.20m/s meas`, or
/// ` x 1.00 y 2.00   90° 0.20m/s meas ±5cm`
/// (how far the position may be off, as its safety layer reports it).
fn pose_line<'a>(r: &RobotView) -> Line<'a> {
    // Height only when airborne, so a ground robot's line has room for
    // whether its speed was measured.
    let z = if r.telemetry.pose.z.abs() >= AIRBORNE {
        format!(" z{:5.2}", r.telemetry.pose.z)
    } else {
        String::new()
    };
    let source = velocity_source_str(r.telemetry.velocity_source);
    let (x, y, heading, speed) = (
        r.telemetry.pose.x,
        r.telemetry.pose.y,
        r.heading_deg(),
        r.speed(),
    );
    match r.safety {
        // Narrower coordinates, so the card's width still holds the error.
        Some(s) if s.position_error > 0.0 => Line::raw(format!(
            " x{x:5.2} y{y:5.2}{z} {heading:4.0}° {speed:.2}m/s {source} ±{:.0}cm",
            s.position_error * 100.0
        )),
        _ => Line::raw(format!(
            " x{x:6.2} y{y:6.2}{z} {heading:4.0}° {speed:.2}m/s {source}"
        )),
    }
}

/// The card's third line: mode, route (✓ acknowledged, … pending),
/// failsafe, what the safety layer limits, a fault or the health, mission,
/// battery, where the loop runs and the links.
fn state_line<'a>(r: &RobotView, t: &Theme) -> Line<'a> {
    let route = if r.route.channel.is_empty() {
        "none".to_string()
    } else if r.route.acknowledged {
        format!("{}✓", r.route.channel)
    } else {
        format!("{}…", r.route.channel)
    };
    let fs_style = match r.telemetry.failsafe {
        FailsafeState::Ok => t.ok(),
        FailsafeState::ChannelSilent => t.dim(),
        _ => t.alarm(),
    };
    let mut spans = vec![
        Span::raw(format!(" {} {} ", mode_str(r.telemetry.mode), route)),
        Span::styled(failsafe_str(r.telemetry.failsafe), fs_style),
    ];
    if let Some(s) = r.safety.filter(|s| s.intervention != Intervention::None) {
        spans.push(Span::styled(
            format!(" {}", intervention_str(s.intervention)),
            t.warn(),
        ));
    }
    if let Some(fault) = &r.fault {
        spans.push(Span::styled(format!(" {fault}"), t.alarm()));
    } else if r.telemetry.health != Health::Ok {
        spans.push(Span::styled(
            format!(" {}", health_str(r.telemetry.health)),
            t.warn(),
        ));
    }
    if let Some(m) = r.telemetry.mission {
        if m.next >= m.total {
            spans.push(Span::styled(
                format!(" wp {}/{} arrived", m.total, m.total),
                t.ok(),
            ));
        } else {
            spans.push(Span::raw(format!(" wp {}/{}", m.next + 1, m.total)));
        }
    }
    if let Some(b) = r.telemetry.battery {
        spans.push(Span::raw(format!(" {:.0}%", b * 100.0)));
    }
    let comp = match r.telemetry.computation {
        Computation::Onboard => "on",
        Computation::Offboard => "off",
    };
    spans.push(Span::raw(format!(" {comp}board")));
    spans.push(Span::raw(if r.links.is_empty() {
        String::new()
    } else {
        format!(" {}", r.links)
    }));
    Line::from(spans)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ui::Action;
    use crate::ui::view::FleetSnapshot;
    use mech_proto::{Velocity, VelocitySource};

    /// The cards of `robots` on a 50-column panel, as text lines.
    fn cards(robots: Vec<RobotView>) -> Vec<String> {
        let mut app = App::new("127.0.0.1:7700", std::time::Instant::now());
        app.update(Action::Fleet(FleetSnapshot {
            robots,
            ..FleetSnapshot::default()
        }));
        let area = Rect::new(0, 0, 50, 10);
        let mut buf = Buffer::empty(area);
        CardsPanel {
            app: &app,
            theme: Theme::new(true),
        }
        .render(area, &mut buf);
        (0..area.height)
            .map(|y| {
                (0..area.width)
                    .map(|x| buf[(x, y)].symbol())
                    .collect::<String>()
            })
            .collect()
    }

    #[test]
    fn speed_says_measured_or_commanded_and_a_fault_its_text() {
        let mut rover = RobotView::at("a_rover", 1, "diff-drive", 1.0, 2.0, 0.0);
        rover.telemetry.velocity = Velocity {
            vx: 0.2,
            ..Velocity::default()
        };
        rover.telemetry.velocity_source = VelocitySource::Measured;
        rover.telemetry.failsafe = FailsafeState::Fault;
        rover.telemetry.health = Health::Fault;
        rover.fault = Some("left wheel stalled: driven at 60% for 0.50 s".into());
        let mut drone = RobotView::at("b_drone", 2, "quadcopter", 0.0, 0.0, 0.0);
        drone.telemetry.pose.z = 1.2;
        let lines = cards(vec![rover, drone]);
        assert!(lines[2].contains("0.20m/s meas"), "{lines:#?}");
        assert!(
            !lines[2].contains(" z"),
            "a ground robot's height is left out"
        );
        assert!(lines[3].contains("fault left wheel stalled"), "{lines:#?}");
        assert!(
            !lines[3].contains("FAULT"),
            "the text replaces the bare health"
        );
        assert!(lines[6].contains("z 1.20"), "{lines:#?}");
        assert!(lines[6].contains("0.00m/s cmd"), "{lines:#?}");
    }

    /// The style of the cell at column `x` of line `y`.
    fn style_at(robots: Vec<RobotView>, x: u16, y: u16) -> ratatui::style::Style {
        let mut app = App::new("127.0.0.1:7700", std::time::Instant::now());
        app.update(Action::Fleet(FleetSnapshot {
            robots,
            ..FleetSnapshot::default()
        }));
        let area = Rect::new(0, 0, 50, 10);
        let mut buf = Buffer::empty(area);
        CardsPanel {
            app: &app,
            theme: Theme::new(false),
        }
        .render(area, &mut buf);
        buf[(x, y)].style()
    }

    #[test]
    fn a_robot_not_heard_has_its_last_state_greyed_with_its_age() {
        let mut lost = RobotView::at("a_rover", 1, "diff-drive", 1.0, 2.0, 0.0);
        lost.telemetry.velocity.vx = 0.1;
        lost.link = LinkState::Lost;
        lost.stale_for = Some(3.2);
        let lines = cards(vec![lost.clone()]);
        assert!(lines[1].contains("Lost 3s ago diff-drive"), "{lines:#?}");
        assert!(lines[2].contains("0.10m/s"), "the last speed, {lines:#?}");
        let dim = Theme::new(false).dim();
        assert_eq!(style_at(vec![lost.clone()], 4, 2).fg, dim.fg, "greyed");
        assert_eq!(style_at(vec![lost.clone()], 4, 3).fg, dim.fg, "greyed");
        let mut heard = lost;
        heard.link = LinkState::Connected;
        heard.stale_for = None;
        assert!(!cards(vec![heard.clone()])[1].contains("ago"));
        assert_ne!(style_at(vec![heard], 4, 2).fg, dim.fg, "live");
    }

    #[test]
    fn an_autopilots_arming_and_mode_are_on_the_card() {
        let mut drone = RobotView::at("px4_1", 1, "quadcopter", 0.0, 0.0, 0.0);
        drone.autopilot = Some(AutopilotState {
            armed: Some(true),
            mode: Some("OFFBOARD".into()),
            lost: false,
        });
        let lines = cards(vec![drone]);
        assert!(
            lines[1].contains("Connected quadcopter armed OFFBOARD"),
            "{lines:#?}"
        );
    }
}

//! `status [TARGET]`: one line per robot (link, pose, speed, mode, route,
//! failsafe, its fleet safety layer (on, off: an alarm, or no arena), what
//! it limits now and how often it did, and the link's rates, loss and
//! round trip), for every robot in natural name order when no target is
//! given, after a summary that says whether the station authenticates,
//! what it refused, its arena and which robots have their safety off.

use mech_core::LinkQuality;
use mech_core::fleet::{Fleet, MissionDelivery, Robot};
use mech_proto::{Intervention, SafetyState};

use super::channel_name;
use crate::lang::args::{Args, Target};
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};

/// Report on the robots of `target`, or on every robot.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Status {
    pub target: Option<Target>,
}

impl Status {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<Status, LangError> {
        Ok(Status {
            target: if a.is_empty() {
                None
            } else {
                Some(a.target()?)
            },
        })
    }

    pub(super) async fn apply(&self, ctx: &mut Context, _at: Span) -> Result<Outcome, LangError> {
        let robots = match &self.target {
            Some(t) => ctx.resolve_shown(t)?,
            None => ctx.gcs.with_fleet(|f| {
                let mut names: Vec<String> = f.robots.keys().cloned().collect();
                names.sort_by(|a, b| mech_core::names::natural_cmp(a, b));
                names
            }),
        };
        let details = ctx.gcs.with_fleet(|f| {
            robots
                .iter()
                .filter_map(|r| f.robot(r))
                .map(status_line)
                .collect::<Vec<_>>()
        });
        let router = ctx.gcs.router();
        let rejected = router.rejections();
        let refused = if rejected.total() == 0 {
            String::new()
        } else {
            let by: Vec<String> = rejected
                .by_reason()
                .iter()
                .filter(|(_, n)| *n > 0)
                .map(|(reason, n)| format!("{n} {}", reason.as_str()))
                .collect();
            format!("; rejected {}", by.join(", "))
        };
        let recording = ctx
            .gcs
            .recording()
            .map(|r| format!("; {}", super::record::describe(&r)))
            .unwrap_or_default();
        let radios: String = router
            .radios()
            .iter()
            .map(|r| {
                format!(
                    "; radio {} {} frames {} replaced {} waiting",
                    r.port, r.frames, r.replaced, r.waiting
                )
            })
            .collect();
        Ok(Outcome {
            summary: format!(
                "{} robots; station {}{refused}{}{}{radios}{recording}",
                details.len(),
                router.security().label(),
                ctx.gcs.with_fleet(stations),
                ctx.gcs.with_fleet(arena),
            ),
            details,
        })
    }
}

/// The arena, and the robots whose safety layer is off (an alarm):
/// `; arena 4 vertices, ...; SAFETY OFF robot_2`.
fn arena(f: &Fleet) -> String {
    let mut s = match &f.arena {
        Some(a) => format!("; arena {}", a.summary()),
        None => "; no arena".to_string(),
    };
    let mut off: Vec<&str> = f
        .local_robots()
        .filter(|r| r.safety_alarm())
        .map(|r| r.name.as_str())
        .collect();
    off.sort_by(|a, b| mech_core::names::natural_cmp(a, b));
    if !off.is_empty() {
        s += &format!("; SAFETY OFF {}", off.join(", "));
    }
    s
}

/// Other stations seen through a bridge, with their state and how many of
/// their robots are shown: `; stations site-b connected (2 robots)`.
fn stations(f: &Fleet) -> String {
    if f.stations.is_empty() {
        return String::new();
    }
    let each: Vec<String> = f
        .stations
        .iter()
        .map(|(name, link)| {
            let n = f.robots_of(name).count();
            format!("{name} {} ({n} robots)", link.as_str())
        })
        .collect();
    format!("; stations {}", each.join(", "))
}

fn status_line(r: &Robot) -> String {
    format!(
        "{} #{} {} {} at ({:.2}, {:.2}) heading {:.2} speed {:.2} mode {:?} route {}{} failsafe {}",
        r.name,
        r.registration.id,
        r.registration.hello.platform,
        r.link.as_str(),
        r.telemetry.pose.x,
        r.telemetry.pose.y,
        r.telemetry.pose.heading,
        r.speed(),
        r.telemetry.mode,
        channel_name(&r.route.requested),
        if r.route.is_pending() {
            " (pending)"
        } else {
            ""
        },
        r.telemetry.failsafe.as_str(),
    ) + &if r.telemetry.stale > 0 {
        format!(" ignored-stale {}", r.telemetry.stale)
    } else {
        String::new()
    } + &safety(r)
        + &link_quality(&r.quality)
        + &links(r)
        + &lost_mission(r)
        + &remote(r)
}

/// ` safety on limiting fence interventions fence 2 separation 1`, or
/// ` safety OFF (alarm)`; nothing for a robot that reports no layer.
fn safety(r: &Robot) -> String {
    let Some(report) = r.telemetry.safety else {
        return if r.safety_enabled {
            String::new()
        } else {
            " safety OFF requested (alarm)".to_string()
        };
    };
    let mut s = match (report.state, r.safety_enabled) {
        (SafetyState::Off, _) => " safety OFF (alarm)".to_string(),
        (_, false) => " safety OFF requested (alarm)".to_string(),
        (SafetyState::On, true) => " safety on".to_string(),
        (SafetyState::NoArena, true) => " safety no-arena".to_string(),
    };
    if report.intervention != Intervention::None {
        s += &format!(" limiting {}", report.intervention.as_str());
    }
    let counts: Vec<String> = Intervention::ALL
        .iter()
        .filter(|i| report.counts.get(**i) > 0)
        .map(|i| format!("{} {}", i.as_str(), report.counts.get(*i)))
        .collect();
    if !counts.is_empty() {
        s += &format!(" interventions {}", counts.join(" "));
    }
    s
}

/// Another station's robot, shown here read-only.
fn remote(r: &Robot) -> String {
    match &r.remote {
        Some(station) => format!(" remote {station} (read-only)"),
        None => String::new(),
    }
}

/// ` link rx 21.0/s tx 4.0/s loss 0.0% rtt 0.42ms`, once measured.
fn link_quality(q: &LinkQuality) -> String {
    if !q.measured() {
        return String::new();
    }
    format!(
        " link rx {:.1}/s tx {:.1}/s loss {} rtt {}",
        q.rx_hz,
        q.tx_hz,
        q.loss_text(),
        q.rtt_text()
    )
}

/// A mission the robot lost (registered again without it: its agent
/// restarted), so the operator knows it will not resume by itself.
fn lost_mission(r: &Robot) -> String {
    match &r.waypoints.sent {
        Some(m) if m.delivery == MissionDelivery::Lost => {
            format!(" mission {} lost (agent restarted; send it again)", m.id)
        }
        _ => String::new(),
    }
}

/// The live links when the robot has a radio (`links wifi*+radio radio-budget 12 Hz`).
fn links(r: &Robot) -> String {
    match r.links.radio_budget_hz {
        Some(hz) => format!(" links {} radio-budget {hz} Hz", r.links.label()),
        None => String::new(),
    }
}

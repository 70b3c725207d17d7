//! `wait CONDITION [TIMEOUT]`: polls the fleet model until a condition
//! holds (robots connected, lost or arrived, a route acknowledged, robots
//! near a point or moved from where they were, the e-stop acknowledged,
//! robots' safety layer in a state) or the timeout passes.

use std::collections::BTreeMap;
use std::time::Duration;

use mech_core::LinkState;
use mech_core::fleet::{Fleet, MissionDelivery, Robot};
use mech_proto::SafetyState;

use super::expect::{parse_safety_state, safety_unmet};
use super::{WAIT_TIMEOUT, channel_name, poll_until};
use crate::lang::args::{Args, Target};
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};

/// Wait until `condition` holds, at most `timeout`.
#[derive(Debug, Clone, PartialEq)]
pub struct Wait {
    pub condition: WaitFor,
    pub timeout: Duration,
}

/// A condition `wait` polls for until it holds or its timeout passes.
#[derive(Debug, Clone, PartialEq)]
pub enum WaitFor {
    /// Every robot of the target is registered and connected.
    Connected(Target),
    /// Every robot of the target is lost.
    Lost(Target),
    /// At least this many robots are connected.
    Robots(usize),
    /// Every robot of the target finished its last mission.
    Arrived(Target),
    /// Every robot of the target acknowledged this route.
    Route(Target, Option<String>),
    /// Every robot of the target is within `tolerance` m of the point.
    Near {
        target: Target,
        x: f64,
        y: f64,
        tolerance: f64,
    },
    /// Every robot of the target is more than `metres` from where it was
    /// when the wait began: a controller, a mission or a gamepad drove it,
    /// however long they took to start.
    Moved { target: Target, metres: f64 },
    /// Every robot acknowledged the current e-stop or release.
    EStopAcked,
    /// Every robot of the target reports its safety layer in this state.
    Safety(Target, SafetyState),
}

impl Wait {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<Wait, LangError> {
        let what = a.next(
            "condition (connected, lost, robots, arrived, route, near, moved, estop, safety)",
        )?;
        let condition = match what.text.as_str() {
            "connected" => WaitFor::Connected(a.target()?),
            "lost" => WaitFor::Lost(a.target()?),
            "arrived" => WaitFor::Arrived(a.target()?),
            "robots" => WaitFor::Robots(a.count("number of robots")? as usize),
            "route" => {
                let target = a.target()?;
                WaitFor::Route(target, a.channel()?)
            }
            "near" => {
                let target = a.target()?;
                let (p, _) = a.point()?;
                let tolerance = a.number("tolerance in metres")?;
                WaitFor::Near {
                    target,
                    x: p.x,
                    y: p.y,
                    tolerance,
                }
            }
            "moved" => {
                let target = a.target()?;
                let metres = a.number("distance in metres")?;
                WaitFor::Moved { target, metres }
            }
            "estop" => WaitFor::EStopAcked,
            "safety" => {
                let target = a.target()?;
                WaitFor::Safety(target, parse_safety_state(a)?)
            }
            other => {
                return Err(LangError::new(
                    what.span,
                    format!(
                        "unknown wait condition {other:?}; use connected, lost, robots, arrived, route, near, moved, estop or safety"
                    ),
                ));
            }
        };
        Ok(Wait {
            condition,
            timeout: a.timeout(WAIT_TIMEOUT)?,
        })
    }

    pub(super) async fn apply(&self, ctx: &mut Context, at: Span) -> Result<Outcome, LangError> {
        let gcs = &ctx.gcs;
        let mut origins = BTreeMap::new();
        let ((), took) = poll_until(self.timeout, at, || {
            gcs.with_fleet(|f| {
                for (name, at) in self.condition.origins(f) {
                    origins.entry(name).or_insert(at);
                }
                match self.condition.unmet(f, &origins) {
                    None => Ok(()),
                    Some(reason) => Err(reason),
                }
            })
        })
        .await?;
        Ok(Outcome::new(format!("after {:.3} s", took.as_secs_f64())))
    }
}

impl WaitFor {
    /// Where each registered robot of a `moved` target is now: the wait
    /// keeps the first of these for each robot, so one that registers
    /// during the wait is measured from where it was first seen.
    fn origins(&self, f: &Fleet) -> BTreeMap<String, (f64, f64)> {
        let WaitFor::Moved { target, .. } = self else {
            return BTreeMap::new();
        };
        f.resolve(&target.name)
            .unwrap_or_else(|| vec![target.name.clone()])
            .into_iter()
            .filter_map(|name| {
                let p = f.robot(&name)?.telemetry.pose;
                Some((name, (p.x, p.y)))
            })
            .collect()
    }

    /// `None` if the condition holds, else why not; `origins` are where a
    /// `moved` target's robots were as the wait began.
    fn unmet(&self, f: &Fleet, origins: &BTreeMap<String, (f64, f64)>) -> Option<String> {
        // Waiting for a robot that has not registered yet is allowed.
        let each = |t: &Target, ok: &dyn Fn(&Robot) -> Option<String>| {
            let members = f.resolve(&t.name).unwrap_or_else(|| vec![t.name.clone()]);
            members.iter().find_map(|name| match f.robot(name) {
                None => Some(format!("{name} is not registered")),
                Some(r) => ok(r),
            })
        };
        match self {
            WaitFor::Connected(t) => each(t, &|r| {
                (r.link != LinkState::Connected)
                    .then(|| format!("{} is {}", r.name, r.link.as_str()))
            }),
            WaitFor::Lost(t) => each(t, &|r| {
                (r.link != LinkState::Lost).then(|| format!("{} is {}", r.name, r.link.as_str()))
            }),
            WaitFor::Robots(n) => {
                let c = f
                    .local_robots()
                    .filter(|r| r.link == LinkState::Connected)
                    .count();
                (c < *n).then(|| format!("{c} of {n} robots connected"))
            }
            WaitFor::Arrived(t) => each(t, &not_arrived),
            WaitFor::Route(t, channel) => each(t, &|r| {
                (r.route.is_pending() || r.route.acknowledged != *channel).then(|| {
                    format!(
                        "{} acknowledged {}, requested {}",
                        r.name,
                        channel_name(&r.route.acknowledged),
                        channel_name(&r.route.requested)
                    )
                })
            }),
            WaitFor::Near {
                target,
                x,
                y,
                tolerance,
            } => each(target, &|r| {
                let d = r.distance_to(*x, *y);
                (d > *tolerance).then(|| format!("{} is {d:.3} m from ({x}, {y})", r.name))
            }),
            WaitFor::Moved { target, metres } => each(target, &|r| {
                let Some(&(x, y)) = origins.get(&r.name) else {
                    return Some(format!("{} has no starting point", r.name));
                };
                let d = r.distance_to(x, y);
                (d <= *metres).then(|| format!("{} moved {d:.3} m of {metres} m", r.name))
            }),
            WaitFor::EStopAcked => (!f.estop.pending.is_empty()).then(|| {
                let pending: Vec<String> = f.estop.pending.iter().cloned().collect();
                format!("waiting for {}", pending.join(", "))
            }),
            WaitFor::Safety(t, state) => each(t, &|r| safety_unmet(&r.name, r, *state)),
        }
    }
}

/// `None` if `r` finished its last mission, else where it is.
fn not_arrived(r: &Robot) -> Option<String> {
    if r.arrived() {
        return None;
    }
    Some(match (&r.waypoints.sent, &r.telemetry.mission) {
        (None, _) => format!("{} has no mission", r.name),
        (Some(s), _) if s.delivery != MissionDelivery::Acked => {
            format!("{} mission {} is {:?}", r.name, s.id, s.delivery)
        }
        (Some(s), Some(p)) if p.id == s.id => {
            format!("{} at waypoint {} of {}", r.name, p.next, p.total)
        }
        (Some(_), _) => format!(
            "{} is not running the mission (route it to its channel)",
            r.name
        ),
    })
}

//! `expect CHECK`: a condition on the fleet model that must hold now (a
//! position, an acknowledged route, a link, failsafe or safety state, a
//! count of dropped commands); a script fails where one does not.

use mech_core::LinkState;
use mech_core::event::safety_state_str;
use mech_core::fleet::{Fleet, Robot};
use mech_proto::{FailsafeState, SafetyState};

use super::channel_name;
use crate::lang::args::{Args, Target, safety_state};
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};

/// A check that must hold now.
#[derive(Debug, Clone, PartialEq)]
pub enum Expectation {
    /// Within `tolerance` metres of `(x, y)`.
    Near {
        target: Target,
        x: f64,
        y: f64,
        tolerance: f64,
    },
    /// Acknowledged route.
    Route(Target, Option<String>),
    Link(Target, LinkState),
    Failsafe(Target, FailsafeState),
    /// The robot's fleet safety layer reports this state.
    Safety(Target, SafetyState),
    /// At least `min` commands on `channel` were dropped as not routed.
    DroppedAtLeast {
        channel: String,
        min: u64,
    },
}

impl Expectation {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<Expectation, LangError> {
        let what = a.next("check (near, route, link, failsafe, safety, dropped)")?;
        Ok(match what.text.as_str() {
            "near" => {
                let target = a.target()?;
                let (p, _) = a.point()?;
                let tolerance = a.number("tolerance in metres")?;
                Expectation::Near {
                    target,
                    x: p.x,
                    y: p.y,
                    tolerance,
                }
            }
            "route" => {
                let target = a.target()?;
                Expectation::Route(target, a.channel()?)
            }
            "link" => {
                let target = a.target()?;
                let state = a.named::<LinkState>()?;
                Expectation::Link(target, state)
            }
            "failsafe" => {
                let target = a.target()?;
                let state = a.named::<FailsafeState>()?;
                Expectation::Failsafe(target, state)
            }
            "safety" => {
                let target = a.target()?;
                Expectation::Safety(target, parse_safety_state(a)?)
            }
            "dropped" => {
                let channel = a
                    .channel()?
                    .ok_or_else(|| LangError::new(what.span, "`expect dropped` needs a channel"))?;
                Expectation::DroppedAtLeast {
                    channel,
                    min: a.count("minimum count")?,
                }
            }
            other => {
                return Err(LangError::new(
                    what.span,
                    format!(
                        "unknown check {other:?}; use near, route, link, failsafe, safety or dropped"
                    ),
                ));
            }
        })
    }

    pub(super) async fn apply(&self, ctx: &mut Context, _at: Span) -> Result<Outcome, LangError> {
        let f = ctx.gcs.snapshot();
        self.check(&f).map(Outcome::new)
    }

    /// What held, or an error at the target naming the first robot at fault.
    fn check(&self, f: &Fleet) -> Result<String, LangError> {
        match self {
            Expectation::Near {
                target,
                x,
                y,
                tolerance,
            } => {
                let mut worst = 0.0_f64;
                each(f, target, |name, r| {
                    let d = r.distance_to(*x, *y);
                    worst = worst.max(d);
                    (d > *tolerance).then(|| format!(
                        "{name} is {d:.3} m from ({x}, {y}), more than {tolerance} m (at {:.3}, {:.3})",
                        r.telemetry.pose.x, r.telemetry.pose.y
                    ))
                })?;
                Ok(format!("within {worst:.3} m"))
            }
            Expectation::Route(target, channel) => {
                each(f, target, |name, r| {
                    (r.route.is_pending() || r.route.acknowledged != *channel).then(|| {
                        format!(
                            "{name} acknowledged route {} (requested {}), expected {}",
                            channel_name(&r.route.acknowledged),
                            channel_name(&r.route.requested),
                            channel_name(channel)
                        )
                    })
                })?;
                Ok(format!("route {}", channel_name(channel)))
            }
            Expectation::Link(target, state) => {
                each(f, target, |name, r| {
                    (r.link != *state).then(|| {
                        format!("{name} is {}, expected {}", r.link.as_str(), state.as_str())
                    })
                })?;
                Ok(format!("link {}", state.as_str()))
            }
            Expectation::Failsafe(target, state) => {
                each(f, target, |name, r| {
                    (r.telemetry.failsafe != *state).then(|| {
                        format!(
                            "{name} failsafe is {}, expected {}",
                            r.telemetry.failsafe.as_str(),
                            state.as_str()
                        )
                    })
                })?;
                Ok(format!("failsafe {}", state.as_str()))
            }
            Expectation::Safety(target, state) => {
                each(f, target, |name, r| safety_unmet(name, r, *state))?;
                Ok(format!("safety {}", safety_state_str(*state)))
            }
            Expectation::DroppedAtLeast { channel, min } => dropped_at_least(f, channel, *min),
        }
    }
}

/// A safety state word (`on`, `off`, `no-arena`).
pub(super) fn parse_safety_state(a: &mut Args<'_>) -> Result<SafetyState, LangError> {
    let w = a.next("safety state")?;
    safety_state(&w.text).ok_or_else(|| {
        LangError::new(
            w.span,
            format!("unknown safety state {:?}; use on, off or no-arena", w.text),
        )
    })
}

/// Why `r` (named `name`) does not report its safety layer `state`, if it
/// does not.
pub(super) fn safety_unmet(name: &str, r: &Robot, state: SafetyState) -> Option<String> {
    match r.telemetry.safety {
        Some(s) if s.state == state => None,
        Some(s) => Some(format!(
            "{name} reports safety {}, expected {}",
            safety_state_str(s.state),
            safety_state_str(state)
        )),
        None => Some(format!("{name} reports no safety layer")),
    }
}

/// Runs `fails` on every registered robot of `target`; the first reason it
/// gives is an error at the target. A target that names nothing is one too.
fn each(
    f: &Fleet,
    target: &Target,
    mut fails: impl FnMut(&str, &Robot) -> Option<String>,
) -> Result<(), LangError> {
    let names = f.resolve(&target.name).ok_or_else(|| {
        LangError::new(
            target.span,
            format!("no robot or cluster named {:?}", target.name),
        )
    })?;
    for name in names {
        let Some(r) = f.robot(&name) else { continue };
        if let Some(reason) = fails(&name, r) {
            return Err(LangError::new(target.span, reason));
        }
    }
    Ok(())
}

fn dropped_at_least(f: &Fleet, channel: &str, min: u64) -> Result<String, LangError> {
    let n = f
        .counters
        .channels
        .get(channel)
        .map_or(0, |t| t.dropped.not_routed);
    if n < min {
        return Err(LangError::new(
            Span::default(),
            format!("{n} messages on {channel} dropped as not routed, expected at least {min}"),
        ));
    }
    Ok(format!("{n} dropped on {channel}"))
}

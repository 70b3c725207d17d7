//! `autopilot TARGET arm|disarm|offboard|hold|land|takeoff ALTITUDE`: the
//! operator's request to each robot's autopilot (PX4, ArduPilot). It is the
//! only way MECH arms, disarms or changes an autopilot's mode; each robot
//! reports what its autopilot did as a notice in the event log.

use mech_core::router::Delivery;
use mech_proto::{AutopilotAction, AutopilotRequest, Body};

use crate::lang::args::{Args, Target};
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};

/// Ask the autopilot of every robot of `target` to do `action`.
#[derive(Debug, Clone, PartialEq)]
pub struct Autopilot {
    pub target: Target,
    pub action: AutopilotAction,
    /// Metres above home, for `takeoff`.
    pub altitude: f64,
}

impl Autopilot {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<Autopilot, LangError> {
        let target = a.target()?;
        let w = a.next("action (arm, disarm, offboard, hold, land, takeoff)")?;
        let action = AutopilotAction::parse(&w.text).ok_or_else(|| {
            LangError::new(
                w.span,
                format!(
                    "unknown autopilot action {:?}; use arm, disarm, offboard, hold, land or takeoff ALTITUDE",
                    w.text
                ),
            )
        })?;
        let altitude = if action == AutopilotAction::Takeoff {
            let at = a.peek().map_or(a.end(), |w| w.span);
            let metres = a.number("altitude in metres")?;
            if !(metres > 0.0 && metres.is_finite()) {
                return Err(LangError::new(at, "the takeoff altitude must be positive"));
            }
            metres
        } else {
            0.0
        };
        Ok(Autopilot {
            target,
            action,
            altitude,
        })
    }

    pub(super) async fn apply(&self, ctx: &mut Context, at: Span) -> Result<Outcome, LangError> {
        let robots = ctx.resolve(&self.target)?;
        let mut sent = Vec::new();
        for r in &robots {
            let body = Body::Autopilot(AutopilotRequest {
                robot: r.clone(),
                action: self.action,
                altitude: self.altitude,
            });
            let delivery = ctx
                .publishers
                .on("")
                .send_body(r, body)
                .await
                .map_err(|e| LangError::new(at, e.to_string()))?;
            if delivery == Delivery::Forwarded(1) {
                sent.push(r.as_str());
            }
        }
        Ok(Outcome::new(format!(
            "autopilot {} sent to {} (each robot reports the result in the event log)",
            self.action.as_str(),
            if sent.is_empty() {
                "no robot".to_string()
            } else {
                sent.join(", ")
            }
        )))
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::lang::parse_line;
    use crate::lang::verbs::Command;

    fn parsed(line: &str) -> Autopilot {
        match parse_line(line).unwrap().unwrap().command {
            Command::Autopilot(a) => a,
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn actions_parse_and_takeoff_needs_a_height() {
        let arm = parsed("autopilot robot_1 arm");
        assert_eq!(
            (arm.target.name.as_str(), arm.action),
            ("robot_1", AutopilotAction::Arm)
        );
        assert_eq!(
            parsed("autopilot c1 offboard").action,
            AutopilotAction::Offboard
        );
        let up = parsed("autopilot drone takeoff 2.5");
        assert_eq!((up.action, up.altitude), (AutopilotAction::Takeoff, 2.5));
        let e = parse_line("autopilot drone takeoff").unwrap_err();
        assert!(e.message.contains("altitude"), "{}", e.message);
        let e = parse_line("autopilot drone takeoff -1").unwrap_err();
        assert!(e.message.contains("positive"), "{}", e.message);
        let e = parse_line("autopilot drone flip").unwrap_err();
        assert_eq!(e.span.column, 17);
        assert!(e.message.contains("unknown autopilot action"));
    }
}

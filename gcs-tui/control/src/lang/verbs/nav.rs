//! `nav ROBOT offboard|onboard|toggle`: moves a robot's waypoint navigation
//! between the station's offboard loop and the robot, keeping the mission's
//! progress; it routes the robot itself, since the switch must not lose a
//! waypoint.

use super::control_error;
use crate::lang::args::{Args, Target};
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};

mech_proto::named_enum! {
    /// Where navigation should run.
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    pub enum NavSide: "navigation side" {
        Onboard => "onboard",
        Offboard => "offboard",
        /// Whichever side it is not on now (the TUI's `o` key).
        Toggle => "toggle",
    }
}

/// Run `robot`'s navigation on `side`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Nav {
    pub robot: Target,
    pub side: NavSide,
}

impl Nav {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<Nav, LangError> {
        let robot = a.target()?;
        let side = a.named::<NavSide>()?;
        Ok(Nav { robot, side })
    }

    pub(super) async fn apply(&self, ctx: &mut Context, _at: Span) -> Result<Outcome, LangError> {
        let robot = &self.robot;
        match self.side {
            NavSide::Offboard => {
                let v = ctx
                    .control
                    .nav_offboard(&robot.name)
                    .await
                    .map_err(|e| control_error(robot, e))?;
                let latency = match v.switch_latency {
                    Some(d) => format!(
                        "first command forwarded {:.3} ms after the request",
                        d.as_secs_f64() * 1e3
                    ),
                    None => "no command forwarded yet (no fresh telemetry?)".to_string(),
                };
                Ok(Outcome::new(format!(
                    "{} offboard on {} from waypoint {} of {} (mission {}); {latency}",
                    robot.name, v.channel, v.progress.next, v.progress.total, v.progress.id
                )))
            }
            NavSide::Onboard => {
                let p = ctx
                    .control
                    .nav_onboard(&robot.name)
                    .await
                    .map_err(|e| control_error(robot, e))?;
                Ok(Outcome::new(format!(
                    "{} onboard: mission {} resumes at waypoint {} of {}",
                    robot.name, p.id, p.next, p.total
                )))
            }
            NavSide::Toggle => ctx
                .control
                .toggle_nav(&robot.name)
                .await
                .map(Outcome::new)
                .map_err(|e| control_error(robot, e)),
        }
    }
}

//! `mode TARGET MODE`: the control mode `drive` uses for these robots.

use mech_proto::CommandKind;

use crate::lang::args::{Args, Target};
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};

/// Set the mode `drive` sends in; every robot of `target` must obey it, or
/// none is changed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Mode {
    pub target: Target,
    pub mode: CommandKind,
}

impl Mode {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<Mode, LangError> {
        let target = a.target()?;
        let w = a.next("mode")?;
        let mode = CommandKind::parse(&w.text).filter(|k| *k != CommandKind::Waypoints).ok_or_else(|| {
            LangError::new(
                w.span,
                format!("unknown mode {:?}; modes are actuators, steering-throttle, velocity-heading, twist, stop (waypoints: use `waypoint` and `send`)", w.text),
            )
        })?;
        Ok(Mode { target, mode })
    }

    pub(super) async fn apply(&self, ctx: &mut Context, _at: Span) -> Result<Outcome, LangError> {
        let robots = ctx.resolve(&self.target)?;
        let (target, mode) = (&self.target, self.mode);
        ctx.gcs.update_fleet(|f| {
            for r in &robots {
                let robot = f
                    .robot(r)
                    .ok_or_else(|| LangError::new(target.span, format!("no robot {r}")))?;
                if !robot.can(mode) {
                    return Err(LangError::new(
                        target.span,
                        format!(
                            "{r} ({}) cannot obey {mode} commands",
                            robot.registration.hello.platform
                        ),
                    ));
                }
            }
            for r in &robots {
                if let Some(robot) = f.robot_mut(r) {
                    robot.gcs_mode = Some(mode);
                }
            }
            Ok(())
        })?;
        Ok(Outcome::new(format!(
            "{} drive mode {mode}",
            robots.join(", ")
        )))
    }
}

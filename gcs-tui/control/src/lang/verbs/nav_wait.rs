//! `nav-wait ROBOT NEXT [TIMEOUT]`: polls until a robot's next waypoint
//! index reaches NEXT, whether the offboard loop or the robot itself is
//! navigating.

use std::time::Duration;

use super::{CONTROL_WAIT_TIMEOUT, poll_until};
use crate::lang::args::{Args, Target};
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};

/// Wait until `robot`'s next waypoint index is at least `next`, at most
/// `timeout`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct NavWait {
    pub robot: Target,
    pub next: u32,
    pub timeout: Duration,
}

impl NavWait {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<NavWait, LangError> {
        let robot = a.target()?;
        let next = a.count("next waypoint index")?;
        Ok(NavWait {
            robot,
            next: u32::try_from(next).unwrap_or(u32::MAX),
            timeout: a.timeout(CONTROL_WAIT_TIMEOUT)?,
        })
    }

    pub(super) async fn apply(&self, ctx: &mut Context, at: Span) -> Result<Outcome, LangError> {
        let name = &self.robot.name;
        // Not `ctx` itself: the wait must stay `Send`, and the spawner in
        // `ctx` is not `Sync`.
        let (hub, gcs) = (&ctx.control, &ctx.gcs);
        let ((next, side), took) = poll_until(self.timeout, at, || {
            let offboard = hub.nav_view(name).map(|v| v.progress.next);
            let onboard = gcs.with_fleet(|f| {
                f.robot(name)
                    .and_then(|r| r.telemetry.mission)
                    .map(|m| m.next)
            });
            let now = offboard.or(onboard);
            let side = if offboard.is_some() {
                "offboard"
            } else {
                "onboard"
            };
            now.filter(|n| *n >= self.next)
                .map(|n| (n, side))
                .ok_or_else(|| format!("{name} next waypoint is {now:?}"))
        })
        .await?;
        Ok(Outcome::new(format!(
            "{name} next waypoint {next} ({side}) after {:.2} s",
            took.as_secs_f64()
        )))
    }
}

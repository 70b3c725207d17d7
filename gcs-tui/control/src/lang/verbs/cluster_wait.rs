//! `cluster-wait CLUSTER [TIMEOUT]` / `cluster-wait CLUSTER settled
//! TOLERANCE [TIMEOUT]`: polls the cluster controller until the cluster has
//! done its waypoints, or until every member is routed to it, reporting,
//! and close to its slot.

use std::time::Duration;

use super::{CONTROL_WAIT_TIMEOUT, poll_until};
use crate::hub::ControlHub;
use crate::lang::args::{Args, Target};
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};

/// Wait until `cluster` is `until`, at most `timeout`.
#[derive(Debug, Clone, PartialEq)]
pub struct ClusterWait {
    pub cluster: Target,
    pub until: ClusterUntil,
    pub timeout: Duration,
}

/// What `cluster-wait` waits for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ClusterUntil {
    /// The waypoints sent last are done.
    Arrived,
    /// Every commanded member is within this distance (m) of its slot.
    Settled(f64),
}

impl ClusterWait {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<ClusterWait, LangError> {
        let cluster = a.target()?;
        let until = if a.keyword("settled") {
            ClusterUntil::Settled(a.number("slot error tolerance (m)")?)
        } else {
            ClusterUntil::Arrived
        };
        Ok(ClusterWait {
            cluster,
            until,
            timeout: a.timeout(CONTROL_WAIT_TIMEOUT)?,
        })
    }

    pub(super) async fn apply(&self, ctx: &mut Context, at: Span) -> Result<Outcome, LangError> {
        // The hub, not `ctx`: the wait must stay `Send`, and the spawner in
        // `ctx` is not `Sync`.
        match self.until {
            ClusterUntil::Settled(tolerance) => self.settled(&ctx.control, tolerance, at).await,
            ClusterUntil::Arrived => self.arrived(&ctx.control, at).await,
        }
    }

    async fn settled(
        &self,
        hub: &ControlHub,
        tolerance: f64,
        at: Span,
    ) -> Result<Outcome, LangError> {
        let name = &self.cluster.name;
        let (worst, took) = poll_until(self.timeout, at, || {
            // Settled means every member routed here and reporting.
            let worst = hub
                .cluster_view(name)
                .filter(|v| {
                    !v.status.slots.is_empty()
                        && v.status.absent.is_empty()
                        && v.status.lost.is_empty()
                })
                .map(|v| v.status.max_error());
            worst
                .filter(|w| *w <= tolerance)
                .ok_or_else(|| format!("{name} largest slot error {worst:?} m"))
        })
        .await?;
        Ok(Outcome::new(format!(
            "{name} settled after {:.2} s: every slot error <= {worst:.3} m",
            took.as_secs_f64()
        )))
    }

    async fn arrived(&self, hub: &ControlHub, at: Span) -> Result<Outcome, LangError> {
        let name = &self.cluster.name;
        let (stats, took) = poll_until(self.timeout, at, || {
            let view = hub.cluster_view(name);
            match view {
                Some(v) if v.finished => Ok(v.stats),
                _ => Err(match view.and_then(|v| v.status.waypoint) {
                    Some((next, total)) => format!("{name} at waypoint {next} of {total}"),
                    None => format!("{name} no waypoints running"),
                }),
            }
        })
        .await?;
        Ok(Outcome::new(format!(
            "{name} finished its waypoints after {:.2} s; slot error max {:.3} m, RMS {:.3} m",
            took.as_secs_f64(),
            stats.max,
            stats.rms()
        )))
    }
}

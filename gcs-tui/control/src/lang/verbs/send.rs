//! `send TARGET [CHANNEL]`: sends each robot's waypoint draft as a mission,
//! or, for a cluster with a `cluster-waypoint` draft and no channel, starts
//! the cluster's waypoints. A robot runs a mission only while routed to its
//! channel: for those routed elsewhere the outcome says so, with the
//! command that routes them.

use crate::lang::args::{Args, Target};
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};

/// Send the drafts of `target` on `channel` (default: the configured
/// mission channel).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct SendWaypoints {
    pub target: Target,
    pub channel: Option<String>,
}

impl SendWaypoints {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<SendWaypoints, LangError> {
        let target = a.target()?;
        let channel = if a.is_empty() { None } else { a.channel()? };
        Ok(SendWaypoints { target, channel })
    }

    pub(super) async fn apply(&self, ctx: &mut Context, _at: Span) -> Result<Outcome, LangError> {
        let target = &self.target;
        if self.channel.is_none() && ctx.control.has_cluster_draft(&target.name) {
            let n = ctx
                .control
                .send_cluster(&target.name)
                .map_err(|e| LangError::new(target.span, e.to_string()))?;
            return Ok(Outcome::new(format!(
                "{}: {n} cluster waypoints started",
                target.name
            )));
        }
        let robots = ctx.resolve(target)?;
        let channel = self
            .channel
            .clone()
            .unwrap_or_else(|| ctx.gcs.config().fleet.mission_channel.clone());
        let mut ids = Vec::new();
        let mut hints = Vec::new();
        for r in &robots {
            let draft = ctx.gcs.with_fleet(|f| {
                f.robot(r)
                    .map(|x| (x.waypoints.draft.clone(), x.waypoints.looped))
            });
            let Some((waypoints, looped)) = draft.filter(|(w, _)| !w.is_empty()) else {
                return Err(LangError::new(
                    target.span,
                    format!("{r} has no waypoints; set them with `waypoint {r} X,Y ...`"),
                ));
            };
            let id = ctx
                .gcs
                .send_waypoints(&ctx.sender, r, &channel, waypoints, looped)
                .await
                .map_err(|e| LangError::new(target.span, e.to_string()))?;
            ids.push(format!("{r}: mission {id}"));
            let routed = ctx
                .gcs
                .with_fleet(|f| f.robot(r).and_then(|x| x.route.requested.clone()));
            if routed.as_deref() != Some(channel.as_str()) {
                hints.push(format!(
                    "{r} is routed to {}: it runs the mission once routed to {channel} \
                     (route {r} {channel})",
                    routed.as_deref().unwrap_or("none")
                ));
            }
        }
        let mut outcome = Outcome::new(format!("sent on {channel}: {}", ids.join(", ")));
        outcome.details = hints;
        Ok(outcome)
    }
}

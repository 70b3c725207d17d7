//! `cluster-move CLUSTER VX VY WZ [SCALE_RATE]`: drives a cluster at a
//! cluster-frame velocity (its members must be routed to `fleet/CLUSTER`).

use mech_proto::ClusterVelocity;

use super::control_error;
use crate::hub::cluster_channel;
use crate::lang::args::{Args, Target};
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};

/// Move `cluster` at `velocity` (m/s, rad/s and 1/s, cluster frame) until
/// told otherwise.
#[derive(Debug, Clone, PartialEq)]
pub struct ClusterMove {
    pub cluster: Target,
    pub velocity: ClusterVelocity,
}

impl ClusterMove {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<ClusterMove, LangError> {
        let cluster = a.target()?;
        let vx = a.number("vx (m/s, cluster frame)")?;
        let vy = a.number("vy (m/s, cluster frame)")?;
        let wz = a.number("wz (rad/s)")?;
        let scale_rate = if a.is_empty() {
            0.0
        } else {
            a.number("scale rate (1/s)")?
        };
        Ok(ClusterMove {
            cluster,
            velocity: ClusterVelocity {
                vx,
                vy,
                wz,
                scale_rate,
            },
        })
    }

    pub(super) async fn apply(&self, ctx: &mut Context, _at: Span) -> Result<Outcome, LangError> {
        let (cluster, v) = (&self.cluster, self.velocity);
        ctx.control
            .cluster_move(&cluster.name, v)
            .map_err(|e| control_error(cluster, e))?;
        Ok(Outcome::new(format!(
            "{} moving at vx {} vy {} m/s, wz {} rad/s, scale rate {} /s (cluster frame) on {}",
            cluster.name,
            v.vx,
            v.vy,
            v.wz,
            v.scale_rate,
            cluster_channel(&cluster.name)
        )))
    }
}

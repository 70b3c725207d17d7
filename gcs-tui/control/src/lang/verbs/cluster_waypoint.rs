//! `cluster-waypoint CLUSTER X,Y[,HEADING]... [loop]`: sets a cluster's
//! waypoint draft; `send CLUSTER` starts it.

use super::control_error;
use crate::cluster::ClusterWaypoint;
use crate::lang::args::{Args, Target};
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};
use crate::spec::parse_cluster_waypoint;

/// Replace the waypoint draft of `cluster` (headings in rad).
#[derive(Debug, Clone, PartialEq)]
pub struct SetClusterWaypoints {
    pub cluster: Target,
    pub waypoints: Vec<ClusterWaypoint>,
    pub looped: bool,
}

impl SetClusterWaypoints {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<SetClusterWaypoints, LangError> {
        let cluster = a.target()?;
        let mut waypoints = Vec::new();
        let mut looped = false;
        loop {
            if a.keyword("loop") {
                looped = true;
                break;
            }
            if a.is_empty() && !waypoints.is_empty() {
                break;
            }
            let w = a.next("cluster waypoint x,y[,heading]")?;
            waypoints.push(
                parse_cluster_waypoint(&w.text)
                    .map_err(|e| LangError::new(w.span, e.to_string()))?,
            );
        }
        if waypoints.is_empty() {
            a.next("cluster waypoint x,y[,heading]")?;
        }
        Ok(SetClusterWaypoints {
            cluster,
            waypoints,
            looped,
        })
    }

    pub(super) async fn apply(&self, ctx: &mut Context, _at: Span) -> Result<Outcome, LangError> {
        let cluster = &self.cluster;
        ctx.control
            .set_cluster_waypoints(&cluster.name, self.waypoints.clone(), self.looped)
            .map_err(|e| control_error(cluster, e))?;
        let l = if self.looped { ", looped" } else { "" };
        Ok(Outcome::new(format!(
            "{} cluster waypoints for {}{l}; start with `send {}`",
            self.waypoints.len(),
            cluster.name,
            cluster.name
        )))
    }
}

//! `cluster-status CLUSTER`: the cluster's pose (desired and measured), its
//! motion, and one line per slot with the member's tracking error.

use mech_proto::ClusterPose;

use super::cluster_view;
use crate::cluster::ClusterMotion;
use crate::hub::ClusterView;
use crate::lang::args::{Args, Target};
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};

/// Report on `cluster`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ClusterStatus {
    pub cluster: Target,
}

impl ClusterStatus {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<ClusterStatus, LangError> {
        Ok(ClusterStatus {
            cluster: a.target()?,
        })
    }

    pub(super) async fn apply(&self, ctx: &mut Context, _at: Span) -> Result<Outcome, LangError> {
        let v = cluster_view(ctx, &self.cluster)?;
        Ok(report(&self.cluster.name, &v))
    }
}

/// One summary line, then one line per slot, lost member and absent member.
fn report(name: &str, v: &ClusterView) -> Outcome {
    let st = &v.status;
    let mut details: Vec<String> = st
        .slots
        .iter()
        .map(|s| {
            format!(
                "{} slot {} at ({:.2}, {:.2}) error {:.3} m",
                s.robot, s.slot, s.x, s.y, s.error
            )
        })
        .collect();
    for r in &st.lost {
        details.push(format!("{r} lost (stale telemetry): not commanded"));
    }
    for r in &st.absent {
        details.push(format!("{r} not routed to {}", v.channel));
    }
    Outcome {
        summary: format!(
            "{name} {} {}: desired {}, measured {}; {}; slot error max {:.3} m, RMS {:.3} m since sent",
            st.formation.kind.as_str(),
            v.channel,
            pose(st.desired),
            pose(st.measured),
            motion(&v.motion),
            v.stats.max,
            v.stats.rms()
        ),
        details,
    }
}

fn pose(p: Option<ClusterPose>) -> String {
    match p {
        Some(p) => format!(
            "({:.2}, {:.2}) heading {:.2} rad scale {:.2}",
            p.x, p.y, p.heading, p.scale
        ),
        None => "unknown".to_string(),
    }
}

fn motion(m: &ClusterMotion) -> String {
    match m {
        ClusterMotion::Hold => "holding".to_string(),
        ClusterMotion::Velocity(c) => format!(
            "moving vx {} vy {} wz {} scale rate {}",
            c.vx, c.vy, c.wz, c.scale_rate
        ),
        ClusterMotion::Waypoints { list, next, .. } => {
            format!("waypoint {next} of {}", list.len())
        }
    }
}

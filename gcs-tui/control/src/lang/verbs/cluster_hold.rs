//! `cluster-hold CLUSTER`: stops a cluster where it is.

use super::control_error;
use crate::lang::args::{Args, Target};
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};

/// Hold `cluster` at its current pose.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ClusterHold {
    pub cluster: Target,
}

impl ClusterHold {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<ClusterHold, LangError> {
        Ok(ClusterHold {
            cluster: a.target()?,
        })
    }

    pub(super) async fn apply(&self, ctx: &mut Context, _at: Span) -> Result<Outcome, LangError> {
        ctx.control
            .hold_cluster(&self.cluster.name)
            .map_err(|e| control_error(&self.cluster, e))?;
        Ok(Outcome::new(format!("{} holding", self.cluster.name)))
    }
}

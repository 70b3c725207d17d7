//! `cluster-expect CLUSTER max-error|rms-error METRES`: checks a cluster's
//! slot tracking error since its waypoints were sent.

use super::cluster_view;
use crate::lang::args::{Args, Target};
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};

mech_proto::named_enum! {
    /// Which tracking statistic `cluster-expect` checks.
    #[derive(Debug, Clone, Copy, PartialEq, Eq)]
    pub enum ErrorMetric: "error metric" {
        Max => "max-error",
        Rms => "rms-error",
    }
}

/// `metric` of `cluster`'s slot error must be at most `limit` metres, over
/// at least one sample.
#[derive(Debug, Clone, PartialEq)]
pub struct ClusterExpect {
    pub cluster: Target,
    pub metric: ErrorMetric,
    pub limit: f64,
}

impl ClusterExpect {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<ClusterExpect, LangError> {
        let cluster = a.target()?;
        let metric = a.named::<ErrorMetric>()?;
        let limit = a.number("error limit (m)")?;
        Ok(ClusterExpect {
            cluster,
            metric,
            limit,
        })
    }

    pub(super) async fn apply(&self, ctx: &mut Context, at: Span) -> Result<Outcome, LangError> {
        let v = cluster_view(ctx, &self.cluster)?;
        let (name, value) = match self.metric {
            ErrorMetric::Max => ("max", v.stats.max),
            ErrorMetric::Rms => ("RMS", v.stats.rms()),
        };
        let text = format!(
            "{} slot error {name} {value:.3} m over {} samples (limit {} m)",
            self.cluster.name, v.stats.samples, self.limit
        );
        if v.stats.samples > 0 && value <= self.limit {
            Ok(Outcome::new(text))
        } else {
            Err(LangError::new(at, format!("expectation failed: {text}")))
        }
    }
}

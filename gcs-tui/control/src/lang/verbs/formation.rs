//! `formation CLUSTER KIND [SPACING]` / `formation CLUSTER custom X,Y...`:
//! sets a cluster's formation; the cluster controller re-assigns slots to
//! minimise travel.

use mech_proto::{Formation, FormationKind};

use super::control_error;
use crate::lang::args::{Args, Target};
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};
use crate::spec::parse_formation;

/// Give `cluster` this formation.
#[derive(Debug, Clone, PartialEq)]
pub struct SetFormation {
    pub cluster: Target,
    pub formation: Formation,
}

impl SetFormation {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<SetFormation, LangError> {
        let cluster = a.target()?;
        let first = a.next("formation (line, column, wedge, circle, custom)")?;
        let mut words = vec![first];
        while !a.is_empty() {
            words.push(a.next("formation argument")?);
        }
        let texts: Vec<&str> = words.iter().map(|w| w.text.as_str()).collect();
        let formation =
            parse_formation(&texts).map_err(|e| LangError::new(first.span, e.to_string()))?;
        Ok(SetFormation { cluster, formation })
    }

    pub(super) async fn apply(&self, ctx: &mut Context, _at: Span) -> Result<Outcome, LangError> {
        let (cluster, formation) = (&self.cluster, &self.formation);
        ctx.control
            .set_formation(&cluster.name, formation.clone())
            .map_err(|e| control_error(cluster, e))?;
        let shape = match formation.kind {
            FormationKind::Custom => format!("custom, {} offsets", formation.offsets.len()),
            k => format!("{}, spacing {} m", k.as_str(), formation.spacing),
        };
        Ok(Outcome::new(format!("{}: formation {shape}", cluster.name)))
    }
}

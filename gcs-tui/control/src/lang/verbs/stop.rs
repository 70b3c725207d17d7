//! `stop TARGET`: a controlled, unlatched stop published on each robot's
//! current channel, so the robot holds still until that channel's next
//! command.

use mech_core::router::Delivery;
use mech_proto::Command as Cmd;

use crate::lang::args::{Args, Target};
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};

/// Stop every robot of `target` that is routed to a channel.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Stop {
    pub target: Target,
}

impl Stop {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<Stop, LangError> {
        Ok(Stop {
            target: a.target()?,
        })
    }

    pub(super) async fn apply(&self, ctx: &mut Context, at: Span) -> Result<Outcome, LangError> {
        let robots = ctx.resolve(&self.target)?;
        let mut stopped = Vec::new();
        for r in &robots {
            let channel = ctx
                .gcs
                .with_fleet(|f| f.robot(r).and_then(|x| x.route.requested.clone()));
            let Some(channel) = channel else { continue };
            let delivery = ctx
                .publishers
                .on(&channel)
                .send(r, Cmd::Stop(mech_proto::Stop {}))
                .await
                .map_err(|e| LangError::new(at, e.to_string()))?;
            if delivery == Delivery::Forwarded(1) {
                stopped.push(r.clone());
            }
        }
        Ok(Outcome::new(format!(
            "stop sent to {} of {} robots (robots routed to none already hold still)",
            stopped.len(),
            robots.len()
        )))
    }
}

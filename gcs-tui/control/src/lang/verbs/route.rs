//! `route TARGET CHANNEL|none`: puts robots on a channel (or none), taking
//! effect for the channel's next message.

use crate::lang::args::{Args, Target};
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};

/// Route every robot of `target` to `channel` (`None`: to no channel, so
/// nothing drives them).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Route {
    pub target: Target,
    pub channel: Option<String>,
}

impl Route {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<Route, LangError> {
        Ok(Route {
            target: a.target()?,
            channel: a.channel()?,
        })
    }

    pub(super) async fn apply(&self, ctx: &mut Context, _at: Span) -> Result<Outcome, LangError> {
        let robots = ctx.resolve(&self.target)?;
        for r in &robots {
            ctx.gcs
                .router()
                .set_route(r, self.channel.as_deref())
                .await
                .map_err(|e| LangError::new(self.target.span, e.to_string()))?;
        }
        Ok(Outcome::new(format!(
            "{} routed to {}",
            robots.join(", "),
            self.channel.as_deref().unwrap_or("none")
        )))
    }
}

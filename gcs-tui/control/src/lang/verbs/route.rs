//! `route TARGET CHANNEL|none`: puts robots on a channel (or none), taking
//! effect for the channel's next message. Another station's robot
//! (`robot@station`) is routed by that station: the request goes to it
//! through the bridge, and it decides.

use std::sync::Arc;

use crate::lang::args::{Args, Target};
use crate::lang::context::{Context, RemoteRoutes};
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
        let robots = ctx.resolve_shown(&self.target)?;
        let channel = self.channel.as_deref();
        let mut answers = Vec::new();
        for r in &robots {
            let station = ctx
                .gcs
                .with_fleet(|f| f.robot(r).and_then(|x| x.remote.clone()));
            match station {
                None => {
                    ctx.gcs
                        .router()
                        .set_route(r, channel)
                        .await
                        .map_err(|e| LangError::new(self.target.span, e.to_string()))?;
                }
                Some(station) => {
                    let routes = ctx.remote_routes.clone();
                    answers.push(self.ask(routes, r, &station).await?);
                }
            }
        }
        let mut summary = format!(
            "{} routed to {}",
            robots.join(", "),
            channel.unwrap_or("none")
        );
        if !answers.is_empty() {
            summary = format!("{summary} ({})", answers.join("; "));
        }
        Ok(Outcome::new(summary))
    }

    /// Asks `station`, through `routes`, to route its robot shown here as
    /// `shown`.
    async fn ask(
        &self,
        routes: Option<Arc<dyn RemoteRoutes>>,
        shown: &str,
        station: &str,
    ) -> Result<String, LangError> {
        let at = |message: String| LangError::new(self.target.span, message);
        let Some(routes) = routes else {
            return Err(at(format!(
                "{shown} is a robot of station {station}, and this station has no bridge \
                 to ask {station} to route it"
            )));
        };
        let robot = shown.strip_suffix(&format!("@{station}")).unwrap_or(shown);
        routes
            .request_route(station, robot, self.channel.as_deref())
            .await
            .map_err(|e| at(format!("station {station} did not route {shown}: {e}")))
    }
}

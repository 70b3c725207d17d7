//! `safety on|off TARGET`: switches robots' fleet safety layer on or off.
//! Only an operator can (the command language is the operators': no
//! controller, robot or peer may send an arena). A robot switched off is
//! no longer kept inside the arena or apart from its neighbours, and shows
//! as an alarm on its card, in the status bar and in `status`.

use crate::lang::args::{Args, Target};
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};

/// Switch every robot of `target`'s layer on (`enabled`) or off.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Safety {
    pub enabled: bool,
    pub target: Target,
}

impl Safety {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<Safety, LangError> {
        let w = a.next("on or off")?;
        let enabled = match w.text.as_str() {
            "on" => true,
            "off" => false,
            other => {
                return Err(LangError::new(
                    w.span,
                    format!("expected on or off, got {other:?}"),
                ));
            }
        };
        Ok(Safety {
            enabled,
            target: a.target()?,
        })
    }

    pub(super) async fn apply(&self, ctx: &mut Context, _at: Span) -> Result<Outcome, LangError> {
        let robots = ctx.resolve(&self.target)?;
        let router = ctx.gcs.router();
        let mut ids = Vec::new();
        for r in &robots {
            let id = router
                .set_safety(r, self.enabled)
                .await
                .map_err(|e| LangError::new(self.target.span, e.to_string()))?;
            ids.push(id);
        }
        let state = if self.enabled { "on" } else { "OFF" };
        let sent = if router.arena().is_some() {
            "sent until acknowledged"
        } else {
            "no arena yet: it goes out with the next one"
        };
        Ok(Outcome::new(format!(
            "safety {state} for {} ({sent})",
            robots.join(", ")
        )))
    }
}

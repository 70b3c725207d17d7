//! `channels`: lists the router's live channels with their publisher, rate
//! and the robots routed to them.

use crate::lang::context::Context;
use crate::lang::{LangError, Outcome};

pub(super) async fn apply(ctx: &mut Context) -> Result<Outcome, LangError> {
    let list = ctx.gcs.router().channels();
    let details = list
        .iter()
        .map(|c| {
            format!(
                "{} publisher {} {:.1} Hz robots [{}]",
                c.name,
                c.publisher,
                c.rate_hz,
                c.robots.join(", ")
            )
        })
        .collect();
    Ok(Outcome {
        summary: format!("{} live channels", list.len()),
        details,
    })
}

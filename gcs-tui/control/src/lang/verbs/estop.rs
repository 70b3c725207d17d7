//! `estop` and `release`: the latched emergency stop of every robot, and
//! its release. Neither takes arguments, so both are unit variants of
//! [`Command`](super::Command) that the TUI can also act on directly.

use crate::lang::context::Context;
use crate::lang::{LangError, Outcome};

/// `estop`: engage the e-stop on every robot, now and at registration.
pub(super) async fn engage(ctx: &mut Context) -> Result<Outcome, LangError> {
    let id = ctx.gcs.router().estop().await;
    Ok(Outcome::new(format!("e-stop {id} engaged for every robot")))
}

/// `release`: release the e-stop.
pub(super) async fn release(ctx: &mut Context) -> Result<Outcome, LangError> {
    let id = ctx.gcs.router().release().await;
    Ok(Outcome::new(format!("e-stop released ({id})")))
}

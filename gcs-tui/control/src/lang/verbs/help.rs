//! `help`: lists every verb of [`VERBS`] with its usage and help line.

use super::VERBS;
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome};

pub(super) async fn apply(_ctx: &mut Context) -> Result<Outcome, LangError> {
    Ok(Outcome {
        summary: format!("{} commands", VERBS.len()),
        details: VERBS
            .iter()
            .map(|v| format!("{:<60} {}", v.usage, v.help))
            .collect(),
    })
}

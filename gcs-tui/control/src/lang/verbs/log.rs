//! `log TEXT...`: writes a line to the event log (and, through tracing, to
//! the log file), so a script's output shows where it is.

use mech_core::fleet::Severity;

use crate::lang::args::Args;
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};

/// Log `text` (the arguments joined by single spaces).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Log {
    pub text: String,
}

impl Log {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<Log, LangError> {
        let mut parts = Vec::new();
        while !a.is_empty() {
            parts.push(a.next("text")?.text.clone());
        }
        Ok(Log {
            text: parts.join(" "),
        })
    }

    pub(super) async fn apply(&self, ctx: &mut Context, _at: Span) -> Result<Outcome, LangError> {
        let text = &self.text;
        tracing::info!(target: "script", "{text}");
        ctx.gcs
            .update_fleet(|f| f.log(Severity::Info, text.clone()));
        Ok(Outcome::new(text.clone()))
    }
}

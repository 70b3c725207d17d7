//! `sleep DURATION`: pauses a script (on tokio's clock, so tests can pause
//! time).

use std::time::Duration;

use crate::lang::args::Args;
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};

/// Do nothing for `duration`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Sleep {
    pub duration: Duration,
}

impl Sleep {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<Sleep, LangError> {
        Ok(Sleep {
            duration: a.duration()?,
        })
    }

    pub(super) async fn apply(&self, _ctx: &mut Context, _at: Span) -> Result<Outcome, LangError> {
        tokio::time::sleep(self.duration).await;
        Ok(Outcome::new(format!(
            "slept {:.3} s",
            self.duration.as_secs_f64()
        )))
    }
}

//! `arena`: the arena robots are kept inside (fleet safety). Alone it says
//! what the station has; `arena load FILE` reads an arena file (the keys
//! of the `[arena]` section at its top level, on the station's machine)
//! and sends it to every robot, `arena demo` the simulator's rectangle,
//! `arena clear` takes it away (robots keep no fence and get no
//! neighbours).

use mech_core::{ArenaConfig, ArenaShape};

use crate::lang::args::Args;
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};

/// What `arena` does.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Arena {
    Show,
    /// Read this file and send its arena.
    Load(String, Span),
    /// The demo simulator's 3.9 m x 2.8 m rectangle.
    Demo,
    Clear,
}

impl Arena {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<Arena, LangError> {
        let Some(w) = a.peek() else {
            return Ok(Arena::Show);
        };
        let what = a.next("load, demo or clear")?;
        Ok(match what.text.as_str() {
            "load" => {
                let file = a.next("arena file")?;
                Arena::Load(file.text.clone(), file.span)
            }
            "demo" => Arena::Demo,
            "clear" => Arena::Clear,
            other => {
                return Err(LangError::new(
                    w.span,
                    format!("unknown arena action {other:?}; use load FILE, demo or clear"),
                ));
            }
        })
    }

    pub(super) async fn apply(&self, ctx: &mut Context, _at: Span) -> Result<Outcome, LangError> {
        let router = ctx.gcs.router();
        let arena = match self {
            Arena::Show => {
                return Ok(Outcome::new(match router.arena() {
                    Some(a) => format!("arena {}", a.summary()),
                    None => "no arena: robots keep no fence (`arena load FILE`)".to_string(),
                }));
            }
            Arena::Load(file, span) => Some(load(file, *span).await?),
            Arena::Demo => Some(ArenaConfig::demo().shape()),
            Arena::Clear => None,
        };
        let summary = match &arena {
            Some(a) => format!("arena {} sent to every robot", a.summary()),
            None => "arena cleared: every robot told".to_string(),
        };
        router.set_arena(arena).await;
        Ok(Outcome::new(summary))
    }
}

/// The arena of `file`, checked; a mistake says `file:line:column`.
async fn load(file: &str, span: Span) -> Result<ArenaShape, LangError> {
    let text = tokio::fs::read_to_string(file)
        .await
        .map_err(|e| LangError::new(span, format!("cannot read {file}: {e}")))?;
    ArenaConfig::parse_file_text(&text, file)
        .map(|a| a.shape())
        .map_err(|e| LangError::new(span, e.to_string()))
}

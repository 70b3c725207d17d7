//! `arena`: the arena robots are kept inside (fleet safety). Alone it says
//! what the station has; `arena load FILE` reads an arena file (the keys
//! of the `[arena]` section at its top level, on the station's machine;
//! from an operator's session a name in the missions directory, as
//! [`crate::files`] says) and sends it to every robot, `arena demo` the
//! simulator's rectangle, `arena clear` takes it away (robots keep no
//! fence and get no neighbours).

use std::path::Path;

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
            Arena::Load(file, span) => {
                let path = ctx
                    .files
                    .resolve(file, false)
                    .map_err(|e| LangError::new(*span, e))?;
                Some(load(&path, *span).await?)
            }
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

/// Arena files are small: a larger file is not one.
const MAX_FILE_BYTES: u64 = 1 << 20;

/// The arena of `file`, checked; a mistake says `file:line:column`.
async fn load(file: &Path, span: Span) -> Result<ArenaShape, LangError> {
    let name = file.display().to_string();
    let text = crate::files::read_text(file, MAX_FILE_BYTES)
        .await
        .map_err(|e| LangError::new(span, format!("cannot read {name}: {e}")))?;
    ArenaConfig::parse_file_text(&text, &name)
        .map(|a| a.shape())
        .map_err(|e| LangError::new(span, e.to_string()))
}

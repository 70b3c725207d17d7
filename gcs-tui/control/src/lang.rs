//! The MECH command language: one parser and one executor shared by the TUI
//! command line and `mech-gcs --script`. The grammar is documented for users
//! in `docs/commands.md`.
//!
//! A script is a sequence of lines; each non-blank line holds one command: a
//! verb followed by whitespace-separated arguments. `#` starts a comment;
//! `"..."` quotes text. Numbers are SI (metres, seconds, radians), points are
//! `x,y` or `x,y,z` with an optional arrival time `@15s`, durations are
//! `500ms`, `2s`, `1.5s` or `1m`.
//!
//! Layers, each using only the ones before it:
//! - [`lexer`] turns text into words with line and column;
//! - [`args`] is the cursor over a command's words and the small word parsers
//!   (target, channel, number, duration, point...);
//! - `context` is what a verb runs against: the station, its controllers,
//!   the publishers the language sends through, the simulator;
//! - [`verbs`] holds one file per verb, each with the verb's parsed form, its
//!   `parse` and its `apply`, and the verb table [`verbs::VERBS`] that the
//!   parser and `help` read;
//! - [`parse`] turns a line's words into a [`Statement`] through that table;
//! - [`exec::Executor`] runs statements against a [`mech_core::Gcs`] and the
//!   [`ControlHub`](crate::ControlHub) controllers, dispatching to each
//!   verb's `apply`.
//!
//! Adding a verb `foo-bar`:
//! 1. a file `verbs/foo_bar.rs` with `pub struct FooBar { ... }` (what the
//!    verb means once parsed), `fn parse(args: &mut Args) -> Result<FooBar,
//!    LangError>` and `async fn apply(&self, ctx: &mut Context, at: Span) ->
//!    Result<Outcome, LangError>`;
//! 2. one row in [`verbs::VERBS`] (name, usage, one-line help, parse);
//! 3. one variant `Command::FooBar(FooBar)` in [`verbs::Command`] and its
//!    arm in `Command::apply`; the compiler points at it;
//! 4. its line in `docs/commands.md`.
//!
//! A verb without arguments (`estop`, `release`, `channels`, `help`) is a
//! unit variant, run by a free function of its file. A verb that waits
//! polls through the one loop `verbs::poll_until`, with its default timeout
//! from [`verbs::WAIT_TIMEOUT`] or [`verbs::CONTROL_WAIT_TIMEOUT`].

pub mod args;
mod context;
pub mod exec;
pub mod lexer;
pub mod parse;
pub mod verbs;

use std::fmt;

pub use args::Target;
pub use exec::{Executor, RemoteRoutes, SharedSpawner, SimSpawner};
pub use lexer::quote;
pub use parse::{Statement, parse_line, parse_script};
pub use verbs::Command;
pub use verbs::expect::Expectation;
pub use verbs::wait::WaitFor;

/// A position in a script, 1-based.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct Span {
    pub line: usize,
    pub column: usize,
}

impl fmt::Display for Span {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "line {}, column {}", self.line, self.column)
    }
}

/// A parse or execution error, pointing at the word that caused it.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{span}: {message}")]
pub struct LangError {
    pub span: Span,
    pub message: String,
}

impl LangError {
    pub fn new(span: Span, message: impl Into<String>) -> LangError {
        LangError {
            span,
            message: message.into(),
        }
    }
}

/// What a command did, for the operator.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Outcome {
    /// One line.
    pub summary: String,
    /// Further lines (`channels`, `status`, `help`, `cluster-status`).
    pub details: Vec<String>,
}

impl Outcome {
    /// A one-line outcome.
    pub fn new(summary: impl Into<String>) -> Outcome {
        Outcome {
            summary: summary.into(),
            details: Vec::new(),
        }
    }
}

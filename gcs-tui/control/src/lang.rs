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
//! Layers: [`lexer`] turns text into words with line and column;
//! [`parse`] turns a line's words into a [`Statement`] using the verb table
//! [`parse::VERBS`]; [`exec::Executor`] runs statements against a [`mech_core::Gcs`].
//!
//! Adding a command: add a variant to [`ast::Command`], a parse function and
//! a row in [`parse::VERBS`] (verb, usage, one-line help), and an arm in
//! [`exec::Executor::execute`]. The compiler points at every match that
//! needs the new variant.

pub mod ast;
pub mod control;
pub mod exec;
pub mod lexer;
pub mod parse;

use std::fmt;

pub use ast::{Command, Expectation, Statement, Target, WaitFor};
pub use exec::{Executor, Outcome, SimSpawner};
pub use parse::{parse_line, parse_script};

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

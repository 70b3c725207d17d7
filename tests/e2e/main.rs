//! End-to-end tests: the real binaries, over real sockets.

mod cli;
mod script;
mod tui;

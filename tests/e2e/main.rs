//! End-to-end tests: the real binaries, over real sockets.

mod cli;
mod cluster_script;
mod script;
mod signed;
mod tui;
mod zenoh;

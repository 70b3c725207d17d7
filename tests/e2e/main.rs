//! End-to-end tests: the real binaries, over real sockets.

mod cli;
mod cluster_script;
mod record;
mod script;
mod serve;
mod signed;
mod tmux;
mod tui;

//! End-to-end tests: the real binaries, over real sockets.

mod autopilot;
mod cli;
mod cluster_script;
mod octave;
mod python;
mod script;
mod signed;
mod station;
mod tui;

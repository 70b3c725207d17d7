//! End-to-end tests: the real binaries, over real sockets.

mod autopilot;
mod cli;
mod cluster_script;
mod record;
mod octave;
mod python;
mod radio;
mod script;
mod serve;
mod signed;
mod tmux;
mod station;
mod tui;

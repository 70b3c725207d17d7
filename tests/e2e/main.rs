//! End-to-end tests: the real binaries, over real sockets.

mod autopilot;
mod cli;
mod cluster_script;
mod cross;
mod examples;
mod fleet_scale;
mod hostile;
mod octave;
mod operator_files;
mod plots;
mod python;
mod radio;
mod record;
mod replay_tui;
mod safety_tui;
mod script;
mod serve;
mod signed;
mod station;
mod tmux;
mod tui;
mod zenoh;

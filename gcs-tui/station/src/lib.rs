//! `mech-station`: the MECH station as a service, without a terminal. The
//! router, fleet model, controllers and simulator run in one place: a
//! `mech-gcs serve` process that outlives any terminal, or, when none
//! runs, inside the TUI's own process (or `mech-zenoh`'s). Clients attach
//! to it with the attach protocol ([`wire`], docs/control-protocol.md): a
//! TUI, an `--attach --script` run, any program. This crate has no
//! terminal and no gamepad in it, so a TUI can only draw what the protocol
//! brings: an embedded and an attached TUI run the same code.
//!
//! - [`wire`]: the attach protocol's messages, as JSON lines, and
//!   [`view`], the fleet as they carry it;
//! - [`Station`] (`server`): what clients attach to, and its `[station]`
//!   section; one session per client (`session`), each with its own
//!   command-language executor, all sharing the controllers; the places
//!   for clients attaching and attached (`admission`); the snapshot and
//!   log feed (`feed`); the control socket and TCP listeners (`listen`);
//!   operators' names ([`operator`]);
//! - [`client`]: attaching (Unix socket, TCP with an operator key, or in
//!   process) and running a script on an attached station;
//! - [`launch`]: a station started from its configuration, in this
//!   process; [`serve`]: `mech-gcs serve`: sockets, systemd notification,
//!   SIGTERM;
//! - [`sim`]: simulated agents for `spawn` and `--demo`;
//! - [`foxglove`]: the Foxglove live view (`--foxglove`, cargo feature
//!   `foxglove`);
//! - [`replay`]: a recording read back, as a station a TUI attaches to or
//!   as `--script` lines;
//! - [`config`]: `gcs.toml`, assembled from each layer's section;
//!   [`logging`]: rolling log files;
//! - [`cli`]: the command-line flags `mech-gcs` and `mech-zenoh` share.

#![cfg_attr(test, allow(clippy::unwrap_used, clippy::field_reassign_with_default))]

mod admission;
pub mod cli;
pub mod client;
pub mod config;
mod feed;
pub mod foxglove;
pub mod launch;
mod listen;
pub mod logging;
pub mod operator;
pub mod replay;
pub mod serve;
mod server;
mod session;
#[cfg(feature = "sim")]
pub mod sim;
pub mod view;
pub mod wire;

pub use config::ConfigFile;
pub use feed::snapshot;
pub use launch::{Launched, Recording};
pub use listen::{ListenError, bind_tcp, bind_unix};
pub use operator::{check_operator, login_name};
pub use server::{Station, StationConfig, Via, default_socket};

/// The simulator `spawn` and `--demo` use, in a build with one (feature
/// `sim`); `None` otherwise, and those commands then say so.
pub fn simulator() -> Option<Box<dyn mech_control::lang::SimSpawner>> {
    #[cfg(feature = "sim")]
    return Some(sim::simulator());
    #[cfg(not(feature = "sim"))]
    None
}

/// The arena the demo's simulated fleet is spread over (the 2017 lab's
/// Pozyx area, `mech_core::ArenaConfig::demo`), for the map outline.
pub fn demo_arena() -> view::ArenaBounds {
    let shape = mech_core::ArenaConfig::demo().shape();
    let xs = shape.boundary.iter().map(|p| p.x);
    let ys = shape.boundary.iter().map(|p| p.y);
    view::ArenaBounds {
        min_x: xs.clone().fold(f64::INFINITY, f64::min),
        min_y: ys.clone().fold(f64::INFINITY, f64::min),
        max_x: xs.fold(f64::NEG_INFINITY, f64::max),
        max_y: ys.fold(f64::NEG_INFINITY, f64::max),
    }
}

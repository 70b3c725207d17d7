//! `mech-zenoh`: several stations, sites and tools sharing fleets over
//! [Zenoh](https://zenoh.io), the pub/sub that ROS 2's `rmw_zenoh` uses.
//!
//! A [`Bridge`] puts one running station ([`mech_core::Gcs`]) on the Zenoh
//! network: each of its robots' registration, telemetry, link state and
//! route under `mech/<station>/<robot>/...` as JSON a program without
//! MECH's code reads (`docs/zenoh.md`); commands published on
//! `mech/<station>/<robot>/cmd/<channel>` into its router, which forwards
//! them only to robots routed to that channel; route requests from other
//! stations' operators, obeyed only where its `[auth]` lists their key; and
//! other stations' robots shown in its fleet model, read-only, marked
//! remote, lost within the lease when they or their station leave.
//!
//! Modules, leaves first:
//! - [`keys`]: the key space and which names may be key chunks;
//! - [`payload`]: the JSON on each key;
//! - [`config`]: the `[zenoh]` section and the session configuration;
//! - [`stats`]: what the bridge counted;
//! - `outbound`, `answers`: this station's robots onto Zenoh;
//! - `inbound`: commands from Zenoh into the router;
//! - `routes`: route requests, taken and sent ([`RouteRequester`]);
//! - `remote`: other stations' robots into the fleet model;
//! - [`bridge`]: [`Bridge`], all of the above started together.
//!
//! Zenoh is a large dependency, so this crate is outside the workspace's
//! default members: `cargo build` leaves it out, `cargo build -p
//! mech-zenoh` (or `--workspace`) builds it and the `mech-zenoh` binary.

#![cfg_attr(test, allow(clippy::unwrap_used))]

mod answers;
pub mod bridge;
pub mod config;
mod inbound;
pub mod keys;
mod outbound;
pub mod payload;
mod remote;
mod routes;
pub mod stats;

pub use bridge::{Bridge, BridgeError};
pub use config::{RouteRequests, ZenohConfig};
pub use routes::RouteRequester;
pub use stats::StatsSnapshot;

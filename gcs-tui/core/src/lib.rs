//! `mech-core`: the MECH ground station's core, with no terminal, gamepad
//! or simulator in it, so `--script`, `serve` and any other program can run
//! a station.
//!
//! Modules, leaves first (each depends only on those above it):
//! - [`sync`], [`config`], [`budget`]: the poison-tolerant lock, what
//!   every configuration section shares, and budgets per second for what
//!   a flood must not multiply;
//! - [`auth`]: keys, roles and the `[auth]` section of the authenticated
//!   control plane;
//! - [`names`]: robot names as an operator reads them (the number a name
//!   ends with, natural order);
//! - [`arena`]: the `[arena]` section, the arena the station holds and
//!   the arena message robots enforce (fleet safety, `docs/safety.md`);
//! - [`event`]: what the station saw happen, and the [`EventSink`] the
//!   router delivers it to;
//! - [`counters`]: traffic counters and live channels;
//! - [`router`]: the UDP/TCP router with live controller switching;
//! - [`fleet`]: the fleet model, an [`EventSink`] fed by the router;
//! - [`neighbours`]: the `[neighbours]` section, choosing each robot's
//!   neighbours from the fleet's states, and the broadcaster that sends
//!   them through the router;
//! - [`record`]: recording what the router sees to MCAP;
//! - [`replay`]: reading a recording back, as events and fleet models;
//! - [`gcs`]: [`Gcs`], the router and fleet model started together.
//!
//! Start a [`Gcs`], read the fleet with [`Gcs::snapshot`] /
//! [`Gcs::with_fleet`], and act through [`Gcs::router`].

#![cfg_attr(test, allow(clippy::unwrap_used, clippy::field_reassign_with_default))]

pub mod arena;
pub mod auth;
pub mod budget;
pub mod config;
pub mod counters;
pub mod event;
pub mod fleet;
pub mod gcs;
pub mod names;
pub mod neighbours;
pub mod record;
pub mod replay;
pub mod router;
pub mod sync;

pub use arena::{ArenaConfig, ArenaShape};
pub use config::ConfigError;
pub use counters::{ChannelStatus, Counters, DropReason, Drops, LinkQuality, Traffic};
pub use event::{Event, EventSink, LinkAddr, LinkState, RobotLinks, Stamped};
pub use fleet::{Fleet, FleetConfig};
pub use gcs::{CoreConfig, Gcs};
pub use neighbours::NeighbourConfig;
pub use record::{RecordConfig, RecordTarget, RecordingStatus};
pub use router::{
    Delivery, Publisher, RadioStatus, Router, RouterConfig, RouterError, RouterHandle,
    SerialEndpoint, Subscription,
};

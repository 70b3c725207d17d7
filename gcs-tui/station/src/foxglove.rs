//! The Foxglove live view (`--foxglove ADDR`, `[foxglove]`): a WebSocket
//! server speaking `foxglove.websocket.v1` that shows the fleet live in
//! Foxglove or Lichtblick, on the same topics and with the same schemas and
//! JSON messages as recordings (`mech_core::record`): a pose per robot, the
//! fleet as a scene, the event log, events, telemetry and clusters.
//!
//! It is built only with the cargo feature `foxglove`; without it, asking
//! for it is a configuration error that names the feature. Its data comes
//! from the router's event subscription, a bounded queue: when the view
//! falls behind, events are dropped and counted, the router is never slowed;
//! each client has a bounded queue too, and a client that reads too slowly
//! loses messages (counted), not the station; one that does not read for
//! 10 s is cut, and told why. Drops are logged.
//!
//! Modules (with the feature): `protocol` (the wire messages), `hub`
//! (channels, clients, queues), `source` (router events to messages),
//! `server` (listening, handshakes), `connection` (a client's life after
//! its handshake, and its end).

use std::net::SocketAddr;

use mech_core::ConfigError;
use serde::Deserialize;

#[cfg(feature = "foxglove")]
mod connection;
#[cfg(feature = "foxglove")]
mod hub;
#[cfg(feature = "foxglove")]
mod protocol;
#[cfg(feature = "foxglove")]
mod server;
#[cfg(feature = "foxglove")]
mod source;

#[cfg(feature = "foxglove")]
pub use server::LiveView;

/// Whether this build has the live view (the cargo feature `foxglove`).
pub const BUILT: bool = cfg!(feature = "foxglove");

/// The `[foxglove]` section.
#[derive(Debug, Clone, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FoxgloveConfig {
    /// Serve the live view here (`--foxglove ADDR`); `None`: no live view.
    pub addr: Option<SocketAddr>,
    /// Router events queued for the live view; when it falls this far
    /// behind, new events are dropped and counted.
    pub queue: usize,
    /// Messages queued for each client; a client that reads slower than
    /// the fleet sends loses what does not fit (counted).
    pub client_queue: usize,
    /// Clients at once; more are refused.
    pub max_clients: usize,
    /// Most fleet scenes (`/mech/scene`) a second (fewer for a big fleet).
    pub scene_hz: f64,
}

impl Default for FoxgloveConfig {
    fn default() -> Self {
        FoxgloveConfig {
            addr: None,
            queue: 1 << 14,
            client_queue: 4096,
            max_clients: 8,
            scene_hz: 10.0,
        }
    }
}

/// What a build without the feature says when the live view is asked for.
pub const NOT_BUILT: &str = "the Foxglove live view (--foxglove, [foxglove] addr) is not in this \
     build of mech-gcs: build it with the cargo feature `foxglove` \
     (cargo build --release -p mech-gcs --features foxglove)";

impl FoxgloveConfig {
    /// Rejects settings the live view cannot run with, and asking for it
    /// in a build without it.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if self.addr.is_some() && !BUILT {
            return Err(ConfigError::new(NOT_BUILT));
        }
        if self.queue == 0 || self.client_queue < 16 || self.max_clients == 0 {
            return Err(ConfigError::new(
                "foxglove.queue must be at least 1, client_queue at least 16, max_clients at least 1",
            ));
        }
        if !(self.scene_hz > 0.0 && self.scene_hz <= 100.0) {
            return Err(ConfigError::new(
                "foxglove.scene_hz must be above 0 and at most 100",
            ));
        }
        Ok(())
    }
}

/// The live view of a running station, when configured: started with the
/// station, stopped (with a summary in the log) when dropped or stopped.
#[derive(Debug, Default)]
pub struct Live {
    #[cfg(feature = "foxglove")]
    view: Option<LiveView>,
}

impl Live {
    /// Starts the live view of `gcs` if `config` asks for one.
    pub async fn start(gcs: &mech_core::Gcs, config: &FoxgloveConfig) -> anyhow::Result<Live> {
        config.validate()?;
        #[cfg(feature = "foxglove")]
        if config.addr.is_some() {
            let view = LiveView::start(gcs, config).await?;
            return Ok(Live { view: Some(view) });
        }
        let _ = gcs;
        Ok(Live::default())
    }

    /// Where it listens, if it runs: `ws://ADDR` for Foxglove.
    pub fn addr(&self) -> Option<SocketAddr> {
        #[cfg(feature = "foxglove")]
        if let Some(v) = &self.view {
            return Some(v.addr());
        }
        None
    }

    /// A sentence for the ready line: where to point Foxglove, or nothing.
    pub fn describe(&self) -> Option<String> {
        self.addr()
            .map(|a| format!("Foxglove live view on ws://{a}"))
    }

    /// Stops it and logs what it sent and dropped.
    pub fn stop(self) {
        #[cfg(feature = "foxglove")]
        if let Some(v) = self.view {
            v.stop();
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn asking_for_the_live_view_is_refused_only_without_the_feature() {
        let mut c = FoxgloveConfig::default();
        assert!(c.validate().is_ok());
        c.addr = Some(SocketAddr::from(([127, 0, 0, 1], 8765)));
        let checked = c.validate();
        assert_eq!(checked.is_ok(), BUILT);
        if let Err(e) = checked {
            assert!(e.to_string().contains("feature `foxglove`"), "{e}");
        }
        c.client_queue = 1;
        assert!(c.validate().is_err());
    }
}

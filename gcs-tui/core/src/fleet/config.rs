//! The fleet model's section of the configuration (`[fleet]`): trails, the
//! event log, and the channels and arrival radius the station's own
//! missions and commands use.

use serde::Deserialize;

use crate::config::{ConfigError, is_channel_name};

/// Fleet-model settings.
#[derive(Debug, Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct FleetConfig {
    /// Poses kept per robot for the map trail.
    pub path_history: usize,
    /// Minimum distance (m) between two kept trail points.
    pub path_spacing: f64,
    /// Entries kept in the event log.
    pub event_log: usize,
    /// Channel the GCS sends missions on.
    pub mission_channel: String,
    /// Channel the command line's `drive` publishes on.
    pub command_channel: String,
    /// Arrival radius (m) of missions sent from the GCS.
    pub arrival_radius: f64,
    /// Where operators' `mission save` and `mission load` read and write
    /// (files named relative to it, none outside); unset:
    /// `$XDG_DATA_HOME/mech/missions` (`~/.local/share/mech/missions`).
    pub mission_dir: Option<std::path::PathBuf>,
}

impl Default for FleetConfig {
    fn default() -> Self {
        FleetConfig {
            path_history: 500,
            path_spacing: 0.02,
            event_log: 500,
            mission_channel: "wp/gcs".into(),
            command_channel: "cmd/gcs".into(),
            arrival_radius: 0.1,
            mission_dir: None,
        }
    }
}

impl FleetConfig {
    /// Rejects settings the station cannot run with.
    pub fn validate(&self) -> Result<(), ConfigError> {
        for (name, channel) in [
            ("fleet.mission_channel", &self.mission_channel),
            ("fleet.command_channel", &self.command_channel),
        ] {
            // An empty channel is "none": commands or missions on it would
            // reach robots nobody routed.
            if !is_channel_name(channel) {
                return Err(ConfigError(format!(
                    "{name} must be a channel name without spaces, got {channel:?}"
                )));
            }
        }
        if self.arrival_radius.is_nan() || self.arrival_radius <= 0.0 {
            return Err(ConfigError::new("fleet.arrival_radius must be positive"));
        }
        Ok(())
    }
}

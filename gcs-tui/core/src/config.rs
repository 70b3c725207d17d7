//! What every layer's configuration section shares: the error type, checks
//! of names, and durations written as seconds. Each layer owns its own
//! section ([`crate::RouterConfig`], [`crate::FleetConfig`]); the binary
//! assembles them into one file.

/// A configuration value the station cannot run with.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{0}")]
pub struct ConfigError(pub String);

impl ConfigError {
    pub fn new(message: impl Into<String>) -> ConfigError {
        ConfigError(message.into())
    }
}

/// Whether `name` can name a channel: not empty, no whitespace or control
/// characters, at most the protocol's name length. An empty channel means
/// "none" on the wire, so it never names one.
pub fn is_channel_name(name: &str) -> bool {
    !name.is_empty()
        && name.len() <= mech_proto::MAX_NAME_LEN
        && !name.chars().any(|c| c.is_whitespace() || c.is_control())
}

/// Durations written as seconds (`0.5`, `2`) in TOML.
pub mod secs {
    use std::time::Duration;

    use serde::{Deserialize, Deserializer};

    pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<Duration, D::Error> {
        let s = f64::deserialize(d)?;
        Duration::try_from_secs_f64(s)
            .map_err(|_| serde::de::Error::custom(format!("{s} is not a duration in seconds")))
    }
}

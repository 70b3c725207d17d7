//! The station as a service. The router, fleet model, controllers and
//! simulator run in one place: a `mech-gcs serve` process that outlives any
//! terminal, or, when none runs, inside the TUI's own process. Clients
//! attach to it with the attach protocol ([`wire`],
//! docs/control-protocol.md): a TUI, an `--attach --script` run, any
//! program. The TUI draws only what the protocol brings, so an embedded and
//! an attached TUI run the same code.
//!
//! - [`wire`]: the messages, as JSON lines;
//! - [`Station`]: what clients attach to: one session per client, each with
//!   its own command-language executor, all sharing the controllers;
//! - [`client`]: attaching (Unix socket, TCP with an operator key, or in
//!   process) and `--attach --script`;
//! - [`serve`]: `mech-gcs serve`: sockets, systemd notification, SIGTERM.

use std::net::SocketAddr;
use std::path::PathBuf;

use serde::Deserialize;

pub mod client;
mod feed;
mod listen;
pub mod serve;
mod server;
mod session;
pub mod wire;

pub(crate) use feed::LogCursor;
pub use feed::snapshot;
pub use listen::{ListenError, bind_tcp, bind_unix};
pub use server::{Station, Via};

/// `[station]`: where a served station listens for clients.
#[derive(Debug, Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct StationConfig {
    /// The local control socket (default [`default_socket`]).
    pub socket: Option<PathBuf>,
    /// Permission bits of the socket: owner and group by default (0o660);
    /// its directory, when the station creates it, gets the same read and
    /// search bits (0o750).
    pub socket_mode: u32,
    /// TCP endpoint for operators on other machines; each proves an
    /// operator key (`[auth]`). None by default.
    pub tcp: Option<SocketAddr>,
    /// Fleet snapshots per second sent to each TUI (a route change or
    /// other event is sent at once, between them).
    pub snapshot_rate: f64,
}

impl Default for StationConfig {
    fn default() -> Self {
        StationConfig {
            socket: None,
            socket_mode: 0o660,
            tcp: None,
            snapshot_rate: 20.0,
        }
    }
}

impl StationConfig {
    pub fn validate(&self) -> Result<(), mech_core::ConfigError> {
        let bad = |m: String| Err(mech_core::ConfigError(format!("[station] {m}")));
        if !(self.snapshot_rate.is_finite() && (1.0..=100.0).contains(&self.snapshot_rate)) {
            return bad(format!(
                "snapshot_rate = {} is not between 1 and 100 per second",
                self.snapshot_rate
            ));
        }
        if self.socket_mode & !0o777 != 0 || self.socket_mode & 0o600 != 0o600 {
            return bad(format!(
                "socket_mode = {:o} must give the owner read and write and have no bits beyond 0o777",
                self.socket_mode
            ));
        }
        if self.socket_mode & 0o007 != 0 {
            return bad(format!(
                "socket_mode = {:o} lets every user on the machine command the robots; give owner and group only (0o660)",
                self.socket_mode
            ));
        }
        Ok(())
    }

    /// The control socket's path.
    pub fn socket_path(&self) -> PathBuf {
        self.socket.clone().unwrap_or_else(default_socket)
    }
}

/// `$XDG_RUNTIME_DIR/mech/gcs.sock`, or `/tmp/mech-UID/gcs.sock` without a
/// runtime directory: private to the user by default.
pub fn default_socket() -> PathBuf {
    match std::env::var_os("XDG_RUNTIME_DIR").filter(|d| !d.is_empty()) {
        Some(d) => PathBuf::from(d).join("mech/gcs.sock"),
        None => PathBuf::from(format!("/tmp/mech-{}/gcs.sock", nix::unistd::getuid())),
    }
}

/// An operator's name as the station uses it in channel names
/// (`joy/NAME/0`) and logs: 1 to 32 letters, digits, `_`, `-` or `.`.
pub fn check_operator(name: &str) -> Result<(), String> {
    let ok = !name.is_empty()
        && name.len() <= 32
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '_' | '-' | '.'));
    if ok {
        Ok(())
    } else {
        Err(format!(
            "operator name {name:?} must be 1 to 32 letters, digits, '_', '-' or '.'"
        ))
    }
}

/// The login name of the user running this process (the default operator
/// name), or `operator`.
pub fn login_name() -> String {
    let uid = nix::unistd::getuid();
    nix::unistd::User::from_uid(uid)
        .ok()
        .flatten()
        .map(|u| u.name)
        .filter(|n| check_operator(n).is_ok())
        .unwrap_or_else(|| "operator".into())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn operator_names_are_channel_safe() {
        for good in ["ana", "b.o_b-2", "x"] {
            assert!(check_operator(good).is_ok(), "{good}");
        }
        for bad in ["", "a b", "a/b", "ana#", &"x".repeat(33), "é"] {
            assert!(check_operator(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn a_socket_open_to_everyone_is_refused() {
        let mut c = StationConfig::default();
        assert!(c.validate().is_ok());
        c.socket_mode = 0o666;
        assert!(c.validate().unwrap_err().0.contains("every user"));
        c.socket_mode = 0o060;
        assert!(c.validate().is_err());
        c.socket_mode = 0o600;
        c.snapshot_rate = 0.0;
        assert!(c.validate().is_err());
    }
}

//! Logging: `tracing` to rolling daily files (plain text, no colour codes),
//! and optionally to stderr. Levels follow the 2017 server log: debug, info
//! (startup, shutdown, connections, route changes), warn (disconnections,
//! e-stops, bad packets), error.

use tracing_appender::non_blocking::WorkerGuard;
use tracing_subscriber::layer::SubscriberExt;
use tracing_subscriber::util::SubscriberInitExt;
use tracing_subscriber::{EnvFilter, Layer, fmt};

use std::path::PathBuf;

use serde::Deserialize;

/// Log files (tracing-appender, rolled daily).
#[derive(Debug, Clone, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct LogConfig {
    /// Directory of the rolling log files; `None` disables file logging.
    pub dir: Option<PathBuf>,
    /// File name prefix (`mech-gcs.log.2026-11-22`).
    pub prefix: String,
    /// `debug`, `info`, `warn` or `error` (or any `tracing` filter).
    pub level: String,
}

impl Default for LogConfig {
    fn default() -> Self {
        LogConfig {
            dir: default_log_dir(),
            prefix: "mech-gcs.log".into(),
            level: "info".into(),
        }
    }
}

/// `$XDG_STATE_HOME/mech` or `~/.local/state/mech`: outside the working
/// directory, so running a script never litters it.
fn default_log_dir() -> Option<PathBuf> {
    if let Some(d) = std::env::var_os("XDG_STATE_HOME").filter(|d| !d.is_empty()) {
        return Some(PathBuf::from(d).join("mech"));
    }
    std::env::var_os("HOME").map(|h| PathBuf::from(h).join(".local/state/mech"))
}

/// Why logging could not start.
#[derive(Debug, thiserror::Error)]
pub enum LogError {
    #[error("bad log level {level:?}: {source}")]
    Level {
        level: String,
        source: tracing_subscriber::filter::ParseError,
    },
    #[error("cannot create the log directory {dir}: {source}")]
    Dir {
        dir: std::path::PathBuf,
        source: std::io::Error,
    },
    #[error("a global logger is already installed")]
    AlreadySet,
}

/// Keeps the file writer flushing; drop it last (at exit) so nothing is lost.
#[derive(Debug)]
pub struct LogGuard {
    _file: Option<WorkerGuard>,
}

/// Installs the global logger: files per `config`, and stderr at
/// `stderr_level` if given (the TUI owns the terminal, so it passes `None`).
pub fn init(config: &LogConfig, stderr_level: Option<&str>) -> Result<LogGuard, LogError> {
    let filter = |level: &str| {
        EnvFilter::try_new(level).map_err(|source| LogError::Level {
            level: level.to_string(),
            source,
        })
    };
    filter(&config.level)?;
    let mut guard = None;
    let file_layer = match &config.dir {
        Some(dir) => {
            std::fs::create_dir_all(dir).map_err(|source| LogError::Dir {
                dir: dir.clone(),
                source,
            })?;
            let appender = tracing_appender::rolling::daily(dir, &config.prefix);
            let (writer, g) = tracing_appender::non_blocking(appender);
            guard = Some(g);
            Some(
                fmt::layer()
                    .with_ansi(false)
                    .with_writer(writer)
                    .with_filter(filter(&config.level)?),
            )
        }
        None => None,
    };
    let stderr_layer = match stderr_level {
        Some(level) => Some(
            fmt::layer()
                .with_writer(std::io::stderr)
                .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
                .with_target(false)
                .with_filter(filter(level)?),
        ),
        None => None,
    };
    tracing_subscriber::registry()
        .with(file_layer)
        .with(stderr_layer)
        .try_init()
        .map_err(|_| LogError::AlreadySet)?;
    Ok(LogGuard { _file: guard })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_plain_lines_to_a_file() {
        let dir = tempfile::tempdir().unwrap();
        let cfg = LogConfig {
            dir: Some(dir.path().to_path_buf()),
            prefix: "t.log".into(),
            level: "info".into(),
        };
        let guard = init(&cfg, None).unwrap();
        tracing::info!(robot = "robot_1", "robot registered");
        tracing::debug!("not at info level");
        drop(guard);
        let file = std::fs::read_dir(dir.path())
            .unwrap()
            .next()
            .unwrap()
            .unwrap()
            .path();
        let text = std::fs::read_to_string(file).unwrap();
        assert!(text.contains("robot registered"), "{text}");
        assert!(!text.contains("not at info level"));
        assert!(!text.contains('\u{1b}'), "no ANSI escapes in files");
    }

    #[test]
    fn a_bad_level_is_an_error() {
        let cfg = LogConfig {
            dir: None,
            prefix: "x".into(),
            level: "robot=verbose".into(),
        };
        assert!(matches!(init(&cfg, None), Err(LogError::Level { .. })));
    }
}

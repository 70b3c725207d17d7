//! A station started in this process from its configuration file: the
//! core (recording as asked), the Foxglove live view when `[foxglove]`
//! asks for one, the simulator behind `spawn`, and the directory `record
//! start` records in. `mech-gcs serve`, the TUI's own station and
//! `mech-zenoh` all start their station here, so they run the same one.

use std::path::{Path, PathBuf};

use anyhow::Context;
use mech_core::{Gcs, RecordTarget};

use crate::config::ConfigFile;
use crate::foxglove::Live;
use crate::server::Station;

/// What a started station records from its first moment.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Recording {
    /// Nothing until an operator types `record start`.
    Off,
    /// Everything, to this file (`--record FILE`); a file that cannot be
    /// written stops the start.
    File(PathBuf),
    /// A service's default: to the file if one is given, else to rotating
    /// files in `[record] dir` (or the log directory). A recording that
    /// cannot start is reported, and the station runs without one.
    Service(Option<PathBuf>),
}

/// A station running in this process, with its live view.
#[derive(Debug)]
pub struct Launched {
    station: Station,
    live: Live,
    recording: String,
}

impl Launched {
    /// Starts the core, the live view and the station. On an error, what
    /// had started is stopped again.
    pub async fn start(config: &ConfigFile, recording: Recording) -> anyhow::Result<Launched> {
        let gcs = Gcs::start(config.core())
            .await
            .context("cannot start the router")?;
        let live = match Live::start(&gcs, &config.foxglove).await {
            Ok(live) => live,
            Err(e) => {
                gcs.shutdown().await;
                return Err(e);
            }
        };
        let recording = match record(&gcs, config, recording) {
            Ok(r) => r,
            Err(e) => {
                live.stop();
                gcs.shutdown().await;
                return Err(e);
            }
        };
        let station = Station::start(gcs, &config.cluster, crate::simulator(), &config.station);
        station.set_record_dir(config.record_dir());
        Ok(Launched {
            station,
            live,
            recording,
        })
    }

    /// The station clients attach to.
    pub fn station(&self) -> &Station {
        &self.station
    }

    /// What it records and where its live view listens, for a ready line:
    /// `recording to FILE; Foxglove live view on ws://ADDR`.
    pub fn describe(&self) -> String {
        match self.live.describe() {
            Some(view) => format!("{}; {view}", self.recording),
            None => self.recording.clone(),
        }
    }

    /// Where the live view listens, when it runs.
    pub fn live_view(&self) -> Option<std::net::SocketAddr> {
        self.live.addr()
    }

    /// Stops the live view, then the station (its sessions, simulated
    /// robots and core).
    pub async fn shutdown(self) {
        self.live.stop();
        self.station.shutdown().await;
    }
}

/// Starts the recording asked for; says what is recorded.
fn record(gcs: &Gcs, config: &ConfigFile, recording: Recording) -> anyhow::Result<String> {
    let file = match recording {
        Recording::Off => return Ok("not recording".into()),
        Recording::File(f) => {
            let path = gcs
                .start_recording(RecordTarget::File(f))
                .context("cannot start recording")?;
            return Ok(format!("recording to {}", path.display()));
        }
        Recording::Service(file) => file,
    };
    let started = match (file, &config.log.dir) {
        (Some(f), _) => gcs.start_recording(RecordTarget::File(f)),
        (None, Some(dir)) => gcs.start_default_recording(dir),
        (None, None) if config.record.dir.is_some() => gcs.start_default_recording(Path::new(".")),
        (None, None) => return Ok("not recording (no [log] or [record] directory)".into()),
    };
    Ok(match started {
        Ok(path) => format!("recording to {}", path.display()),
        Err(e) => {
            tracing::error!(error = %e, "cannot record");
            format!("NOT recording: {e}")
        }
    })
}

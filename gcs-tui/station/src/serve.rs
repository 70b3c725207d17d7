//! `mech-gcs serve`: the headless station as a long-running service. It
//! listens on the control socket (and TCP when configured), tells systemd
//! when it is ready and keeps its watchdog fed while the router answers,
//! ignores the hang-up of the terminal it was started from, and on SIGTERM
//! or Ctrl-C says Bye to every client and every robot before it exits.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::Context;
use sd_notify::NotifyState;
use tokio::signal::unix::{SignalKind, signal};

use crate::config::ConfigFile;
use crate::launch::{Launched, Recording};
use crate::listen::{bind_tcp, bind_unix};
use crate::server::Station;

/// Stops what [`serve_with`] started beside the station.
pub type Stop = futures::future::BoxFuture<'static, ()>;

/// Starts the station and serves until SIGTERM or SIGINT. `demo`: start
/// that many simulated robots first.
pub async fn serve(
    config: ConfigFile,
    demo: Option<usize>,
    record: Option<PathBuf>,
) -> anyhow::Result<()> {
    let nothing = |_: Station| async { Ok(Box::pin(async {}) as Stop) };
    serve_with(config, demo, record, nothing).await
}

/// [`serve`], with `beside` started once the station runs (before its
/// sockets take clients and its demo robots start): something that extends
/// the station, such as a bridge to other stations. What it returns is
/// awaited, to stop it, before the station stops.
pub async fn serve_with<F, Fut>(
    config: ConfigFile,
    demo: Option<usize>,
    record: Option<PathBuf>,
    beside: F,
) -> anyhow::Result<()>
where
    F: FnOnce(Station) -> Fut,
    Fut: std::future::Future<Output = anyhow::Result<Stop>>,
{
    tracing::info!(
        version = env!("CARGO_PKG_VERSION"),
        "{} serve starting",
        program()
    );
    // The socket first: if a station already runs, this one must not start
    // a second router beside it.
    let socket = config.station.socket_path();
    let listener = bind_unix(&socket, config.station.socket_mode)?;
    let launched = match Launched::start(&config, Recording::Service(record)).await {
        Ok(l) => l,
        Err(e) => {
            let _ = std::fs::remove_file(&socket);
            return Err(e);
        }
    };
    let station = launched.station().clone();
    let result = match beside(station.clone()).await {
        Ok(stop) => {
            station.listen_unix(listener);
            let recording = launched.describe();
            let result = run(&station, &config, &socket, demo, &recording).await;
            let _ = sd_notify::notify(&[NotifyState::Stopping]);
            stop.await;
            result
        }
        Err(e) => Err(e),
    };
    launched.shutdown().await;
    let _ = std::fs::remove_file(&socket);
    tracing::info!("{} serve stopped", program());
    result
}

async fn run(
    station: &Station,
    config: &ConfigFile,
    socket: &Path,
    demo: Option<usize>,
    recording: &str,
) -> anyhow::Result<()> {
    let mut stop = Signals::new()?;
    if let Some(addr) = config.station.tcp {
        station.listen_tcp(bind_tcp(station, addr).await?);
    }
    if let Some(n) = demo {
        spawn_demo(station, n).await?;
    }
    let ready = format!("{}; {recording}", ready_line(station, socket, config));
    tracing::info!("{ready}");
    // stdout may be a terminal that has gone: never fail on it.
    let _ = writeln!(std::io::stdout(), "{ready}");
    let _ = std::io::stdout().flush();
    let _ = sd_notify::notify(&[NotifyState::Ready, NotifyState::Status(&ready)]);
    let watchdog = sd_notify::watchdog_enabled().map(|t| keep_watchdog(station.clone(), t));
    stop.wait().await;
    if let Some(w) = watchdog {
        w.abort();
    }
    Ok(())
}

fn ready_line(station: &Station, socket: &Path, config: &ConfigFile) -> String {
    let router = station.gcs().router();
    let tcp = config
        .station
        .tcp
        .map(|a| format!(", operators over TCP on {a}"))
        .unwrap_or_default();
    format!(
        "{} serving: router on {} ({}), control socket {}{tcp}",
        program(),
        router.udp_addr(),
        router.security().label(),
        socket.display()
    )
}

/// The running program's name (`mech-gcs`, or `mech-zenoh` serving the
/// same station with its bridge), for the ready line and systemd's status.
fn program() -> String {
    std::env::current_exe()
        .ok()
        .and_then(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .unwrap_or_else(|| "mech-gcs".into())
}

/// `serve --demo N`: N simulated robots, as `spawn N` would.
pub async fn spawn_demo(station: &Station, n: usize) -> anyhow::Result<()> {
    let mut exec = mech_control::lang::Executor::new(station.gcs().clone())
        .with_control(station.control().clone());
    if let Some(s) = &station.inner.spawner {
        exec = exec.with_spawner(Box::new(s.clone()));
    }
    exec.execute_line(&format!("spawn {n}"))
        .await
        .map_err(|e| anyhow::anyhow!("--demo {n}: {}", e.message))?;
    station.set_arena(Some(crate::demo_arena()));
    Ok(())
}

/// Feeds systemd's watchdog at half its period for as long as the router
/// answers (asking for its counters takes its tables' lock: a router stuck
/// holding it stops the pings, and systemd restarts the service).
fn keep_watchdog(station: Station, period: Duration) -> tokio::task::JoinHandle<()> {
    tokio::spawn(async move {
        let mut tick = tokio::time::interval(period / 2);
        loop {
            tick.tick().await;
            let _ = station.gcs().router().counters();
            let _ = sd_notify::notify(&[NotifyState::Watchdog]);
        }
    })
}

/// The signals a service stops on, and the hang-up it outlives.
struct Signals {
    term: tokio::signal::unix::Signal,
    int: tokio::signal::unix::Signal,
    hup: tokio::signal::unix::Signal,
}

impl Signals {
    fn new() -> anyhow::Result<Signals> {
        let s = |k| signal(k).context("cannot install signal handlers");
        Ok(Signals {
            term: s(SignalKind::terminate())?,
            int: s(SignalKind::interrupt())?,
            hup: s(SignalKind::hangup())?,
        })
    }

    /// Returns on SIGTERM or SIGINT; a SIGHUP (the terminal that started
    /// the service closed) is logged and outlived.
    async fn wait(&mut self) {
        loop {
            tokio::select! {
                _ = self.term.recv() => {
                    tracing::info!("SIGTERM: stopping");
                    return;
                }
                _ = self.int.recv() => {
                    tracing::info!("SIGINT: stopping");
                    return;
                }
                _ = self.hup.recv() => {
                    tracing::info!("SIGHUP ignored: the station outlives its terminal (stop it with SIGTERM)");
                }
            }
        }
    }
}

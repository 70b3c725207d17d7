//! `mech-zenoh`: a ground station on the Zenoh network. It runs the same
//! station as `mech-gcs` ([`mech_station::Station`], started from the same
//! configuration file, plus its `[zenoh]` section) with a [`Bridge`]
//! beside it: its robots are published, commands and route requests come
//! in through its router, and other stations' robots are shown read-only.
//! Its station runs as a service (`serve`), runs a script headless
//! (`--script`), or is shown in the TUI: `mech-gcs --attach` on a control
//! socket private to this process, as a child process on this terminal
//! (this program has no terminal code in it).

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use clap::{Parser, Subcommand};
use mech_station::cli::{self, Args, runtime};
use mech_station::client::{AttachOptions, Attached, attach_stream};
use mech_station::serve::{self, Stop};
use mech_station::wire::Streams;
use mech_station::{ConfigFile, Launched, Recording, Station, bind_unix, logging, login_name};
use mech_zenoh::{Bridge, ZenohConfig};

/// The program's name in its messages.
const PROGRAM: &str = "mech-zenoh";

/// MECH ground-control station on the Zenoh network: publishes its robots
/// under mech/<station>/..., takes commands and route requests, shows other
/// stations' robots read-only. With --script, a last JSON line gives the
/// bridge's counters.
#[derive(Debug, Parser)]
#[command(name = "mech-zenoh", version)]
struct Cli {
    #[command(flatten)]
    station: Args,
    /// This station's name on Zenoh (overrides zenoh.station).
    #[arg(long = "station", value_name = "NAME", global = true)]
    name: Option<String>,
    /// Zenoh endpoint to listen on, e.g. tcp/127.0.0.1:7447 (repeatable;
    /// replaces zenoh.listen).
    #[arg(long, value_name = "ENDPOINT", global = true)]
    listen: Vec<String>,
    /// Zenoh endpoint of another station or router to connect to
    /// (repeatable; replaces zenoh.connect).
    #[arg(long, value_name = "ENDPOINT", global = true)]
    connect: Vec<String>,
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run the station with its bridge as a service, as `mech-gcs serve`
    /// does (`mech-gcs --attach` attaches to it; it records to --record
    /// FILE, else to rotating files in the [record] or [log] directory);
    /// stops on SIGTERM.
    Serve,
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("{PROGRAM}: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    let (config, zenoh) = load(&cli)?;
    let demo = cli.station.demo;
    if let Some(Command::Serve) = cli.command {
        let _log = logging::init(&config.log, Some("info")).context("cannot start logging")?;
        let beside = |station: Station| start_bridge(station, zenoh);
        let record = cli.station.record.clone();
        runtime()?.block_on(serve::serve_with(config, demo, record, beside))?;
        return Ok(ExitCode::SUCCESS);
    }
    let source = cli.station.read_script()?;
    let stderr = source.as_ref().map(|_| "warn");
    let _log = logging::init(&config.log, stderr).context("cannot start logging")?;
    let recording = cli
        .station
        .record
        .clone()
        .map_or(Recording::Off, Recording::File);
    let code = runtime()?.block_on(async {
        let embedded = Embedded::start(&config, &zenoh, recording).await?;
        let code = match &source {
            Some(source) => embedded.script(demo, source).await,
            None => embedded.tui(&cli, demo).await,
        };
        embedded.shutdown().await;
        code
    })?;
    Ok(ExitCode::from(code))
}

/// Starts the bridge beside a running station: route requests typed in any
/// session go through it; what it returns stops it.
async fn start_bridge(station: Station, zenoh: ZenohConfig) -> anyhow::Result<Stop> {
    let bridge = Bridge::start(station.gcs(), &zenoh)
        .await
        .context("cannot start the Zenoh bridge")?;
    station.set_remote_routes(bridge.route_requests());
    tracing::info!(station = bridge.station(), "on Zenoh");
    Ok(Box::pin(bridge.shutdown()))
}

/// The configuration file's station sections and its `[zenoh]` section,
/// with the command line's overrides, checked.
fn load(cli: &Cli) -> anyhow::Result<(ConfigFile, ZenohConfig)> {
    let config = cli.station.load()?;
    let mut zenoh = zenoh_section(&config, cli.station.config.as_deref())?;
    if let Some(s) = &cli.name {
        zenoh.station.clone_from(s);
    }
    if !cli.listen.is_empty() {
        zenoh.listen.clone_from(&cli.listen);
    }
    if !cli.connect.is_empty() {
        zenoh.connect.clone_from(&cli.connect);
    }
    zenoh.validate()?;
    Ok((config, zenoh))
}

/// The `[zenoh]` section of the file at `path` (the defaults without a
/// file or section), with the files it names found next to the file.
fn zenoh_section(config: &ConfigFile, path: Option<&Path>) -> anyhow::Result<ZenohConfig> {
    let Some(path) = path else {
        return Ok(ZenohConfig::default());
    };
    let mut zenoh: ZenohConfig = config
        .zenoh
        .read("zenoh")
        .with_context(|| path.display().to_string())?;
    let dir = path.parent().unwrap_or(Path::new("."));
    let beside = |p: &mut PathBuf| {
        if p.is_relative() {
            *p = dir.join(&*p);
        }
    };
    zenoh.operator_key.as_mut().map(beside);
    zenoh.zenoh_config.as_mut().map(beside);
    Ok(zenoh)
}

/// A station with its bridge in this process, for a script or the TUI.
struct Embedded {
    launched: Launched,
    bridge: Bridge,
}

impl Embedded {
    /// Starts the station (with the simulator, the live view when
    /// configured, recording as asked) and the bridge beside it.
    async fn start(
        config: &ConfigFile,
        zenoh: &ZenohConfig,
        recording: Recording,
    ) -> anyhow::Result<Embedded> {
        let launched = Launched::start(config, recording).await?;
        let bridge = match Bridge::start(launched.station().gcs(), zenoh).await {
            Ok(b) => b,
            Err(e) => {
                launched.shutdown().await;
                return Err(e).context("cannot start the Zenoh bridge");
            }
        };
        launched
            .station()
            .set_remote_routes(bridge.route_requests());
        tracing::info!(station = bridge.station(), "on Zenoh");
        Ok(Embedded { launched, bridge })
    }

    fn station(&self) -> &Station {
        self.launched.station()
    }

    /// Attaches to the station in process, as `login_name()`.
    async fn attach(&self, stream: Streams) -> anyhow::Result<Attached> {
        let opts = AttachOptions {
            operator: Some(login_name()),
            key: None,
            stream,
        };
        Ok(attach_stream(self.station().attach_local(), opts).await?)
    }

    /// Runs `source` as `mech-gcs --attach --script` would on this station
    /// (after `demo` simulated robots start), then prints the bridge's
    /// counters as one more JSON line.
    async fn script(&self, demo: Option<usize>, source: &str) -> anyhow::Result<u8> {
        let stream = Streams {
            snapshots: false,
            log: false,
            events: true,
        };
        let mut attached = self.attach(stream).await?;
        let code = match demo {
            Some(n) => match serve::spawn_demo(self.station(), n).await {
                Ok(()) => None,
                Err(e) => {
                    eprintln!("{PROGRAM}: {e:#}");
                    Some(1)
                }
            },
            None => None,
        };
        let code = match code {
            Some(c) => c,
            None => cli::run_script(PROGRAM, &mut attached, source).await,
        };
        let stats = serde_json::json!({"type": "zenoh", "station": self.bridge.station(), "stats": self.bridge.stats()});
        println!("{stats}");
        Ok(code)
    }

    /// Shows the station in the TUI: `demo` simulated robots first, then
    /// `mech-gcs --attach` on a control socket of this process's own, on
    /// this terminal, until the operator quits it; its exit code.
    async fn tui(&self, cli: &Cli, demo: Option<usize>) -> anyhow::Result<u8> {
        if let Some(n) = demo {
            serve::spawn_demo(self.station(), n).await?;
        }
        let socket = private_socket();
        self.station().listen_unix(bind_unix(&socket, 0o600)?);
        let mut tui = std::process::Command::new(tui_program());
        tui.arg("--attach").arg(&socket);
        if let Some(config) = &cli.station.config {
            tui.arg("--config").arg(config);
        }
        if cli.station.no_mouse {
            tui.arg("--no-mouse");
        }
        let status = tokio::task::spawn_blocking(move || tui.status()).await;
        let _ = std::fs::remove_file(&socket);
        let status = status
            .context("the TUI's waiter failed")?
            .with_context(|| {
                format!(
                    "cannot start the TUI ({}): build mech-gcs beside mech-zenoh \
                     (cargo build --release -p mech-gcs), or run `mech-zenoh serve` \
                     and attach with `mech-gcs --attach`",
                    tui_program().display()
                )
            })?;
        Ok(status.code().map_or(1, |c| u8::try_from(c).unwrap_or(1)))
    }

    /// Stops the bridge, then the station.
    async fn shutdown(self) {
        self.bridge.shutdown().await;
        self.launched.shutdown().await;
    }
}

/// A control socket for this process's TUI alone (owner only), beside the
/// station's default one.
fn private_socket() -> PathBuf {
    let name = format!("mech-zenoh-{}.sock", std::process::id());
    mech_station::default_socket().with_file_name(name)
}

/// The TUI program: `mech-gcs` next to this program if it is there (a
/// build puts both in one directory), else `mech-gcs` on the PATH.
fn tui_program() -> PathBuf {
    let beside = std::env::current_exe()
        .ok()
        .map(|exe| exe.with_file_name("mech-gcs"))
        .filter(|p| p.is_file());
    beside.unwrap_or_else(|| PathBuf::from("mech-gcs"))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Reads a configuration file as `--config` does: `[zenoh]` is this
    /// program's, the rest the station's.
    fn read(path: &Path) -> anyhow::Result<(ConfigFile, ZenohConfig)> {
        let config = ConfigFile::load(path)?;
        let zenoh = zenoh_section(&config, Some(path))?;
        Ok((config, zenoh))
    }

    #[test]
    fn the_example_configuration_reads_with_paths_beside_it() {
        let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../config/site-a.toml");
        let (config, zenoh) = read(&path).unwrap();
        zenoh.validate().unwrap();
        assert_eq!(zenoh.station, "site-a");
        assert_eq!(zenoh.route_requests, mech_zenoh::RouteRequests::Signed);
        let bridge = config.auth.keys.iter().find(|k| k.name == "zenoh").unwrap();
        assert!(bridge.file.starts_with(path.parent().unwrap()));
        assert_eq!(config.router.udp.port(), 7400);
    }

    #[test]
    fn a_bad_zenoh_section_names_itself() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("bad.toml");
        std::fs::write(&path, "[zenoh]\nstaton = \"a\"\n").unwrap();
        let e = format!("{:#}", read(&path).unwrap_err());
        assert!(e.contains("[zenoh]") && e.contains("staton"), "{e}");
        std::fs::write(&path, "[router]\nudpp = 1\n").unwrap();
        assert!(
            read(&path).is_err(),
            "the station's sections are checked too"
        );
    }
}

//! `mech-zenoh`: a ground station on the Zenoh network. It runs the same
//! station as `mech-gcs` ([`mech_gcs::station::Station`]: the TUI,
//! `--script` headless, or `serve` as a service) from the same
//! configuration file, plus its `[zenoh]` section, with a [`Bridge`]
//! beside it: its robots are published, commands and route requests come
//! in through its router, and other stations' robots are shown read-only.

use std::io::Read;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Context;
use clap::{Parser, Subcommand};
use mech_core::Gcs;
use mech_gcs::station::client::{self, AttachOptions, Attached, attach_stream};
use mech_gcs::station::serve::{self, Stop};
use mech_gcs::station::wire::Streams;
use mech_gcs::station::{Station, login_name};
use mech_gcs::{GcsConfig, logging, sim};
use mech_zenoh::{Bridge, ZenohConfig};

/// MECH ground-control station on the Zenoh network: publishes its robots
/// under mech/<station>/..., takes commands and route requests, shows other
/// stations' robots read-only.
#[derive(Debug, Parser)]
#[command(name = "mech-zenoh", version)]
struct Cli {
    /// Configuration file (TOML): mech-gcs's sections plus [zenoh].
    #[arg(long, value_name = "FILE", global = true)]
    config: Option<PathBuf>,
    /// This station's name on Zenoh (overrides zenoh.station).
    #[arg(long, value_name = "NAME", global = true)]
    station: Option<String>,
    /// Zenoh endpoint to listen on, e.g. tcp/127.0.0.1:7447 (repeatable;
    /// replaces zenoh.listen).
    #[arg(long, value_name = "ENDPOINT", global = true)]
    listen: Vec<String>,
    /// Zenoh endpoint of another station or router to connect to
    /// (repeatable; replaces zenoh.connect).
    #[arg(long, value_name = "ENDPOINT", global = true)]
    connect: Vec<String>,
    /// Start a simulated fleet of N robots (default 4); the router then
    /// listens on loopback only unless configured otherwise.
    #[arg(long, value_name = "N", num_args = 0..=1, default_missing_value = "4", global = true)]
    demo: Option<usize>,
    /// Run a command script headless ("-" for stdin): one JSON line per
    /// event and result, then the bridge's counters.
    #[arg(long, value_name = "FILE")]
    script: Option<PathBuf>,
    /// Do not capture the mouse in the TUI.
    #[arg(long)]
    no_mouse: bool,
    /// UDP endpoint of the router (overrides the configuration).
    #[arg(long, value_name = "ADDR", global = true)]
    udp: Option<SocketAddr>,
    /// TCP endpoint of the router (overrides the configuration).
    #[arg(long, value_name = "ADDR", global = true)]
    tcp: Option<SocketAddr>,
    /// The control socket of a served station (overrides [station] socket).
    #[arg(long, value_name = "PATH", global = true)]
    socket: Option<PathBuf>,
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run the station with its bridge as a service, as `mech-gcs serve`
    /// does (`mech-gcs --attach` attaches to it); stops on SIGTERM.
    Serve {
        /// Record to this MCAP file (default: rotating files in the
        /// [record] or [log] directory, as `mech-gcs serve` does).
        #[arg(long, value_name = "FILE")]
        record: Option<PathBuf>,
    },
}

fn main() -> ExitCode {
    match run(Cli::parse()) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("mech-zenoh: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    let (config, zenoh) = load(&cli)?;
    if let Some(Command::Serve { record }) = cli.command {
        let _log = logging::init(&config.log, Some("info")).context("cannot start logging")?;
        let beside = |station: Station| start_bridge(station, zenoh);
        runtime()?.block_on(serve::serve_with(config, cli.demo, record, beside))?;
        return Ok(ExitCode::SUCCESS);
    }
    let source = cli.script.as_deref().map(read_script).transpose()?;
    let stderr = source.as_ref().map(|_| "warn");
    let _log = logging::init(&config.log, stderr).context("cannot start logging")?;
    let station = Embedded {
        config,
        zenoh,
        demo: cli.demo,
    };
    let code = match source {
        Some(source) => runtime()?.block_on(station.script(&source))?,
        None => runtime()?
            .block_on(station.tui(!cli.no_mouse))
            .map(|()| 0)?,
    };
    Ok(ExitCode::from(code))
}

fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("cannot start the async runtime")
}

fn read_script(path: &Path) -> anyhow::Result<String> {
    if path.as_os_str() == "-" {
        let mut s = String::new();
        std::io::stdin()
            .read_to_string(&mut s)
            .context("cannot read the script from stdin")?;
        return Ok(s);
    }
    std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))
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
fn load(cli: &Cli) -> anyhow::Result<(GcsConfig, ZenohConfig)> {
    let (mut config, mut zenoh) = match &cli.config {
        Some(path) => read(path)?,
        None => (GcsConfig::default(), ZenohConfig::default()),
    };
    config.override_with(&mech_gcs::config::Overrides {
        demo_without_file: cli.demo.is_some() && cli.config.is_none(),
        udp: cli.udp,
        tcp: cli.tcp,
        socket: cli.socket.clone(),
    });
    if let Some(s) = &cli.station {
        zenoh.station.clone_from(s);
    }
    if !cli.listen.is_empty() {
        zenoh.listen.clone_from(&cli.listen);
    }
    if !cli.connect.is_empty() {
        zenoh.connect.clone_from(&cli.connect);
    }
    config.validate()?;
    zenoh.validate()?;
    Ok((config, zenoh))
}

/// Reads a configuration file: `[zenoh]` is this program's, the rest is
/// `mech-gcs`'s. Files it names are found next to it.
fn read(path: &Path) -> anyhow::Result<(GcsConfig, ZenohConfig)> {
    let text =
        std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mut table: toml::Table =
        toml::from_str(&text).with_context(|| format!("{}", path.display()))?;
    let mut zenoh: ZenohConfig = match table.remove("zenoh") {
        Some(section) => section
            .try_into()
            .with_context(|| format!("{}: [zenoh]", path.display()))?,
        None => ZenohConfig::default(),
    };
    let rest = toml::to_string(&table).context("re-reading the configuration")?;
    let mut config = GcsConfig::parse(&rest).with_context(|| format!("{}", path.display()))?;
    let dir = path.parent().unwrap_or(Path::new("."));
    let beside = |p: &mut PathBuf| {
        if p.is_relative() {
            *p = dir.join(&*p);
        }
    };
    config
        .auth
        .keys
        .iter_mut()
        .for_each(|k| beside(&mut k.file));
    zenoh.operator_key.as_mut().map(beside);
    zenoh.zenoh_config.as_mut().map(beside);
    Ok((config, zenoh))
}

/// A station with its bridge in this process, as the TUI or a script runs
/// it (attached in process, as `mech-gcs` does with its own station).
struct Embedded {
    config: GcsConfig,
    zenoh: ZenohConfig,
    demo: Option<usize>,
}

impl Embedded {
    /// Starts the router, the station (with the simulator) and the bridge,
    /// and attaches to the station in process.
    async fn start(&self, stream: Streams) -> anyhow::Result<(Station, Bridge, Attached)> {
        let gcs = Gcs::start(self.config.core())
            .await
            .context("cannot start the router")?;
        let bridge = match Bridge::start(&gcs, &self.zenoh).await {
            Ok(b) => b,
            Err(e) => {
                gcs.shutdown().await;
                return Err(e).context("cannot start the Zenoh bridge");
            }
        };
        let sim = Some(sim::simulator());
        let station = Station::start(gcs, &self.config.cluster, sim, &self.config.station);
        station.set_remote_routes(bridge.route_requests());
        let opts = AttachOptions {
            operator: Some(login_name()),
            key: None,
            stream,
        };
        let attached = attach_stream(station.attach_local(), opts).await?;
        Ok((station, bridge, attached))
    }

    async fn tui(self, mouse: bool) -> anyhow::Result<()> {
        let teleop = self
            .config
            .gamepad
            .teleop()
            .context("invalid [gamepad] configuration")?;
        let stream = Streams {
            snapshots: true,
            log: true,
            events: false,
        };
        let (station, bridge, attached) = self.start(stream).await?;
        let mut options = mech_gcs::ui::RunOptions {
            mouse,
            teleop,
            ..mech_gcs::ui::RunOptions::default()
        };
        if let Some(n) = self.demo {
            options.startup.push(format!("spawn {n}"));
            options.arena = Some(sim::demo_arena());
        }
        let result = mech_gcs::ui::run(attached, options).await;
        bridge.shutdown().await;
        station.shutdown().await;
        result.context("terminal error")
    }

    /// Runs `source` as `mech-gcs --attach --script` would on this station,
    /// then prints the bridge's counters as one more JSON line.
    async fn script(self, source: &str) -> anyhow::Result<u8> {
        let stream = Streams {
            snapshots: false,
            log: false,
            events: true,
        };
        let (station, bridge, mut attached) = self.start(stream).await?;
        let code = match self.demo {
            Some(n) => match serve::spawn_demo(&station, n).await {
                Ok(()) => None,
                Err(e) => {
                    eprintln!("mech-zenoh: {e:#}");
                    Some(1)
                }
            },
            None => None,
        };
        let code = match code {
            Some(c) => c,
            None => run_script(&mut attached, source).await,
        };
        let stats = serde_json::json!({"type": "zenoh", "station": bridge.station(), "stats": bridge.stats()});
        println!("{stats}");
        drop(attached);
        bridge.shutdown().await;
        station.shutdown().await;
        Ok(code)
    }
}

/// The script's exit code: 0 when every command succeeded, 130 on Ctrl-C.
async fn run_script(attached: &mut Attached, source: &str) -> u8 {
    let mut out = std::io::stdout();
    tokio::select! {
        outcome = client::run_script(attached, source, &mut out) => {
            if let mech_control::script::ScriptOutcome::Failed { error, .. } = &outcome {
                eprintln!("mech-zenoh: script failed at {error}");
            }
            outcome.exit_code() as u8
        }
        _ = tokio::signal::ctrl_c() => 130,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

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

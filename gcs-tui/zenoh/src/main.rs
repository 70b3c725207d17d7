//! `mech-zenoh`: a ground station on the Zenoh network. It runs the same
//! station as `mech-gcs` (the TUI, or `--script` headless) from the same
//! configuration file, plus its `[zenoh]` section, with a [`Bridge`]
//! attached: its robots are published, commands and route requests come in
//! through its router, and other stations' robots are shown read-only.

use std::io::Read;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::{Arc, Mutex};

use anyhow::Context;
use clap::Parser;
use mech_control::lang::Executor;
use mech_control::script::{self, Sink};
use mech_core::Gcs;
use mech_gcs::{GcsConfig, logging, sim};
use mech_zenoh::{Bridge, ZenohConfig};

/// MECH ground-control station on the Zenoh network: publishes its robots
/// under mech/<station>/..., takes commands and route requests, shows other
/// stations' robots read-only.
#[derive(Debug, Parser)]
#[command(name = "mech-zenoh", version)]
struct Cli {
    /// Configuration file (TOML): mech-gcs's sections plus [zenoh].
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// This station's name on Zenoh (overrides zenoh.station).
    #[arg(long, value_name = "NAME")]
    station: Option<String>,
    /// Zenoh endpoint to listen on, e.g. tcp/127.0.0.1:7447 (repeatable;
    /// replaces zenoh.listen).
    #[arg(long, value_name = "ENDPOINT")]
    listen: Vec<String>,
    /// Zenoh endpoint of another station or router to connect to
    /// (repeatable; replaces zenoh.connect).
    #[arg(long, value_name = "ENDPOINT")]
    connect: Vec<String>,
    /// Start a simulated fleet of N robots (default 4); the router then
    /// listens on loopback only unless configured otherwise.
    #[arg(long, value_name = "N", num_args = 0..=1, default_missing_value = "4")]
    demo: Option<usize>,
    /// Run a command script headless ("-" for stdin): one JSON line per
    /// event and result, then the bridge's counters.
    #[arg(long, value_name = "FILE")]
    script: Option<PathBuf>,
    /// Do not capture the mouse in the TUI.
    #[arg(long)]
    no_mouse: bool,
    /// UDP endpoint of the router (overrides the configuration).
    #[arg(long, value_name = "ADDR")]
    udp: Option<SocketAddr>,
    /// TCP endpoint of the router (overrides the configuration).
    #[arg(long, value_name = "ADDR")]
    tcp: Option<SocketAddr>,
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
    let source = match &cli.script {
        None => None,
        Some(p) if p.as_os_str() == "-" => {
            let mut s = String::new();
            std::io::stdin()
                .read_to_string(&mut s)
                .context("cannot read the script from stdin")?;
            Some(s)
        }
        Some(p) => Some(
            std::fs::read_to_string(p).with_context(|| format!("cannot read {}", p.display()))?,
        ),
    };
    let stderr = source.as_ref().map(|_| "warn");
    let _log = logging::init(&config.log, stderr).context("cannot start logging")?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("cannot start the async runtime")?;
    let station = Station {
        config,
        zenoh,
        demo: cli.demo,
    };
    let code = match source {
        Some(source) => runtime.block_on(station.script(&source))?,
        None => runtime.block_on(station.tui(!cli.no_mouse)).map(|()| 0)?,
    };
    Ok(ExitCode::from(code))
}

/// The configuration file's station sections and its `[zenoh]` section,
/// with the command line's overrides, checked.
fn load(cli: &Cli) -> anyhow::Result<(GcsConfig, ZenohConfig)> {
    let (mut config, mut zenoh) = match &cli.config {
        Some(path) => read(path)?,
        None => (GcsConfig::default(), ZenohConfig::default()),
    };
    if cli.demo.is_some() && cli.config.is_none() {
        // A demo fleet lives in this process: the router stays on loopback.
        config
            .router
            .udp
            .set_ip(std::net::Ipv4Addr::LOCALHOST.into());
    }
    if let Some(udp) = cli.udp {
        config.router.udp = udp;
    }
    if let Some(tcp) = cli.tcp {
        config.router.tcp = Some(tcp);
    }
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

/// A station with its bridge, as the TUI or a script runs it.
struct Station {
    config: GcsConfig,
    zenoh: ZenohConfig,
    demo: Option<usize>,
}

impl Station {
    /// Starts the router, the bridge and the executor (with the simulator
    /// and route requests to other stations).
    async fn start(&self) -> anyhow::Result<(Gcs, Bridge, Executor)> {
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
        let executor = Executor::new(gcs.clone())
            .with_clusters(&self.config.cluster)
            .with_spawner(sim::simulator())
            .with_remote_routes(bridge.route_requests());
        Ok((gcs, bridge, executor))
    }

    async fn tui(self, mouse: bool) -> anyhow::Result<()> {
        let teleop = self
            .config
            .gamepad
            .teleop()
            .context("invalid [gamepad] configuration")?;
        let (gcs, bridge, executor) = self.start().await?;
        let mut options = mech_gcs::ui::RunOptions {
            mouse,
            teleop,
            ..mech_gcs::ui::RunOptions::default()
        };
        if let Some(n) = self.demo {
            options.startup.push(format!("spawn {n}"));
            options.arena = Some(mech_gcs::ui::demo_arena());
        }
        let result = mech_gcs::ui::run(gcs.clone(), executor, options).await;
        bridge.shutdown().await;
        gcs.shutdown().await;
        result.context("terminal error")
    }

    async fn script(self, source: &str) -> anyhow::Result<u8> {
        let (gcs, bridge, mut executor) = self.start().await?;
        let sink: Sink = Arc::new(Mutex::new(Box::new(std::io::stdout())));
        let code = async {
            if let Some(n) = self.demo {
                if let Err(e) = executor.execute_line(&format!("spawn {n}")).await {
                    eprintln!("mech-zenoh: --demo {n}: {}", e.message);
                    return 1;
                }
            }
            tokio::select! {
                outcome = script::run(&gcs, &mut executor, source, sink) => {
                    if let script::ScriptOutcome::Failed { error, .. } = &outcome {
                        eprintln!("mech-zenoh: script failed at {error}");
                    }
                    outcome.exit_code() as u8
                }
                _ = tokio::signal::ctrl_c() => 130,
            }
        }
        .await;
        let stats = serde_json::json!({"type": "zenoh", "station": bridge.station(), "stats": bridge.stats()});
        println!("{stats}");
        executor.shutdown().await;
        bridge.shutdown().await;
        gcs.shutdown().await;
        Ok(code)
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
        assert!(read(&path).is_err(), "the station's sections are checked too");
    }
}

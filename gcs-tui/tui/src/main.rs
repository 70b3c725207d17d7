//! `mech-gcs`: the ground-control station binary. Parses the command line,
//! loads the configuration, starts logging and the router, then either runs
//! a script headless (`--script`) or the interactive station.

use std::io::Read;
use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::{Arc, Mutex};

use anyhow::Context;
use clap::{Parser, Subcommand};
use mech_control::lang::Executor;
use mech_control::script::{self, Sink};
use mech_core::Gcs;
use mech_gcs::station::Station;
use mech_gcs::station::client::{self, Address, AttachOptions, attach, attach_stream};
use mech_gcs::station::wire::Streams;
use mech_gcs::{GcsConfig, logging, replay, sim};

/// MECH ground-control station: robot cards, braille map, waypoints, live
/// controller routing.
#[derive(Debug, Parser)]
#[command(name = "mech-gcs", version)]
struct Cli {
    /// Configuration file (TOML); built-in defaults otherwise.
    #[arg(long, value_name = "FILE", global = true)]
    config: Option<PathBuf>,
    /// Start a simulated fleet of N robots (default 4). Without --config or
    /// --udp the router then listens on loopback only (127.0.0.1:7400).
    /// The TUI then always runs its own station.
    #[arg(long, value_name = "N", num_args = 0..=1, default_missing_value = "4", global = true)]
    demo: Option<usize>,
    /// Attach to a running station (`mech-gcs serve`): its control socket
    /// by default, or ADDR: a socket path, or HOST:PORT over TCP (with
    /// --key). Without --attach, the TUI attaches to the local station if
    /// one runs and starts its own otherwise.
    #[arg(long, value_name = "ADDR", num_args = 0..=1, default_missing_value = "")]
    attach: Option<String>,
    /// Operator key file, to attach over TCP.
    #[arg(long, value_name = "FILE")]
    key: Option<PathBuf>,
    /// The operator name the station logs your commands under (default:
    /// your login; over TCP, the key's name).
    #[arg(long, value_name = "NAME")]
    operator: Option<String>,
    /// Run a command script headless ("-" for stdin); prints one JSON line
    /// per event and result, exits 0 only if every command succeeded.
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
    /// The control socket of the station (overrides [station] socket).
    #[arg(long, value_name = "PATH", global = true)]
    socket: Option<PathBuf>,
    /// Record everything the router sees to this MCAP file (Foxglove and
    /// Lichtblick open it; `mech-gcs replay` replays it). `serve` records
    /// into its log directory by default, in rotating files.
    #[arg(long, value_name = "FILE.mcap", global = true)]
    record: Option<PathBuf>,
    /// Serve the Foxglove live view here (e.g. 127.0.0.1:8765): Foxglove
    /// or Lichtblick connect to ws://ADDR and show the fleet live, on the
    /// topics of a recording. Needs a build with the `foxglove` feature.
    #[arg(long, value_name = "ADDR", global = true)]
    foxglove: Option<SocketAddr>,
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Run the station as a service, without a terminal: router, fleet
    /// model, controllers and missions keep running while TUIs attach and
    /// detach (`mech-gcs` attaches to it). Stops on SIGTERM, telling every
    /// client and robot; ready and watchdog notifications for systemd.
    Serve,
    /// Replay a recording without a router: nothing is sent to any robot.
    /// Shows it in the TUI (`:pause`, `:play`, `:speed X`, `:seek T`); with
    /// --script, prints it as the JSON lines of `--script`; with --info,
    /// what it holds (exit code 1 if the file is damaged: what could be
    /// read is printed or shown first).
    Replay {
        /// The recording (`--record`, `record start`, or `serve`'s).
        file: PathBuf,
        /// Print the recording as `--script` JSON lines.
        #[arg(long, conflicts_with = "info")]
        script: bool,
        /// Print what the recording holds: span, robots, topics.
        #[arg(long)]
        info: bool,
    },
    /// Make a new key for a robot, controller, operator or e-stop device,
    /// in a file only its owner can read. List it in the station's
    /// `[auth]` section and give the file to its holder (a robot's
    /// `[auth] key`).
    Keygen {
        /// Who signs with it: the robot's, controller's, operator's or
        /// device's name.
        name: String,
        /// Where to write it (default: NAME.key). An existing file is never
        /// overwritten.
        #[arg(long, value_name = "FILE")]
        out: Option<PathBuf>,
    },
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("mech-gcs: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    if let Some(Command::Keygen { name, out }) = &cli.command {
        return keygen(name, out.clone());
    }
    if let Some(Command::Replay { file, script, info }) = &cli.command {
        let show = if *script {
            replay::Show::Script
        } else if *info {
            replay::Show::Info
        } else {
            let _log =
                logging::init(&load_config(&cli)?.log, None).context("cannot start logging")?;
            let options = mech_gcs::ui::RunOptions {
                mouse: !cli.no_mouse,
                gamepads: false,
                ..mech_gcs::ui::RunOptions::default()
            };
            return runtime()?.block_on(replay::run_tui(file, cli.config.as_deref(), options));
        };
        return replay::run(file, show, cli.config.as_deref());
    }
    let config = load_config(&cli)?;
    if matches!(cli.command, Some(Command::Serve)) {
        if cli.script.is_some() || cli.attach.is_some() {
            anyhow::bail!(
                "serve runs the station: attach to it with --attach, --script from another mech-gcs"
            );
        }
        let _log = logging::init(&config.log, Some("info")).context("cannot start logging")?;
        let serve = mech_gcs::station::serve::serve(config, cli.demo, cli.record.clone());
        runtime()?.block_on(serve)?;
        return Ok(ExitCode::SUCCESS);
    }
    if let Some(path) = &cli.script {
        let source = read_script(path)?;
        let _log = logging::init(&config.log, Some("warn")).context("cannot start logging")?;
        let code = runtime()?.block_on(async {
            match attach_address(&cli, &config) {
                Some(addr) => {
                    run_attached_script(&addr, attach_options(&cli, true)?, &source).await
                }
                None => run_script(config, cli.demo, &source, cli.record.clone()).await,
            }
        })?;
        return Ok(ExitCode::from(code));
    }
    let _log = logging::init(&config.log, None).context("cannot start logging")?;
    runtime()?.block_on(run_tui(config, &cli))?;
    Ok(ExitCode::SUCCESS)
}

/// The configuration file (or the defaults) with the command line's
/// overrides applied, checked.
fn load_config(cli: &Cli) -> anyhow::Result<GcsConfig> {
    let mut config = match &cli.config {
        Some(path) => GcsConfig::load(path)?,
        None => GcsConfig::default(),
    };
    config.override_with(&mech_gcs::config::Overrides {
        demo_without_file: cli.demo.is_some() && cli.config.is_none(),
        udp: cli.udp,
        tcp: cli.tcp,
        socket: cli.socket.clone(),
    });
    if let Some(addr) = cli.foxglove {
        config.foxglove.addr = Some(addr);
    }
    config.validate()?;
    Ok(config)
}

fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("cannot start the async runtime")
}

fn read_script(path: &std::path::Path) -> anyhow::Result<String> {
    if path.as_os_str() == "-" {
        let mut s = String::new();
        std::io::stdin()
            .read_to_string(&mut s)
            .context("cannot read the script from stdin")?;
        return Ok(s);
    }
    std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))
}

/// Where `--attach` points: the station's control socket when given no
/// address.
fn attach_address(cli: &Cli, config: &GcsConfig) -> Option<Address> {
    match cli.attach.as_deref()? {
        "" => Some(Address::Unix(config.station.socket_path())),
        a => Some(Address::parse(a)),
    }
}

/// Who attaches (and, for a script, with the events streamed; for the
/// TUI, with snapshots and the event log).
fn attach_options(cli: &Cli, script: bool) -> anyhow::Result<AttachOptions> {
    let key = match &cli.key {
        Some(path) => Some(mech_core::auth::KeyFile::load(path)?.into()),
        None => None,
    };
    let stream = Streams {
        snapshots: !script,
        log: !script,
        events: script,
    };
    Ok(AttachOptions {
        operator: cli.operator.clone(),
        key,
        stream,
    })
}

/// `mech-gcs keygen NAME`: writes a new key and says how to use it.
fn keygen(name: &str, out: Option<PathBuf>) -> anyhow::Result<ExitCode> {
    let path = out.unwrap_or_else(|| PathBuf::from(format!("{name}.key")));
    let key = mech_core::auth::KeyFile::generate(name, &path)?;
    println!(
        "wrote {} (key id {:08x}, readable only by you)\n\n\
         station (gcs.toml), with role robot, controller, operator or estop:\n\n\
         [[auth.keys]]\nrole = \"robot\"\nname = {name:?}\nfile = {:?}\n\n\
         robot (mech-agent config):\n\n[auth]\nkey = {:?}",
        path.display(),
        key.key.id(),
        path.display().to_string(),
        path.display().to_string(),
    );
    Ok(ExitCode::SUCCESS)
}

/// The interactive station. `--demo N` runs its own station with N
/// simulated robots; `--attach` attaches to a running one; otherwise the
/// TUI attaches to the local station if one runs and starts its own if
/// not.
async fn run_tui(config: GcsConfig, cli: &Cli) -> anyhow::Result<()> {
    tracing::info!(version = env!("CARGO_PKG_VERSION"), "mech-gcs starting");
    let teleop = config
        .gamepad
        .teleop()
        .context("invalid [gamepad] configuration")?;
    let mut options = mech_gcs::ui::RunOptions {
        mouse: !cli.no_mouse,
        teleop,
        ..mech_gcs::ui::RunOptions::default()
    };
    let opts = attach_options(cli, false)?;
    if cli.demo.is_none() {
        let (addr, explicit) = match attach_address(cli, &config) {
            Some(a) => (a, true),
            None => (Address::Unix(config.station.socket_path()), false),
        };
        match attach(&addr, opts.clone()).await {
            Ok(attached) => {
                tracing::info!(station = %addr, "attached");
                options.attached = Some(addr.short());
                return mech_gcs::ui::run(attached, options)
                    .await
                    .context("terminal error");
            }
            Err(e) if explicit => return Err(e.into()),
            Err(e) => {
                tracing::info!(station = %addr, error = %e, "no station to attach to: starting one")
            }
        }
    }
    if let Some(n) = cli.demo {
        options.startup.push(format!("spawn {n}"));
        options.arena = Some(mech_gcs::sim::demo_arena());
    }
    let gcs = start(&config, cli.record.clone()).await?;
    let live = mech_gcs::foxglove::Live::start(&gcs, &config.foxglove).await?;
    let station = Station::start(
        gcs,
        &config.cluster,
        Some(sim::simulator()),
        &config.station,
    );
    station.set_record_dir(record_dir(&config));
    let attached = attach_stream(station.attach_local(), opts).await?;
    let result = mech_gcs::ui::run(attached, options).await;
    live.stop();
    station.shutdown().await;
    tracing::info!("mech-gcs stopped");
    result.context("terminal error")
}

/// `--attach ADDR --script FILE`: the script runs on a running station.
async fn run_attached_script(
    addr: &Address,
    opts: AttachOptions,
    source: &str,
) -> anyhow::Result<u8> {
    let mut attached = attach(addr, opts).await?;
    let mut out = std::io::stdout();
    let outcome = tokio::select! {
        o = client::run_script(&mut attached, source, &mut out) => o,
        _ = tokio::signal::ctrl_c() => {
            eprintln!("mech-gcs: interrupted");
            return Ok(130);
        }
    };
    match &outcome {
        script::ScriptOutcome::Passed { .. } => {}
        script::ScriptOutcome::Invalid(e) => eprintln!("mech-gcs: invalid script: {e}"),
        script::ScriptOutcome::Failed { error, .. } => {
            eprintln!("mech-gcs: script failed at {error}")
        }
    }
    Ok(outcome.exit_code() as u8)
}

/// Starts the station, recording to `record` if given.
async fn start(config: &GcsConfig, record: Option<PathBuf>) -> anyhow::Result<Gcs> {
    let gcs = Gcs::start(config.core())
        .await
        .context("cannot start the router")?;
    if let Some(file) = record {
        gcs.start_recording(mech_core::RecordTarget::File(file))
            .context("cannot start recording")?;
    }
    Ok(gcs)
}

/// The command-language executor of a station, naming where its commands
/// come from (`tui`, `script`) in recordings.
fn executor(gcs: &Gcs, config: &GcsConfig, source: &str) -> Executor {
    let mut executor = Executor::new(gcs.clone())
        .with_clusters(&config.cluster)
        .with_spawner(sim::simulator())
        .with_source(source);
    if let Some(dir) = record_dir(config) {
        executor = executor.with_record_dir(dir);
    }
    executor
}

/// Where `record start` without a file name records.
fn record_dir(config: &GcsConfig) -> Option<PathBuf> {
    config.record.dir.clone().or_else(|| config.log.dir.clone())
}

async fn run_script(
    config: GcsConfig,
    demo: Option<usize>,
    source: &str,
    record: Option<PathBuf>,
) -> anyhow::Result<u8> {
    tracing::info!(
        version = env!("CARGO_PKG_VERSION"),
        "mech-gcs starting (script mode)"
    );
    let gcs = start(&config, record).await?;
    let mut executor = executor(&gcs, &config, "script");
    let sink: Sink = Arc::new(Mutex::new(Box::new(std::io::stdout())));
    let code = async {
        if let Some(n) = demo {
            if let Err(e) = executor.execute_line(&format!("spawn {n}")).await {
                eprintln!("mech-gcs: --demo {n}: {}", e.message);
                return 1;
            }
        }
        tokio::select! {
            outcome = script::run(&gcs, &mut executor, source, sink) => {
                match &outcome {
                    script::ScriptOutcome::Passed { .. } => {}
                    script::ScriptOutcome::Invalid(e) => eprintln!("mech-gcs: invalid script: {e}"),
                    script::ScriptOutcome::Failed { error, .. } => eprintln!("mech-gcs: script failed at {error}"),
                }
                outcome.exit_code() as u8
            }
            _ = tokio::signal::ctrl_c() => {
                eprintln!("mech-gcs: interrupted");
                130
            }
        }
    }
    .await;
    executor.shutdown().await;
    gcs.shutdown().await;
    tracing::info!(code, "mech-gcs stopped");
    Ok(code)
}

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
use mech_gcs::{GcsConfig, logging, replay, sim};

/// MECH ground-control station: robot cards, braille map, waypoints, live
/// controller routing.
#[derive(Debug, Parser)]
#[command(name = "mech-gcs", version)]
struct Cli {
    /// Configuration file (TOML); built-in defaults otherwise.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// Start a simulated fleet of N robots (default 4). Without --config or
    /// --udp the router then listens on loopback only (127.0.0.1:7400).
    #[arg(long, value_name = "N", num_args = 0..=1, default_missing_value = "4")]
    demo: Option<usize>,
    /// Run a command script headless ("-" for stdin); prints one JSON line
    /// per event and result, exits 0 only if every command succeeded.
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
    /// Record everything the router sees to this MCAP file (Foxglove and
    /// Lichtblick open it; `mech-gcs replay` replays it).
    #[arg(long, value_name = "FILE.mcap")]
    record: Option<PathBuf>,
    #[command(subcommand)]
    command: Option<Command>,
}

#[derive(Debug, Subcommand)]
enum Command {
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
    /// Replay a recording without a router: nothing is sent to any robot.
    /// Prints what it holds; with --script, prints it as the JSON lines of
    /// `--script` (exit code 1 if the file is damaged: what could be read
    /// is printed first).
    Replay {
        /// The recording (`--record`, `record start`, or `serve`'s).
        file: PathBuf,
        /// Print the recording as `--script` JSON lines.
        #[arg(long)]
        script: bool,
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
    if let Some(Command::Replay { file, script }) = &cli.command {
        return replay::run(file, *script, cli.config.as_deref());
    }
    let mut config = match &cli.config {
        Some(path) => GcsConfig::load(path)?,
        None => GcsConfig::default(),
    };
    if cli.demo.is_some() && cli.config.is_none() {
        // A demo fleet lives in this process: nothing on the network needs
        // to reach the router, so it is not exposed beyond this machine.
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
    config.validate()?;
    let Some(script_path) = cli.script else {
        let _log = logging::init(&config.log, None).context("cannot start logging")?;
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .enable_all()
            .build()
            .context("cannot start the async runtime")?;
        runtime.block_on(run_tui(config, cli.demo, cli.no_mouse, cli.record))?;
        return Ok(ExitCode::SUCCESS);
    };
    let source = if script_path.as_os_str() == "-" {
        let mut s = String::new();
        std::io::stdin()
            .read_to_string(&mut s)
            .context("cannot read the script from stdin")?;
        s
    } else {
        std::fs::read_to_string(&script_path)
            .with_context(|| format!("cannot read {}", script_path.display()))?
    };
    let _log = logging::init(&config.log, Some("warn")).context("cannot start logging")?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("cannot start the async runtime")?;
    let code = runtime.block_on(run_script(config, cli.demo, &source, cli.record))?;
    Ok(ExitCode::from(code))
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

/// The interactive station; `--demo N` spawns N simulated robots first.
async fn run_tui(
    config: GcsConfig,
    demo: Option<usize>,
    no_mouse: bool,
    record: Option<PathBuf>,
) -> anyhow::Result<()> {
    tracing::info!(version = env!("CARGO_PKG_VERSION"), "mech-gcs starting");
    let teleop = config
        .gamepad
        .teleop()
        .context("invalid [gamepad] configuration")?;
    let gcs = start(&config, record).await?;
    let executor = executor(&gcs, &config, "tui");
    let mut options = mech_gcs::ui::RunOptions {
        mouse: !no_mouse,
        teleop,
        ..mech_gcs::ui::RunOptions::default()
    };
    if let Some(n) = demo {
        options.startup.push(format!("spawn {n}"));
        options.arena = Some(mech_gcs::ui::demo_arena());
    }
    let result = mech_gcs::ui::run(gcs.clone(), executor, options).await;
    gcs.shutdown().await;
    tracing::info!("mech-gcs stopped");
    result.context("terminal error")
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
    if let Some(dir) = config.record.dir.clone().or_else(|| config.log.dir.clone()) {
        executor = executor.with_record_dir(dir);
    }
    executor
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

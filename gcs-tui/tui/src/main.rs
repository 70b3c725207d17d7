//! `mech-gcs`: the ground-control station binary. Parses the command line,
//! loads the configuration and starts logging, then runs the station as a
//! service (`serve`), a script headless (`--script`), a recording
//! (`replay`) or the TUI, attached to a running station or to one it
//! starts in this process.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::{Parser, Subcommand};
use mech_gcs::gamepad::{TeleopConfig, teleop_config};
use mech_station::cli::{self, Args, runtime};
use mech_station::client::{Address, AttachOptions, attach, attach_stream};
use mech_station::replay;
use mech_station::wire::Streams;
use mech_station::{ConfigFile, Launched, Recording, logging, serve};

/// The program's name in its messages.
const PROGRAM: &str = "mech-gcs";

/// MECH ground-control station: robot cards, braille map, waypoints, live
/// controller routing.
#[derive(Debug, Parser)]
#[command(name = "mech-gcs", version)]
struct Cli {
    #[command(flatten)]
    station: Args,
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
    /// Serve the Foxglove live view here (e.g. 127.0.0.1:8765): Foxglove
    /// or Lichtblick connect to ws://ADDR and show the fleet live, on the
    /// topics of a recording. For the station this process runs: the
    /// TUI's, `serve`'s, and `--script`'s without `--attach`. Needs a build
    /// with the `foxglove` feature.
    #[arg(long, value_name = "ADDR", global = true)]
    foxglove: Option<SocketAddr>,
    /// Check the configuration (with the command line's overrides) and
    /// everything the station would need to start with it (keys when it
    /// listens beyond loopback, each key file readable only by its owner),
    /// say what is wrong, and exit: 0 when it would start, 1 when not.
    #[arg(long)]
    check: bool,
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
            eprintln!("{PROGRAM}: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    if let Some(Command::Keygen { name, out }) = &cli.command {
        return keygen(name, out.clone());
    }
    let (config, teleop) = load_config(&cli)?;
    if cli.check {
        return Ok(check(&cli, &config));
    }
    if let Some(Command::Replay { file, script, info }) = &cli.command {
        let show = if *script {
            replay::Show::Script
        } else if *info {
            replay::Show::Info
        } else {
            let _log = logging::init(&config.log, None).context("cannot start logging")?;
            let options = mech_gcs::ui::RunOptions {
                mouse: !cli.station.no_mouse,
                gamepads: false,
                ..mech_gcs::ui::RunOptions::default()
            };
            let run = mech_gcs::replay::run_tui(file, config.fleet, options);
            return runtime()?.block_on(run);
        };
        return replay::run(file, show, config.fleet);
    }
    if matches!(cli.command, Some(Command::Serve)) {
        if cli.station.script.is_some() || cli.attach.is_some() {
            anyhow::bail!(
                "serve runs the station: attach to it with --attach, --script from another mech-gcs"
            );
        }
        let _log = logging::init(&config.log, Some("info")).context("cannot start logging")?;
        let serve = serve::serve(config, cli.station.demo, cli.station.record.clone());
        runtime()?.block_on(serve)?;
        return Ok(ExitCode::SUCCESS);
    }
    if let Some(source) = cli.station.read_script()? {
        let _log = logging::init(&config.log, Some("warn")).context("cannot start logging")?;
        let code = runtime()?.block_on(async {
            match attach_address(&cli, &config) {
                Some(addr) => {
                    if cli.foxglove.is_some() {
                        anyhow::bail!(
                            "--foxglove serves the live view of a station this process runs; \
                             an attached station serves its own (mech-gcs serve --foxglove ADDR)"
                        );
                    }
                    let mut attached = attach(&addr, attach_options(&cli, true)?).await?;
                    Ok(cli::run_script(PROGRAM, &mut attached, &source).await)
                }
                None => {
                    let (demo, record) = (cli.station.demo, cli.station.record.clone());
                    cli::run_script_in_process(PROGRAM, config, demo, &source, record).await
                }
            }
        })?;
        return Ok(ExitCode::from(code));
    }
    let _log = logging::init(&config.log, None).context("cannot start logging")?;
    runtime()?.block_on(run_tui(config, teleop, &cli))?;
    Ok(ExitCode::SUCCESS)
}

/// The configuration file (or the defaults) with the command line's
/// overrides applied, checked, and the teleop settings of its `[gamepad]`
/// section.
fn load_config(cli: &Cli) -> anyhow::Result<(ConfigFile, TeleopConfig)> {
    let mut config = cli.station.load()?;
    if let Some(addr) = cli.foxglove {
        config.foxglove.addr = Some(addr);
        config.validate()?;
    }
    let teleop = teleop_config(&config)?;
    Ok((config, teleop))
}

/// `--check`: one line when the station would start with `config`; else
/// one line per problem, exit code 1.
fn check(cli: &Cli, config: &ConfigFile) -> ExitCode {
    let name = cli
        .station
        .config
        .as_ref()
        .map_or("built-in defaults".into(), |p| p.display().to_string());
    let problems = config.core().start_problems();
    if problems.is_empty() {
        println!("{name}: ok");
        return ExitCode::SUCCESS;
    }
    println!("{name}: the configuration is valid, but the station would not start:");
    for p in &problems {
        println!("  {p}");
    }
    ExitCode::from(1)
}

/// Where `--attach` points: the station's control socket when given no
/// address.
fn attach_address(cli: &Cli, config: &ConfigFile) -> Option<Address> {
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
async fn run_tui(config: ConfigFile, teleop: TeleopConfig, cli: &Cli) -> anyhow::Result<()> {
    tracing::info!(version = env!("CARGO_PKG_VERSION"), "mech-gcs starting");
    let mut options = mech_gcs::ui::RunOptions {
        mouse: !cli.station.no_mouse,
        teleop,
        ..mech_gcs::ui::RunOptions::default()
    };
    let opts = attach_options(cli, false)?;
    if cli.station.demo.is_none() {
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
    if let Some(n) = cli.station.demo {
        options.startup.push(format!("spawn {n}"));
        options.arena = Some(mech_station::demo_arena());
    }
    let recording = cli
        .station
        .record
        .clone()
        .map_or(Recording::Off, Recording::File);
    let launched = Launched::start(&config, recording).await?;
    let result = match attach_stream(launched.station().attach_local(), opts).await {
        Ok(attached) => mech_gcs::ui::run(attached, options)
            .await
            .context("terminal error"),
        Err(e) => Err(e.into()),
    };
    launched.shutdown().await;
    tracing::info!("mech-gcs stopped");
    result
}

//! `mech-agent`: runs on each robot.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::Parser;
use mech_agent::config::RobotConfig;
use mech_agent::launch::{self, Overrides};
use mech_agent::preflight;

/// MECH robot agent: obeys the routed controller, reports telemetry, stops
/// when the link or the controller goes quiet.
#[derive(Debug, Parser)]
#[command(name = "mech-agent", version)]
struct Cli {
    /// Robot configuration file (TOML); see config/agents/ for examples.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Simulate the vehicle (kinematics, actuator limits, UWB-like noise)
    /// instead of driving hardware.
    #[arg(long)]
    sim: bool,
    /// Router address, overriding the config (default 127.0.0.1:7400).
    #[arg(long, value_name = "HOST:PORT")]
    router: Option<String>,
    /// Robot name, overriding the config.
    #[arg(long)]
    name: Option<String>,
    /// MAVLink link to the autopilot, overriding `[autopilot] link`
    /// (`udpin:0.0.0.0:14541` for a second simulator, `serial:/dev/ttyACM0:921600`).
    #[arg(long, value_name = "LINK")]
    autopilot: Option<String>,
    /// Check the config and the key, open every device the config names
    /// (GPIO, serial ports) without driving it, say what could not be
    /// opened, and exit: 0 when all is well, 1 when a device could not be
    /// opened (with --sim, no device is opened).
    #[arg(long)]
    check: bool,
}

/// Config used by `--sim` without `--config`: a simulated diff-drive robot.
const DEFAULT_SIM: &str = "name = \"sim_robot\"\n[platform]\nkind = \"diff-drive\"\ntrack_width = 0.15\nmax_wheel_speed = 0.5\n[position]\nkind = \"sim\"\n[sim]\nx = 1.0\ny = 1.0\n";

fn main() -> ExitCode {
    let cli = Cli::parse();
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        // Colour codes only for a terminal, never into a redirected log.
        .with_ansi(std::io::IsTerminal::is_terminal(&std::io::stderr()))
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                // DDS (a ROS 2 base) logs its discovery at info: errors
                // only, as the bridge does; RUST_LOG=rustdds=info shows it.
                .unwrap_or_else(|_| {
                    tracing_subscriber::EnvFilter::new("info,rustdds=error,ros2_client=error")
                }),
        )
        .init();
    match run(cli) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("mech-agent: {e:#}");
            ExitCode::from(2)
        }
    }
}

fn run(cli: Cli) -> anyhow::Result<ExitCode> {
    let mut config = match &cli.config {
        Some(path) => RobotConfig::load(path)?,
        None if cli.sim => RobotConfig::parse(DEFAULT_SIM, "<built-in sim config>")?,
        None => anyhow::bail!("give --config robot.toml, or --sim for a simulated robot"),
    };
    if let Some(name) = cli.name {
        mech_agent::config::check_name(&name).map_err(|e| anyhow::anyhow!("--name: {e}"))?;
        config.name = toml::Spanned::new(0..0, name);
    }
    if let Some(link) = &cli.autopilot {
        config
            .set_autopilot_link(link)
            .map_err(|e| anyhow::anyhow!("--autopilot {link}: {e}"))?;
    }
    let router = cli
        .router
        .as_deref()
        .map(|r| {
            r.parse::<SocketAddr>()
                .with_context(|| format!("--router {r}: expected HOST:PORT, e.g. 127.0.0.1:7400"))
        })
        .transpose()?;
    if cli.check {
        return check(&config, cli.config.as_deref(), cli.sim);
    }
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the runtime")?;
    runtime.block_on(async move {
        let (stop, shutdown) = tokio::sync::watch::channel(false);
        let mut terminate =
            tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate())
                .context("installing the SIGTERM handler")?;
        tokio::spawn(async move {
            // Either signal stops the robot cleanly: actuators zeroed, Bye sent.
            tokio::select! {
                _ = tokio::signal::ctrl_c() => {}
                _ = terminate.recv() => {}
            }
            let _ = stop.send(true);
        });
        let counters = launch::run(
            config,
            Overrides {
                sim: cli.sim,
                router,
            },
            shutdown,
        )
        .await
        .context("running the agent")?;
        report(&counters);
        Ok(ExitCode::SUCCESS)
    })
}

/// `--check`: the config (already loaded), the key, then the devices.
/// Prints one line when all is well; otherwise one line per device that
/// could not be opened, and nothing else.
fn check(
    config: &RobotConfig,
    path: Option<&std::path::Path>,
    sim: bool,
) -> anyhow::Result<ExitCode> {
    config
        .key()
        .map_err(|e| anyhow::anyhow!("[auth] key: {e}"))?;
    let name = path.map_or("built-in sim config".into(), |p| p.display().to_string());
    let unopened = if sim {
        Vec::new()
    } else {
        preflight::check(config, &mut preflight::HostDevices)
    };
    if unopened.is_empty() {
        let devices = if sim {
            " (simulated: no device opened)"
        } else {
            ""
        };
        println!("{name}: ok{devices}");
        return Ok(ExitCode::SUCCESS);
    }
    println!("{name}: the config is valid, but this machine cannot open:");
    for u in &unopened {
        println!("  {u}");
    }
    Ok(ExitCode::from(1))
}

/// The agent's counters, as one line on stdout when it stops (for logs
/// and the fault-injection tests).
fn report(c: &mech_agent::machine::Counters) {
    println!(
        "{{\"agent_counters\":{{\"commands\":{},\"failsafe_trips\":{},\"stale_commands\":{},\"stale_estops\":{},\"not_routed\":{},\"ignored_estopped\":{},\"bad_messages\":{},\"reregistered\":{},\"tripped_at_us\":{},\"estopped_at_us\":{}}}}}",
        c.commands,
        c.failsafe_trips,
        c.stale_commands,
        c.stale_estops,
        c.not_routed,
        c.ignored_estopped,
        c.bad_messages,
        c.reregistered,
        c.tripped_at_us,
        c.estopped_at_us
    );
}

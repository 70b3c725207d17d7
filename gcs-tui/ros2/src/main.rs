//! `mech-ros2`: joins a running MECH station as an external controller and
//! bridges its robots to ROS 2 over DDS (`docs/ros2.md`). Logs to stderr;
//! on SIGINT or SIGTERM it unsubscribes and prints its counters as one
//! JSON line on stdout.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Context;
use clap::Parser;
use mech_ros2::config::{CmdVelType, EStopService};
use mech_ros2::{Bridge, Ros2Config};

/// Bridge a MECH station's robots to ROS 2: odometry, TF, battery,
/// diagnostics and markers out; cmd_vel, goal poses and e-stop engage in.
#[derive(Debug, Parser)]
#[command(name = "mech-ros2", version)]
struct Cli {
    /// Configuration file (TOML) with a [ros2] section; may be the
    /// station's own gcs.toml.
    #[arg(long, value_name = "FILE")]
    config: Option<PathBuf>,
    /// The station's router, UDP (overrides ros2.router).
    #[arg(long, value_name = "ADDR")]
    router: Option<SocketAddr>,
    /// Controller key file (overrides ros2.key).
    #[arg(long, value_name = "FILE")]
    key: Option<PathBuf>,
    /// E-stop key file (overrides ros2.estop_key).
    #[arg(long, value_name = "FILE")]
    estop_key: Option<PathBuf>,
    /// Sender name when unsigned (overrides ros2.name).
    #[arg(long, value_name = "NAME")]
    name: Option<String>,
    /// DDS domain (overrides ros2.domain_id and ROS_DOMAIN_ID).
    #[arg(long, value_name = "N")]
    domain: Option<u16>,
    /// cmd_vel type: twist or stamped (overrides ros2.cmd_vel).
    #[arg(long, value_name = "TYPE", value_parser = ["twist", "stamped"])]
    cmd_vel: Option<String>,
    /// The /mech/estop service's DDS mapping: enhanced (Fast DDS, ROS 2's
    /// default), cyclone (rmw_cyclonedds), basic, or off (overrides
    /// ros2.estop_service).
    #[arg(long, value_name = "MAPPING", value_parser = ["enhanced", "cyclone", "basic", "off"])]
    estop_service: Option<String>,
    /// Seconds between summary lines in the log (0: none).
    #[arg(long, value_name = "S")]
    summary_every: Option<f64>,
    /// Attach to the station (its control socket, or tcp:HOST:PORT with
    /// --attach-key) for each robot's link quality and the arena
    /// (overrides ros2.attach).
    #[arg(long, value_name = "ADDR")]
    attach: Option<String>,
    /// Operator key file for attaching over TCP (overrides
    /// ros2.attach_key).
    #[arg(long, value_name = "FILE")]
    attach_key: Option<PathBuf>,
}

fn main() -> ExitCode {
    use std::io::IsTerminal;
    tracing_subscriber::fmt()
        .with_writer(std::io::stderr)
        .with_ansi(std::io::stderr().is_terminal())
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| "info,rustdds=error,ros2_client=error".into()),
        )
        .init();
    match run(Cli::parse()) {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("mech-ros2: {e:#}");
            ExitCode::FAILURE
        }
    }
}

fn config(cli: &Cli) -> anyhow::Result<Ros2Config> {
    let mut c = match &cli.config {
        Some(path) => Ros2Config::load(path).map_err(anyhow::Error::msg)?,
        None => Ros2Config::default(),
    };
    if let Some(r) = cli.router {
        c.router = r;
    }
    if let Some(k) = &cli.key {
        c.key = Some(k.clone());
    }
    if let Some(k) = &cli.estop_key {
        c.estop_key = Some(k.clone());
    }
    if let Some(n) = &cli.name {
        c.name = n.clone();
    }
    if let Some(d) = cli.domain {
        c.domain_id = Some(d);
    }
    if let Some(t) = &cli.cmd_vel {
        c.cmd_vel = if t == "stamped" {
            CmdVelType::Stamped
        } else {
            CmdVelType::Twist
        };
    }
    if let Some(m) = &cli.estop_service {
        c.estop_service = match m.as_str() {
            "cyclone" => EStopService::Cyclone,
            "basic" => EStopService::Basic,
            "off" => EStopService::Off,
            _ => EStopService::Enhanced,
        };
    }
    if let Some(s) = cli.summary_every {
        c.summary_every = s;
    }
    if let Some(a) = &cli.attach {
        c.attach = Some(a.clone());
    }
    if let Some(k) = &cli.attach_key {
        c.attach_key = Some(k.clone());
    }
    c.check().map_err(anyhow::Error::msg)?;
    Ok(c)
}

fn run(cli: Cli) -> anyhow::Result<()> {
    let config = config(&cli)?;
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("cannot start the runtime")?;
    runtime.block_on(async {
        let bridge = Bridge::start(config).await?;
        let stats = bridge.run(stop_signal()).await;
        let line = serde_json::json!({"type": "ros2", "stats": stats});
        println!("{line}");
        Ok(())
    })
}

/// Resolves on SIGINT or SIGTERM.
async fn stop_signal() {
    use tokio::signal::unix::{SignalKind, signal};
    let Ok(mut term) = signal(SignalKind::terminate()) else {
        let _ = tokio::signal::ctrl_c().await;
        return;
    };
    tokio::select! {
        _ = term.recv() => {}
        _ = tokio::signal::ctrl_c() => {}
    }
}

//! The command line both station programs share (`mech-gcs`,
//! `mech-zenoh`): the flags that say which configuration, router
//! endpoints and control socket a station runs with, whether it simulates
//! robots, records, or runs a script ([`Args`], flattened into each
//! program's own command line), and what the programs do with them: load
//! the configuration, read the script, run it to its end or to Ctrl-C and
//! say how it ended.

use std::io::Read;
use std::net::SocketAddr;
use std::path::{Path, PathBuf};

use std::sync::{Arc, Mutex};

use anyhow::Context;
use mech_control::lang::Executor;
use mech_control::script::{self, ScriptOutcome, Sink};
use mech_core::{Gcs, RecordTarget};

use crate::client::{self, Attached};
use crate::config::{ConfigFile, Overrides};

/// The flags of a station program (`#[command(flatten)]` it).
#[derive(Debug, Clone, Default, clap::Args)]
pub struct Args {
    /// Configuration file (TOML); built-in defaults otherwise.
    #[arg(long, value_name = "FILE", global = true)]
    pub config: Option<PathBuf>,
    /// Start a simulated fleet of N robots (default 4). Without --config or
    /// --udp the router then listens on loopback only (127.0.0.1:7400),
    /// and the TUI runs its own station.
    #[arg(long, value_name = "N", num_args = 0..=1, default_missing_value = "4", global = true)]
    pub demo: Option<usize>,
    /// Run a command script headless ("-" for stdin); prints one JSON line
    /// per event and result, exits 0 only if every command succeeded.
    #[arg(long, value_name = "FILE")]
    pub script: Option<PathBuf>,
    /// Do not capture the mouse in the TUI.
    #[arg(long)]
    pub no_mouse: bool,
    /// UDP endpoint of the router (overrides the configuration).
    #[arg(long, value_name = "ADDR", global = true)]
    pub udp: Option<SocketAddr>,
    /// TCP endpoint of the router (overrides the configuration).
    #[arg(long, value_name = "ADDR", global = true)]
    pub tcp: Option<SocketAddr>,
    /// The control socket of the station (overrides `[station] socket`).
    #[arg(long, value_name = "PATH", global = true)]
    pub socket: Option<PathBuf>,
    /// Record everything the router sees to this MCAP file (Foxglove and
    /// Lichtblick open it; `mech-gcs replay` replays it). `serve` records
    /// into its log directory by default, in rotating files.
    #[arg(long, value_name = "FILE.mcap", global = true)]
    pub record: Option<PathBuf>,
}

impl Args {
    /// What the command line overrides in the configuration file.
    pub fn overrides(&self) -> Overrides {
        Overrides {
            demo_without_file: self.demo.is_some() && self.config.is_none(),
            demo: self.demo.is_some(),
            udp: self.udp,
            tcp: self.tcp,
            socket: self.socket.clone(),
        }
    }

    /// The configuration file (or the defaults) with the command line's
    /// overrides applied, checked.
    pub fn load(&self) -> anyhow::Result<ConfigFile> {
        let mut config = match &self.config {
            Some(path) => ConfigFile::load(path)?,
            None => ConfigFile::default(),
        };
        config.override_with(&self.overrides());
        config.validate()?;
        Ok(config)
    }

    /// The script of `--script`, read from its file or stdin (`-`); `None`
    /// without `--script`.
    pub fn read_script(&self) -> anyhow::Result<Option<String>> {
        self.script.as_deref().map(read_script).transpose()
    }
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

/// The async runtime a station program runs on: two worker threads.
pub fn runtime() -> anyhow::Result<tokio::runtime::Runtime> {
    tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .context("cannot start the async runtime")
}

/// Runs `source` on an attached station (one that streams events),
/// printing `--script`'s JSON lines on stdout, until it ends or Ctrl-C;
/// its exit code, see [`script_exit_code`].
pub async fn run_script(program: &str, attached: &mut Attached, source: &str) -> u8 {
    let mut out = std::io::stdout();
    script_exit_code(program, client::run_script(attached, source, &mut out)).await
}

/// Runs `source` on a station core started for it in this process (`--script`
/// without a station to attach to), with `demo` simulated robots first,
/// recording to `record` if given and the Foxglove live view when
/// `[foxglove]` (or `--foxglove`) asks for one, printing `--script`'s JSON lines on
/// stdout; the summary line adds the router's counters and the recording.
/// Its exit code, see [`script_exit_code`].
pub async fn run_script_in_process(
    program: &str,
    config: ConfigFile,
    demo: Option<usize>,
    source: &str,
    record: Option<PathBuf>,
) -> anyhow::Result<u8> {
    tracing::info!(
        version = env!("CARGO_PKG_VERSION"),
        "{program} starting (script mode)"
    );
    let gcs = Gcs::start(config.core())
        .await
        .context("cannot start the router")?;
    let live = match crate::foxglove::Live::start(&gcs, &config.foxglove).await {
        Ok(live) => live,
        Err(e) => {
            gcs.shutdown().await;
            return Err(e);
        }
    };
    if let Some(view) = live.describe() {
        eprintln!("{program}: {view}");
    }
    if let Some(file) = record {
        if let Err(e) = gcs.start_recording(RecordTarget::File(file)) {
            live.stop();
            gcs.shutdown().await;
            return Err(e).context("cannot start recording");
        }
    }
    let mut executor = Executor::new(gcs.clone())
        .with_clusters(&config.cluster)
        .with_source("script");
    if let Some(simulator) = crate::simulator() {
        executor = executor.with_spawner(simulator);
    }
    if let Some(dir) = config.record_dir() {
        executor = executor.with_record_dir(dir);
    }
    let sink: Sink = Arc::new(Mutex::new(Box::new(std::io::stdout())));
    let code = async {
        if let Some(n) = demo {
            if let Err(e) = executor.execute_line(&format!("spawn {n}")).await {
                eprintln!("{program}: --demo {n}: {}", e.message);
                return 1;
            }
        }
        script_exit_code(program, script::run(&gcs, &mut executor, source, sink)).await
    }
    .await;
    executor.shutdown().await;
    live.stop();
    gcs.shutdown().await;
    tracing::info!(code, "{program} stopped");
    Ok(code)
}

/// Awaits a script run and says on stderr why it failed, if it did. The
/// exit code: 0 when every command succeeded, 1 when one failed, 2 for a
/// script that does not parse, 130 on Ctrl-C (the run is abandoned).
pub async fn script_exit_code(
    program: &str,
    run: impl std::future::Future<Output = ScriptOutcome>,
) -> u8 {
    tokio::select! {
        outcome = run => {
            match &outcome {
                ScriptOutcome::Passed { .. } => {}
                ScriptOutcome::Invalid(e) => eprintln!("{program}: invalid script: {e}"),
                ScriptOutcome::Failed { error, .. } => {
                    eprintln!("{program}: script failed at {error}")
                }
            }
            outcome.exit_code() as u8
        }
        _ = tokio::signal::ctrl_c() => {
            eprintln!("{program}: interrupted");
            130
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use clap::Parser;

    /// A program with the shared flags and one of its own.
    #[derive(Debug, Parser)]
    struct Program {
        #[command(flatten)]
        station: Args,
        #[arg(long)]
        own: bool,
        #[command(subcommand)]
        command: Option<Sub>,
    }

    #[derive(Debug, clap::Subcommand)]
    enum Sub {
        Serve,
    }

    #[test]
    fn the_shared_flags_parse_before_and_after_a_subcommand() {
        let p = Program::parse_from([
            "p",
            "--demo",
            "--udp",
            "127.0.0.1:0",
            "serve",
            "--record",
            "a.mcap",
            "--socket",
            "s.sock",
        ]);
        assert_eq!(p.station.demo, Some(4), "--demo alone is 4 robots");
        assert_eq!(p.station.udp, Some(SocketAddr::from(([127, 0, 0, 1], 0))));
        assert_eq!(p.station.record.as_deref(), Some(Path::new("a.mcap")));
        assert_eq!(p.station.socket.as_deref(), Some(Path::new("s.sock")));
        assert!(matches!(p.command, Some(Sub::Serve)));
        assert!(!p.own);
        let p = Program::parse_from(["p", "--demo", "7", "--no-mouse", "--script", "-", "--own"]);
        assert_eq!(p.station.demo, Some(7));
        assert!(p.station.no_mouse && p.own);
        assert_eq!(p.station.script.as_deref(), Some(Path::new("-")));
    }

    #[test]
    fn the_overrides_apply_over_the_file_and_are_checked() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("gcs.toml");
        std::fs::write(&file, "[router]\nudp = \"0.0.0.0:7600\"\n").unwrap();
        let mut args = Args {
            config: Some(file.clone()),
            demo: Some(2),
            ..Args::default()
        };
        let config = args.load().unwrap();
        assert_eq!(
            config.router.udp,
            SocketAddr::from(([0, 0, 0, 0], 7600)),
            "a file's address is kept with --demo"
        );
        args.config = None;
        let config = args.load().unwrap();
        assert!(
            config.router.udp.ip().is_loopback(),
            "--demo without a file stays on this machine"
        );
        args.tcp = Some(SocketAddr::from(([127, 0, 0, 1], 7701)));
        args.socket = Some(dir.path().join("s.sock"));
        let config = args.load().unwrap();
        assert_eq!(config.router.tcp, args.tcp);
        assert_eq!(config.station.socket_path(), dir.path().join("s.sock"));
        std::fs::write(&file, "[station]\nsnapshot_rate = 0\n").unwrap();
        args.config = Some(file);
        let e = args.load().unwrap_err().to_string();
        assert!(e.contains("snapshot_rate"), "{e}");
    }

    #[test]
    fn a_script_is_read_from_its_file() {
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("s.mech");
        std::fs::write(&file, "status\n").unwrap();
        let mut args = Args::default();
        assert!(args.read_script().unwrap().is_none());
        args.script = Some(file);
        assert_eq!(args.read_script().unwrap().as_deref(), Some("status\n"));
        args.script = Some(dir.path().join("missing.mech"));
        let e = args.read_script().unwrap_err().to_string();
        assert!(e.contains("missing.mech"), "{e}");
    }

    #[tokio::test]
    async fn a_script_run_says_how_it_ended_in_its_exit_code() {
        let passed = async { ScriptOutcome::Passed { commands: 1 } };
        assert_eq!(script_exit_code("t", passed).await, 0);
        let invalid = mech_control::lang::parse_script("route robot_1 \"").unwrap_err();
        let invalid = async { ScriptOutcome::Invalid(invalid) };
        assert_eq!(script_exit_code("t", invalid).await, 2);
        let at = mech_control::lang::Span { line: 2, column: 1 };
        let error = mech_control::lang::LangError::new(at, "expected connected");
        let failed = async { ScriptOutcome::Failed { error, commands: 2 } };
        assert_eq!(script_exit_code("t", failed).await, 1);
    }
}

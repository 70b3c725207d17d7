//! Every example robot config runs under `--sim` as its header says: the
//! command its header gives (`mech-agent --config config/agents/X.toml
//! --sim ...`, run from the repository), pointed at a station of the
//! test's, registers and sends telemetry. A config whose header gives no
//! such command fails the test.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use mech_e2e::harness::controller::Controller;
use mech_e2e::harness::station::{self, Station};
use mech_e2e::harness::{Killed, poll};

/// The repository's root.
fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

/// The arguments of the header's `mech-agent ... --sim` command (the
/// leading comment lines), `--router` pointed at `router`.
fn sim_command(config: &Path, router: &str) -> Vec<String> {
    let text = std::fs::read_to_string(config).expect("the example");
    let line = text
        .lines()
        .take_while(|l| l.starts_with('#'))
        .find(|l| l.contains("mech-agent --config") && l.contains("--sim"))
        .unwrap_or_else(|| {
            panic!(
                "{}: the header says how to run it under --sim",
                config.display()
            )
        });
    let (_, command) = line.split_once("mech-agent").unwrap_or_default();
    let mut args: Vec<String> = command
        .split_whitespace()
        .map(|w| w.trim_matches('`').to_string())
        .collect();
    match args.iter().position(|a| a == "--router") {
        Some(i) => {
            assert_eq!(
                args.get(i + 1).map(String::as_str),
                Some("127.0.0.1:7400"),
                "{line}: a station on the same machine"
            );
            args[i + 1] = router.to_string();
        }
        // Without --router the config's own must be the local station.
        None => {
            assert!(
                text.contains("router = \"127.0.0.1:7400\"") || !text.contains("router ="),
                "{}: {line} reaches no local station",
                config.display()
            );
            args.extend(["--router".to_string(), router.to_string()]);
        }
    }
    let given = args
        .iter()
        .position(|a| a == "--config")
        .and_then(|i| args.get(i + 1))
        .map(|p| root().join(p));
    assert_eq!(
        given.and_then(|p| p.canonicalize().ok()),
        config.canonicalize().ok(),
        "{line}: runs this very file"
    );
    args
}

#[test]
fn every_example_config_runs_under_sim_as_its_header_says() {
    let mut examples: Vec<PathBuf> = std::fs::read_dir(root().join("config/agents"))
        .expect("config/agents")
        .map(|e| e.expect("entry").path())
        .filter(|p| p.extension().is_some_and(|x| x == "toml"))
        .collect();
    examples.sort();
    assert!(examples.len() >= 6, "{examples:?}");
    for config in examples {
        let text = std::fs::read_to_string(&config).expect("the example");
        let name = text
            .lines()
            .find_map(|l| l.strip_prefix("name = \""))
            .and_then(|l| l.split('"').next())
            .expect("the example names its robot")
            .to_string();
        let dir = tempfile::tempdir().expect("temp dir");
        let port = station::free_port();
        let gcs = Station::start(
            &station::config(dir.path(), port, ""),
            &format!("wait connected {name} 30s\nlog connected\nsleep 60s\n"),
            dir.path(),
        );
        let router = format!("127.0.0.1:{port}");
        let log = dir.path().join("agent.log");
        let mut agent = Killed(Some(
            Command::new(mech_e2e::binary("mech-agent"))
                .args(sim_command(&config, &router))
                .current_dir(root())
                .stdout(Stdio::null())
                .stderr(std::fs::File::create(&log).map_or_else(|_| Stdio::null(), Stdio::from))
                .spawn()
                .expect("mech-agent starts"),
        ));
        gcs.wait(Duration::from_secs(30), |l| {
            l.json["type"] == "result" && l.json["summary"] == "connected"
        })
        .unwrap_or_else(|| {
            panic!(
                "{}: {name} never connected ({}): {:#?}\n{}",
                config.display(),
                agent.state(),
                gcs.tail(),
                std::fs::read_to_string(&log).unwrap_or_default()
            )
        });
        let ctl = Controller::start(router.parse().expect("addr"), &[&name], "ext/t", 0.0);
        poll(Duration::from_secs(30), || {
            ctl.samples().iter().any(|s| s.robot == name).then_some(())
        })
        .unwrap_or_else(|| panic!("{}: no telemetry from {name}", config.display()));
        agent.kill();
    }
}

//! The `mech-agent` binary: config checking and error exit codes.
#![allow(clippy::unwrap_used)]

use std::process::Command;

fn agent() -> Command {
    Command::new(env!("CARGO_BIN_EXE_mech-agent"))
}

#[test]
fn example_configs_check_ok() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/agents");
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        let out = agent()
            .arg("--config")
            .arg(&path)
            .arg("--check")
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}: {}",
            path.display(),
            String::from_utf8_lossy(&out.stderr)
        );
    }
}

#[test]
fn bad_config_exits_2_with_file_line_and_expectation() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("robot.toml");
    std::fs::write(&path, "name = \"r1\"\n[platform]\nkind = \"diff-drive\"\ntrack_width = \"wide\"\nmax_wheel_speed = 0.5\n").unwrap();
    let out = agent()
        .arg("--config")
        .arg(&path)
        .arg("--check")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("robot.toml:") && err.contains("track_width") || err.contains("expected"),
        "{err}"
    );
    let out = agent()
        .args(["--sim", "--router", "nowhere", "--check"])
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("expected HOST:PORT"));
    let out = agent().output().unwrap();
    assert_eq!(out.status.code(), Some(2), "no config and no --sim");
}

#[test]
fn the_autopilot_link_is_changed_from_the_command_line_and_checked() {
    let px4 = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../config/agents/px4-quadcopter.toml");
    let run = |config: &std::path::Path, link: &str| {
        agent()
            .arg("--config")
            .arg(config)
            .args(["--autopilot", link, "--check"])
            .output()
            .unwrap()
    };
    assert!(run(&px4, "udpin:0.0.0.0:14541").status.success());
    let out = run(&px4, "com3");
    assert_eq!(out.status.code(), Some(2));
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains("--autopilot com3") && err.contains("udpin:"),
        "{err}"
    );
    let kiwi =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/agents/sim-kiwi.toml");
    let out = run(&kiwi, "udpin:0.0.0.0:14541");
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("no [autopilot] section"));
}

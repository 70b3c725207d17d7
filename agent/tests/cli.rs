//! The `mech-agent` binary: config checking and error exit codes.
#![allow(clippy::unwrap_used)]

use std::process::Command;

fn agent() -> Command {
    Command::new(env!("CARGO_BIN_EXE_mech-agent"))
}

/// Every example config is valid: `--check` passes, or (on a machine
/// without the robot's devices) exits 1 naming only the devices it could
/// not open, one line each.
#[test]
fn example_configs_check_ok_or_name_only_their_devices() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../config/agents");
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        let out = agent()
            .arg("--config")
            .arg(&path)
            .arg("--check")
            .output()
            .unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout);
        let stderr = String::from_utf8_lossy(&out.stderr);
        match out.status.code() {
            Some(0) => assert!(stdout.ends_with(": ok\n"), "{}: {stdout}", path.display()),
            Some(1) => {
                let mut lines = stdout.lines();
                let head = lines.next().unwrap_or_default();
                assert!(head.ends_with("this machine cannot open:"), "{head}");
                for line in lines {
                    assert!(
                        line.starts_with("  GPIO ") || line.starts_with("  serial port "),
                        "{}: {line}",
                        path.display()
                    );
                }
                assert!(stderr.is_empty(), "{}: {stderr}", path.display());
            }
            code => panic!("{}: exit {code:?}: {stderr}", path.display()),
        }
        // Simulated, the same config opens no device.
        let sim = agent()
            .arg("--config")
            .arg(&path)
            .args(["--check", "--sim"])
            .output()
            .unwrap();
        assert!(sim.status.success(), "{}: {stderr}", path.display());
    }
}

/// A Pi robot's config checked on a machine that is not a Pi (and has no
/// Pozyx tag plugged in) says exactly what it could not open: the L298's
/// GPIO pins and the tag's serial port, and nothing else.
#[test]
fn a_pi_config_off_a_pi_names_the_gpio_and_the_serial_port() {
    let pi = std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../config/agents/pi-l298-diff-drive.toml");
    let out = agent()
        .arg("--config")
        .arg(&pi)
        .arg("--check")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(1));
    let stdout = String::from_utf8_lossy(&out.stdout);
    let lines: Vec<&str> = stdout.lines().collect();
    assert_eq!(lines.len(), 3, "{stdout}");
    assert!(lines[1].starts_with("  GPIO 6, 12, 20, 13, 19, 26 (actuators: L298): "));
    assert_eq!(
        lines[2],
        "  serial port /dev/ttyACM0 at 115200 baud (position: Pozyx): No such file or directory"
    );
    assert!(
        out.stderr.is_empty(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
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

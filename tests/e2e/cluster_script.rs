//! A cluster mission run headless: four `mech-agent --sim` processes (two
//! differential drives, two kiwis, UWB-like position noise) and
//! `mech-gcs --script tests/scripts/cluster_mission.mech`, over real UDP
//! sockets. Checks the exit code and the JSON lines the script prints.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::station::free_port;

/// Kills the agents however the test ends.
struct Agents(Vec<Child>);

impl Drop for Agents {
    fn drop(&mut self) {
        for c in &mut self.0 {
            let _ = c.kill();
            let _ = c.wait();
        }
    }
}

fn agent_config(dir: &Path, name: &str, platform: &str, x: f64, y: f64, seed: u64) -> PathBuf {
    let geometry = match platform {
        "kiwi" => "radius = 0.1\nmax_wheel_speed = 0.5",
        _ => "track_width = 0.15\nmax_wheel_speed = 0.5",
    };
    let text = format!(
        "name = \"{name}\"\n[platform]\nkind = \"{platform}\"\n{geometry}\n[position]\nkind = \"sim\"\n\
         [sim]\nx = {x}\ny = {y}\nheading = 0.0\nnoise = true\nseed = {seed}\n"
    );
    let path = dir.join(format!("{name}.toml"));
    std::fs::write(&path, text).expect("write agent config");
    path
}

/// Two differential drives and two kiwis, simulated with position noise,
/// registering with the router at `router`.
fn start_agents(dir: &Path, router: &str) -> Agents {
    let robots = [
        ("robot_1", "diff-drive", 1.0, 0.8),
        ("robot_2", "kiwi", 1.8, 0.8),
        ("robot_3", "diff-drive", 1.0, 1.6),
        ("robot_4", "kiwi", 1.8, 1.6),
    ];
    let mut agents = Agents(Vec::new());
    for (i, (name, platform, x, y)) in robots.iter().enumerate() {
        let config = agent_config(dir, name, platform, *x, *y, 11 + i as u64);
        let child = Command::new(mech_e2e::binary("mech-agent"))
            .arg("--config")
            .arg(&config)
            .args(["--sim", "--router", router])
            .env("RUST_LOG", "warn")
            .stdout(Stdio::null())
            .stderr(Stdio::null())
            .spawn()
            .expect("mech-agent starts");
        agents.0.push(child);
    }
    agents
}

/// Runs `mech-gcs --script` on the router at `router` until it exits
/// (at most 240 s).
fn run_script(script: &Path, router: &str, dir: &Path) -> std::process::Output {
    let started = Instant::now();
    let mut gcs = Command::new(mech_e2e::binary("mech-gcs"))
        .arg("--script")
        .arg(script)
        .args(["--udp", router, "--tcp", "127.0.0.1:0"])
        .env("XDG_STATE_HOME", dir)
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("mech-gcs starts");
    let deadline = started + Duration::from_secs(240);
    while gcs.try_wait().expect("poll mech-gcs").is_none() {
        if Instant::now() > deadline {
            let _ = gcs.kill();
            panic!("the script did not finish within 240 s");
        }
        std::thread::sleep(Duration::from_millis(100));
    }
    gcs.wait_with_output().expect("mech-gcs output")
}

#[test]
fn cluster_mission_script_passes_headless() {
    let dir = std::env::temp_dir().join(format!("mech-e2e-cluster-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let port = free_port();
    let router = format!("127.0.0.1:{port}");
    let agents = start_agents(&dir, &router);

    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("scripts/cluster_mission.mech");
    let out = run_script(&script, &router, &dir);
    drop(agents);
    let _ = std::fs::remove_dir_all(&dir);
    let stdout = String::from_utf8_lossy(&out.stdout);
    let stderr = String::from_utf8_lossy(&out.stderr);

    let lines: Vec<serde_json::Value> = stdout
        .lines()
        .map(|l| serde_json::from_str(l).unwrap_or_else(|e| panic!("not JSON ({e}): {l}")))
        .collect();
    let results: Vec<&serde_json::Value> = lines.iter().filter(|v| v["type"] == "result").collect();
    for r in &results {
        if r["command"]
            .as_str()
            .is_some_and(|c| c.starts_with("cluster-"))
        {
            println!(
                "{}: {}",
                r["command"],
                r["summary"].as_str().or(r["error"].as_str()).unwrap_or("")
            );
        }
    }
    assert_eq!(
        out.status.code(),
        Some(0),
        "script passed; stderr: {stderr}\nstdout: {stdout}"
    );
    let summary = lines.last().expect("a summary line");
    assert_eq!(summary["type"], "summary");
    assert_eq!(summary["ok"], true);
    assert_eq!(summary["connected_robots"], 4);
    let expected = std::fs::read_to_string(&script)
        .expect("script readable")
        .lines()
        .filter(|l| !l.trim().is_empty() && !l.trim_start().starts_with('#'))
        .count();
    assert_eq!(results.len(), expected, "every command ran");
    assert!(results.iter().all(|r| r["ok"] == true));
    let finished = results
        .iter()
        .find(|r| r["command"] == "cluster-wait c1 120s")
        .expect("the mission wait ran");
    assert!(
        finished["summary"]
            .as_str()
            .is_some_and(|s| s.contains("finished its waypoints"))
    );
    // Route changes to and from the cluster channel reached every robot:
    // each acknowledged fleet/c1, and none after it. A robot may confirm
    // a route more than once: an agent that registers again (its Hello
    // repeated while the station was slow to welcome it, or the router
    // unheard for its timeout on a loaded machine) must confirm its route
    // anew, and the router reports that acknowledgement too.
    for robot in ["robot_1", "robot_2", "robot_3", "robot_4"] {
        let acks: Vec<&str> = lines
            .iter()
            .filter(|v| v["event"] == "route_acked" && v["robot"] == robot)
            .filter_map(|v| v["channel"].as_str())
            .collect();
        let to_cluster = acks.iter().position(|c| *c == "fleet/c1");
        assert!(
            to_cluster.is_some_and(|i| acks[i..].contains(&"none")),
            "{robot} acknowledged fleet/c1, then none: {acks:?}"
        );
    }
}

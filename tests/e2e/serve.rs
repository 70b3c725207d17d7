//! The station as a service, end to end: `mech-gcs serve` with two
//! `mech-agent --sim` processes, TUIs attached in tmux and killed the ways
//! operators lose them (kill -9, the tmux session closing as an SSH drop
//! does), scripts attached to the same station, and a clean SIGTERM.

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use crate::tmux::{Tmux, card_position, card_status};

/// A running `mech-gcs serve` and its simulated robots, stopped on drop.
struct Service {
    station: Child,
    agents: Vec<Child>,
    dir: PathBuf,
    socket: PathBuf,
}

impl Service {
    /// `mech-gcs serve` on loopback with `robots` simulated agents, each
    /// its own `mech-agent --sim` process.
    fn start(tag: &str, robots: usize) -> Service {
        Service::start_with(tag, robots, &[])
    }

    /// [`Service::start`] with extra environment for the station.
    fn start_with(tag: &str, robots: usize, env: &[(&str, &str)]) -> Service {
        let dir = std::env::temp_dir().join(format!("mech-e2e-serve-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("temp dir");
        let socket = dir.join("gcs.sock");
        let mut station = Command::new(mech_e2e::binary("mech-gcs"))
            .args([
                "serve",
                "--udp",
                "127.0.0.1:0",
                "--tcp",
                "127.0.0.1:0",
                "--socket",
            ])
            .arg(&socket)
            .env("XDG_STATE_HOME", &dir)
            .envs(env.iter().copied())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("mech-gcs serve starts");
        let router = ready_router(&mut station);
        let agents = (1..=robots)
            .map(|i| {
                let log = std::fs::File::create(dir.join(format!("robot_{i}.log"))).expect("log");
                Command::new(mech_e2e::binary("mech-agent"))
                    .args([
                        "--sim",
                        "--router",
                        &router,
                        "--name",
                        &format!("robot_{i}"),
                    ])
                    .env("RUST_LOG", "info")
                    .stdout(Stdio::null())
                    .stderr(log)
                    .spawn()
                    .expect("mech-agent starts")
            })
            .collect();
        Service {
            station,
            agents,
            dir,
            socket,
        }
    }

    /// Runs a script attached to the station; returns its JSON lines and
    /// whether it passed.
    fn script(&self, source: &str) -> (bool, String) {
        let attach: [&std::ffi::OsStr; 2] = ["--attach".as_ref(), self.socket.as_ref()];
        mech_e2e::run_script(&attach, source, &self.dir)
    }

    /// A TUI attached to the station in a new tmux session (the TUI is the
    /// pane's process, so the pane's pid is the TUI's).
    fn tui(&self, name: &str) -> Tmux {
        self.tui_with(name, "--attach")
    }

    /// A TUI started with `how` and the station's socket: `--attach`, or
    /// `--socket` (no --attach: it attaches when a station runs there).
    fn tui_with(&self, name: &str, how: &str) -> Tmux {
        let tmux = Tmux {
            socket: format!("mech-e2e-serve-{name}-{}", std::process::id()),
            session: name.into(),
            state: self.dir.join(format!("tmux-{name}")),
        };
        std::fs::create_dir_all(&tmux.state).expect("tmux state dir");
        let cmd = format!(
            "exec env XDG_STATE_HOME={} {} {how} {}",
            tmux.state.display(),
            mech_e2e::binary("mech-gcs").display(),
            self.socket.display()
        );
        let out = tmux.run(&[
            "new-session",
            "-d",
            "-s",
            name,
            "-x",
            "160",
            "-y",
            "48",
            &cmd,
        ]);
        assert!(out.status.success(), "tmux new-session: {out:?}");
        tmux.wait_for(
            "both robots on the attached TUI, which says it is attached",
            Duration::from_secs(20),
            |s| s.contains("robots 2 (2 ok") && s.contains("│ attached "),
        );
        tmux
    }

    fn alive(&mut self) -> bool {
        matches!(self.station.try_wait(), Ok(None))
    }
}

impl Drop for Service {
    fn drop(&mut self) {
        for a in &mut self.agents {
            let _ = a.kill();
            let _ = a.wait();
        }
        let _ = self.station.kill();
        let _ = self.station.wait();
        let _ = std::fs::remove_dir_all(&self.dir);
    }
}

/// Reads the serve's ready line ("mech-gcs serving: router on ADDR ...")
/// and returns the router's address.
fn ready_router(station: &mut Child) -> String {
    let out = station.stdout.take().expect("stdout piped");
    let mut lines = BufReader::new(out).lines();
    let line = lines
        .next()
        .and_then(Result::ok)
        .expect("mech-gcs serve prints a ready line");
    // Keep draining stdout so the station never blocks on it.
    std::thread::spawn(move || for _ in lines {});
    line.split("router on ")
        .nth(1)
        .and_then(|rest| rest.split_whitespace().next())
        .unwrap_or_else(|| panic!("no router address in {line:?}"))
        .to_string()
}

/// The TUI's process id: the tmux pane's.
fn pane_pid(tmux: &Tmux) -> String {
    let out = tmux.run(&["display-message", "-p", "-t", &tmux.session, "#{pane_pid}"]);
    String::from_utf8_lossy(&out.stdout).trim().to_string()
}

fn tmux_missing() -> bool {
    if Command::new("tmux").arg("-V").output().is_err() {
        println!("skipped: tmux is not installed");
        return true;
    }
    false
}

/// Types a command line into a TUI.
fn command(tmux: &Tmux, line: &str) {
    tmux.keys(&["Escape", ":"]);
    tmux.literal(line);
    tmux.keys(&["Enter"]);
}

#[test]
fn a_mission_outlives_its_tui_killed_and_a_new_tui_shows_it_arrived() {
    if tmux_missing() {
        return;
    }
    let mut service = Service::start("kill", 2);
    let first = service.tui("first");
    let screen = first.screen();
    let (x, y) = card_position(&screen, "robot_1").expect("robot_1 on its card");
    // A mission 1 m away (several seconds at the simulator's speed).
    command(&first, &format!("waypoint robot_1 {:.2},{y:.2}", x + 1.0));
    command(&first, "send robot_1");
    command(&first, "route robot_1 wp/gcs");
    first.wait_for("robot_1 on its way", Duration::from_secs(15), |s| {
        card_status(s, "robot_1").contains("wp/gcs✓")
            && card_position(s, "robot_1").is_some_and(|(x1, _)| x1 > x + 0.1)
    });

    // The operator's TUI dies mid-mission.
    let pid = pane_pid(&first);
    let killed = Command::new("kill")
        .args(["-9", &pid])
        .status()
        .expect("kill");
    assert!(killed.success(), "kill -9 {pid}");
    drop(first);
    assert!(service.alive(), "the station outlives its TUI");

    // The robot finishes on its own...
    let (ok, out) = service.script(
        "wait arrived robot_1 40s\nexpect near robot_1 {x},{y} 0.2\n"
            .replace("{x}", &format!("{:.2}", x + 1.0))
            .replace("{y}", &format!("{y:.2}"))
            .as_str(),
    );
    assert!(ok, "robot_1 arrived without its TUI:\n{out}");
    // ...and a new TUI shows it arrived, on the route it was given.
    let second = service.tui("second");
    let screen = second.wait_for("robot_1 arrived", Duration::from_secs(10), |s| {
        card_status(s, "robot_1").contains("arrived")
    });
    assert!(
        card_status(&screen, "robot_1").contains("wp/gcs✓"),
        "the route is untouched:\n{screen}"
    );
    second.keys(&["q"]);
}

#[test]
fn two_tuis_see_one_fleet_and_a_route_change_in_one_shows_in_the_other() {
    if tmux_missing() {
        return;
    }
    let service = Service::start("two", 2);
    let a = service.tui("a");
    // Without --attach, a TUI finds the running station by its socket.
    let b = service.tui_with("b", "--socket");
    // The line typed first; the clock starts with its Enter.
    a.keys(&["Escape", ":"]);
    a.literal("route robot_2 joy/e2e");
    a.wait_for("the typed line", Duration::from_secs(5), |s| {
        s.contains(":route robot_2 joy/e2e")
    });
    a.keys(&["Enter"]);
    let sent = Instant::now();
    // Poll b's screen as fast as tmux answers, to time the change.
    let seen = loop {
        if card_status(&b.screen(), "robot_2").contains("joy/e2e") {
            break sent.elapsed();
        }
        assert!(
            sent.elapsed() < Duration::from_secs(5),
            "b never shows a's route:\n{}",
            b.screen()
        );
    };
    println!(
        "route change entered in one TUI, on the other's screen after {:.0} ms (tmux key delivery and screen capture included)",
        seen.as_secs_f64() * 1e3
    );
    // Both TUIs log who did it.
    b.wait_for(
        "a's command in b's event log",
        Duration::from_secs(5),
        |s| s.contains("> route robot_2 joy/e2e"),
    );
    a.keys(&["q"]);
    b.keys(&["q"]);
}

#[test]
fn closing_the_terminal_of_an_attached_tui_leaves_station_routes_and_robots_alone() {
    if tmux_missing() {
        return;
    }
    let mut service = Service::start("hup", 2);
    let tui = service.tui("ssh");
    command(&tui, "route robot_1 joy/held");
    tui.wait_for("the route", Duration::from_secs(10), |s| {
        card_status(s, "robot_1").contains("joy/held✓")
    });
    // The SSH connection drops: the session and its terminal go away.
    let out = tui.run(&["kill-session", "-t", &tui.session]);
    assert!(out.status.success());
    drop(tui);
    std::thread::sleep(Duration::from_millis(500));
    assert!(service.alive(), "the station outlives the terminal");
    let (ok, out) = service.script(
        "expect route robot_1 joy/held\nexpect link robot_1 connected\nexpect link robot_2 connected\nexpect route robot_2 none\n",
    );
    assert!(ok, "routes and robots untouched:\n{out}");
}

#[test]
fn sigterm_tells_every_robot_and_removes_the_socket() {
    let mut service = Service::start("term", 2);
    let (ok, out) = service.script("wait robots 2 20s\n");
    assert!(ok, "{out}");
    let pid = service.station.id().to_string();
    let status = Command::new("kill")
        .args(["-TERM", &pid])
        .status()
        .expect("kill");
    assert!(status.success());
    let start = Instant::now();
    let exit = loop {
        if let Ok(Some(s)) = service.station.try_wait() {
            break s;
        }
        assert!(
            start.elapsed() < Duration::from_secs(10),
            "serve stops on SIGTERM"
        );
        std::thread::sleep(Duration::from_millis(50));
    };
    assert!(exit.success(), "a clean stop: {exit:?}");
    assert!(!service.socket.exists(), "the socket is removed");
    // It recorded, by default, into its log directory; the file replays.
    let recordings: Vec<PathBuf> = std::fs::read_dir(service.dir.join("mech"))
        .expect("the log directory")
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "mcap"))
        .collect();
    assert_eq!(recordings.len(), 1, "{recordings:?}");
    let replay = Command::new(mech_e2e::binary("mech-gcs"))
        .arg("replay")
        .arg(&recordings[0])
        .arg("--script")
        .output()
        .expect("replay runs");
    let lines = String::from_utf8_lossy(&replay.stdout);
    assert!(replay.status.success(), "{lines}");
    assert!(
        lines.contains(r#""event":"registered""#) && lines.contains("robot_2"),
        "{lines}"
    );
    // Each robot heard the station go (not just its silence).
    for i in 1..=2 {
        let log = service.dir.join(format!("robot_{i}.log"));
        let told = wait_for_text(&log, "router is stopping", Duration::from_secs(5));
        assert!(told, "robot_{i} was told; its log:\n{}", read(&log));
    }
}

#[test]
fn systemd_hears_ready_watchdog_and_stopping() {
    use std::os::unix::net::UnixDatagram;
    let dir = std::env::temp_dir().join(format!("mech-e2e-notify-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("temp dir");
    let notify = dir.join("notify.sock");
    let systemd = UnixDatagram::bind(&notify).expect("a notify socket");
    systemd
        .set_read_timeout(Some(Duration::from_secs(10)))
        .expect("timeout");
    let path = notify.to_string_lossy().into_owned();
    let mut service = Service::start_with(
        "notify",
        0,
        &[
            ("NOTIFY_SOCKET", path.as_str()),
            ("WATCHDOG_USEC", "200000"),
        ],
    );
    let mut heard = String::new();
    let mut buf = [0u8; 4096];
    let start = Instant::now();
    while heard.matches("WATCHDOG=1").count() < 3 {
        let n = systemd.recv(&mut buf).expect("a notification within 10 s");
        heard.push_str(&String::from_utf8_lossy(&buf[..n]));
        heard.push('\n');
        assert!(start.elapsed() < Duration::from_secs(10), "{heard}");
    }
    assert!(heard.contains("READY=1"), "{heard}");
    assert!(heard.contains("STATUS=mech-gcs serving"), "{heard}");
    let pid = service.station.id().to_string();
    assert!(
        Command::new("kill")
            .args(["-TERM", &pid])
            .status()
            .expect("kill")
            .success()
    );
    loop {
        let n = systemd.recv(&mut buf).expect("STOPPING=1 within 10 s");
        if String::from_utf8_lossy(&buf[..n]).contains("STOPPING=1") {
            break;
        }
    }
    let _ = service.station.wait();
    let _ = std::fs::remove_dir_all(&dir);
}

fn read(path: &Path) -> String {
    std::fs::read_to_string(path).unwrap_or_default()
}

fn wait_for_text(path: &Path, text: &str, timeout: Duration) -> bool {
    let start = Instant::now();
    while start.elapsed() < timeout {
        if read(path).contains(text) {
            return true;
        }
        std::thread::sleep(Duration::from_millis(50));
    }
    false
}

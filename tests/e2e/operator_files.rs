//! The files an operator names, end to end: `mech-gcs serve` with keys,
//! and scripts attached to it as operators over TCP (with an operator key)
//! and over the local control socket. Neither may have the station write a
//! recording, or read a mission or arena file, outside the station's own
//! directories, nor replace an existing recording unasked
//! (`docs/commands.md`, *Files a command names*).

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};

use mech_e2e::harness::Killed;

use crate::station::keygen;

/// A served station that authenticates, its directories and how to reach
/// it.
struct Served {
    _station: Killed,
    dir: tempfile::TempDir,
    socket: PathBuf,
    tcp: String,
    key: PathBuf,
    recordings: PathBuf,
    missions: PathBuf,
}

/// How a script attaches.
#[derive(Debug, Clone, Copy)]
enum Via {
    Tcp,
    Socket,
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .map(|a| a.port())
        .expect("a free port")
}

impl Served {
    fn start() -> Served {
        let dir = tempfile::tempdir().expect("temp dir");
        let key = dir.path().join("ana.key");
        keygen("ana", &key);
        let socket = dir.path().join("run/gcs.sock");
        let recordings = dir.path().join("recordings");
        let missions = dir.path().join("missions");
        std::fs::create_dir_all(&missions).expect("missions directory");
        let tcp = format!("127.0.0.1:{}", free_port());
        let config = dir.path().join("gcs.toml");
        std::fs::write(
            &config,
            format!(
                "[router]\nudp = \"127.0.0.1:0\"\ntcp = \"127.0.0.1:0\"\n\
                 [station]\nsocket = {socket:?}\ntcp = {tcp:?}\n\
                 [record]\ndir = {recordings:?}\n\
                 [fleet]\nmission_dir = {missions:?}\n\
                 [auth]\nmode = \"required\"\n\
                 [[auth.keys]]\nrole = \"operator\"\nname = \"ana\"\nfile = {key:?}\n",
                socket = socket.display().to_string(),
                recordings = recordings.display().to_string(),
                missions = missions.display().to_string(),
                key = key.display().to_string(),
            ),
        )
        .expect("config written");
        let child = Command::new(mech_e2e::binary("mech-gcs"))
            .args(["serve", "--config"])
            .arg(&config)
            .env("XDG_STATE_HOME", dir.path())
            .stdin(Stdio::null())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("mech-gcs serve starts");
        let mut station = Killed(Some(child));
        let mut ready = String::new();
        if let Some(out) = station.0.as_mut().and_then(|c| c.stdout.take()) {
            let _ = BufReader::new(out).read_line(&mut ready);
        }
        assert!(ready.contains("serving"), "{ready:?}");
        assert!(ready.contains(&tcp), "{ready:?}");
        Served {
            _station: station,
            dir,
            socket,
            tcp,
            key,
            recordings,
            missions,
        }
    }

    /// `mech-gcs --attach ... --script -` with `source`: whether it passed,
    /// and its output.
    fn script(&self, via: Via, source: &str) -> (bool, String) {
        let attach: Vec<&std::ffi::OsStr> = match via {
            Via::Tcp => vec![
                "--attach".as_ref(),
                self.tcp.as_ref(),
                "--key".as_ref(),
                self.key.as_ref(),
            ],
            Via::Socket => vec!["--attach".as_ref(), self.socket.as_ref()],
        };
        mech_e2e::run_script(&attach, source, self.dir.path())
    }

    fn outside(&self, name: &str) -> String {
        self.dir.path().join(name).display().to_string()
    }
}

/// What each way of attaching is refused and allowed.
fn an_operator_is_kept_inside_the_stations_directories(s: &Served, via: Via, tag: &str) {
    let victim = s.outside("victim.mcap");
    let arena = s.outside("arena.toml");
    let mission = s.outside("mission.toml");
    let refusals = [
        (format!("record start {victim}"), "recording directory"),
        (
            format!("record start {victim} overwrite"),
            "recording directory",
        ),
        (
            "record start ../escape.mcap".to_string(),
            "recording directory",
        ),
        (
            "record start up/escape.mcap".to_string(),
            "leads out of the recording directory",
        ),
        (format!("arena load {arena}"), "missions directory"),
        ("arena load ../arena.toml".to_string(), "missions directory"),
        (format!("mission load all {mission}"), "missions directory"),
        (format!("mission save all {mission}"), "missions directory"),
    ];
    for (line, why) in &refusals {
        let (ok, out) = s.script(via, &format!("{line}\n"));
        assert!(!ok, "{via:?} {line}: {out}");
        assert!(out.contains("\"ok\":false"), "{via:?} {line}: {out}");
        assert!(out.contains(why), "{via:?} {line}: {out}");
    }
    assert_eq!(
        std::fs::read_to_string(&victim).expect("victim"),
        "an earlier experiment",
        "{via:?}"
    );
    assert!(!Path::new(&s.outside("escape.mcap")).exists(), "{via:?}");
    let (ok, out) = s.script(via, "arena\n");
    assert!(ok && out.contains("no arena"), "{via:?}: {out}");

    // Inside, a new name records; the same name again only with `overwrite`.
    let name = format!("{tag}.mcap");
    let (ok, out) = s.script(via, &format!("record start {name}\nrecord stop\n"));
    assert!(ok, "{via:?}: {out}");
    let file = s.recordings.join(&name);
    assert!(file.is_file(), "{via:?}: {out}");
    let size = std::fs::metadata(&file).expect("recorded").len();
    let (ok, out) = s.script(via, &format!("record start {name}\n"));
    assert!(!ok && out.contains("exists"), "{via:?}: {out}");
    assert_eq!(std::fs::metadata(&file).expect("kept").len(), size);
    let (ok, out) = s.script(
        via,
        &format!("record start {name} overwrite\nrecord stop\n"),
    );
    assert!(ok, "{via:?}: {out}");
    let (ok, out) = s.script(via, "arena load lab.toml\narena clear\n");
    assert!(ok && out.contains("4 vertices"), "{via:?}: {out}");
}

#[test]
fn operators_over_tcp_and_the_socket_name_files_only_inside_the_stations_directories() {
    let s = Served::start();
    let square = "boundary = [[0, 0], [5, 0], [5, 4], [0, 4]]\n";
    std::fs::write(s.outside("arena.toml"), square).expect("arena outside");
    std::fs::write(s.missions.join("lab.toml"), square).expect("arena inside");
    std::fs::write(
        s.outside("mission.toml"),
        "mech_mission = 1\nkind = \"robot\"\n[[waypoint]]\nx = 1\ny = 2\n",
    )
    .expect("mission outside");
    std::fs::write(s.outside("victim.mcap"), "an earlier experiment").expect("victim");
    // `serve` records by default; the operators' own recordings come after.
    let (ok, out) = s.script(Via::Socket, "record stop\n");
    assert!(ok, "{out}");
    std::os::unix::fs::symlink(s.dir.path(), s.recordings.join("up")).expect("link out");
    an_operator_is_kept_inside_the_stations_directories(&s, Via::Tcp, "tcp");
    an_operator_is_kept_inside_the_stations_directories(&s, Via::Socket, "socket");
}

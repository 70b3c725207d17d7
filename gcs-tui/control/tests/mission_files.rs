//! `mission save` / `mission load` against a real station: MECH's own
//! format and QGC WPL 110 round trips (waypoints, arrival times, loop, a
//! cluster's headings), a file as MAVProxy's `wp save` writes it (written
//! by pymavlink's `MAVWPLoader.save`, which `wp save` calls), read back by
//! pymavlink itself, and the directories an operator's session is kept in:
//! mission and arena files in the missions directory, recordings in the
//! recording directory (`mech_control::files`).

#![allow(clippy::unwrap_used)]

#[path = "../../core/tests/support/agent.rs"]
mod agent;

use std::path::{Path, PathBuf};

use agent::{Peer, config};
use mech_control::lang::Executor;
use mech_core::Gcs;
use mech_proto::Waypoint;

/// The fixture: home, a takeoff, a 2 m x 3 m square around a field in the
/// Netherlands (the second waypoint held 2 s), and a jump back to the
/// first waypoint forever, as pymavlink's `MAVWPLoader.save` writes it.
fn mavproxy_file() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/fixtures/mavproxy-wp-save.txt")
}

async fn station(mission_dir: Option<&Path>) -> (Gcs, Vec<Peer>) {
    let mut c = config();
    c.fleet.mission_dir = mission_dir.map(Path::to_path_buf);
    let gcs = Gcs::start(c).await.unwrap();
    let mut robots = Vec::new();
    for name in ["robot_1", "robot_2"] {
        let mut r = Peer::new(name, gcs.router().udp_addr()).await;
        r.register().await;
        robots.push(r);
    }
    (gcs, robots)
}

fn draft(gcs: &Gcs, robot: &str) -> (Vec<Waypoint>, bool) {
    gcs.with_fleet(|f| {
        let r = f.robot(robot).unwrap();
        (r.waypoints.draft.clone(), r.waypoints.looped)
    })
}

fn near(a: &[Waypoint], b: &[Waypoint], tol: f64) {
    assert_eq!(a.len(), b.len(), "{a:?}\n{b:?}");
    for (p, q) in a.iter().zip(b) {
        let d = ((p.x - q.x).powi(2) + (p.y - q.y).powi(2) + (p.z - q.z).powi(2)).sqrt();
        assert!(d < tol, "{p:?} {q:?}: {d} m apart");
    }
}

fn path(dir: &Path, name: &str) -> String {
    dir.join(name).to_str().unwrap().to_string()
}

/// The fixture is refused without an origin (its frame is relative to
/// home), and loads around its home with `origin home`, the takeoff and
/// the hold time noted.
async fn loads_only_around_its_home(exec: &mut Executor, fixture: &str) {
    let refused = exec
        .execute_line(&format!("mission load robot_1 {fixture}"))
        .await
        .unwrap_err()
        .to_string();
    assert!(
        refused.contains("line 4: item 2 is in frame 3 (MAV_FRAME_GLOBAL_RELATIVE_ALT"),
        "{refused}"
    );
    assert!(refused.contains("origin LAT,LON"), "{refused}");

    let loaded = exec
        .execute_line(&format!("mission load robot_1 {fixture} origin home"))
        .await
        .unwrap();
    assert!(
        loaded
            .summary
            .starts_with("robot_1: 4 waypoints, looped loaded from"),
        "{loaded:?}"
    );
    assert!(loaded.summary.contains("(QGC WPL 110)"), "{loaded:?}");
    assert_eq!(
        loaded.details,
        [
            "skipped, not waypoints: item 1 (22, NAV_TAKEOFF)",
            "1 hold time(s) (param 1) not kept: a MECH waypoint is passed, not held"
        ]
    );
}

/// pymavlink, which MAVProxy's wp load calls, reads what MECH wrote in
/// `out`: home, the square in the fixture's frame, the jump.
fn pymavlink_reads_the_square(out: &str) {
    if let Some(items) = pymavlink_reads(out) {
        assert_eq!(items.len(), 6, "home, four waypoints, the jump: {items:?}");
        let home = &items[0];
        assert_eq!((home[0], home[1]), (0.0, 16.0));
        assert!((home[2] - 52.001234).abs() < 1e-9 && (home[3] - 4.371234).abs() < 1e-9);
        for w in &items[1..5] {
            assert_eq!((w[0], w[1]), (3.0, 16.0), "{w:?}");
        }
        let jump = &items[5];
        assert_eq!((jump[1], jump[4], jump[5]), (177.0, 1.0, -1.0), "{jump:?}");
        let fixture_first = [52.001270, 4.371263];
        assert!(
            (items[1][2] - fixture_first[0]).abs() < 1e-7
                && (items[1][3] - fixture_first[1]).abs() < 1e-7,
            "{items:?}"
        );
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_file_mavproxy_wrote_loads_around_its_home_and_round_trips() {
    let dir = tempfile::tempdir().unwrap();
    let (gcs, _robots) = station(None).await;
    let mut exec = Executor::new(gcs.clone());
    let fixture = mavproxy_file();
    let fixture = fixture.to_str().unwrap();

    loads_only_around_its_home(&mut exec, fixture).await;
    let (square, looped) = draft(&gcs, "robot_1");
    assert!(looped);
    // 0.000036 deg of latitude north and 0.000029 deg of longitude east of
    // home at 52 deg N: 4.00 m and 1.99 m.
    let r = 6_371_000.0_f64;
    let north = (0.000036_f64).to_radians() * r;
    let east = (0.000029_f64).to_radians() * r * 52.001234_f64.to_radians().cos();
    near(
        &square[..1],
        &[Waypoint {
            x: east,
            y: north,
            z: 0.0,
            time: None,
        }],
        1e-6,
    );
    assert!((north - 4.003).abs() < 0.001 && (east - 1.985).abs() < 0.001);

    // Back to QGC WPL around the same origin, and in again: the same square.
    let out = path(dir.path(), "square.waypoints");
    let saved = exec
        .execute_line(&format!(
            "mission save robot_1 {out} origin 52.001234,4.371234,1.5"
        ))
        .await
        .unwrap();
    assert!(
        saved
            .summary
            .contains("(QGC WPL 110, MAV_FRAME_GLOBAL_RELATIVE_ALT)"),
        "{saved:?}"
    );
    exec.execute_line(&format!("mission load robot_2 {out} origin home"))
        .await
        .unwrap();
    let (again, looped) = draft(&gcs, "robot_2");
    assert!(looped);
    near(&again, &square, 1e-3);

    // The same in MECH's format: exact.
    let toml = path(dir.path(), "square.toml");
    exec.execute_line(&format!("mission save robot_1 {toml}"))
        .await
        .unwrap();
    exec.execute_line("waypoint robot_2 9,9").await.unwrap();
    exec.execute_line(&format!("mission load robot_2 {toml}"))
        .await
        .unwrap();
    assert_eq!(draft(&gcs, "robot_2"), (square.clone(), true));

    pymavlink_reads_the_square(&out);
    gcs.shutdown().await;
}

/// What pymavlink's `MAVWPLoader.load` reads in `file`: per item frame,
/// command, x, y, z, param1, param2; `None` without Python or pymavlink
/// outside CI (`scripts/deps.sh` installs them for the tests).
fn pymavlink_reads(file: &str) -> Option<Vec<Vec<f64>>> {
    let program = r#"
import json, sys
from pymavlink import mavwp
w = mavwp.MAVWPLoader()
w.load(sys.argv[1])
print(json.dumps([[p.frame, p.command, p.x, p.y, p.param1, p.param2] for p in w.wpoints]))
"#;
    let out = std::process::Command::new("python3")
        .args(["-c", program, file])
        .output();
    let skip = |why: String| {
        assert!(
            std::env::var_os("CI").is_none(),
            "CI needs pymavlink: {why}"
        );
        println!("skipped pymavlink's reading: {why}");
        None
    };
    let out = match out {
        Ok(o) => o,
        Err(e) => return skip(e.to_string()),
    };
    let stderr = String::from_utf8_lossy(&out.stderr);
    if stderr.contains("No module named") {
        return skip(stderr.to_string());
    }
    assert!(out.status.success(), "pymavlink: {stderr}");
    // x and y come back as the float32 of a MAVLink MISSION_ITEM: compare
    // them loosely; the test reads them as degrees.
    let items: Vec<Vec<f64>> = serde_json::from_slice(&out.stdout).unwrap();
    Some(
        items
            .into_iter()
            .map(|i| vec![i[0], i[1], i[2], i[3], i[4], i[5]])
            .collect(),
    )
}

/// A cluster's waypoints, headings and loop survive both formats (files
/// written in `dir`).
async fn a_clusters_waypoints_round_trip(exec: &mut Executor, dir: &Path) {
    exec.execute_line("cluster c1 robot_1 robot_2")
        .await
        .unwrap();
    exec.execute_line("cluster-waypoint c1 0.5,0.5,90deg 1.5,0.5 1.5,1.5,0 loop")
        .await
        .unwrap();
    let cluster_before = exec.control().cluster_draft("c1").unwrap();
    for name in ["c1.toml", "c1.waypoints"] {
        let file = path(dir, name);
        exec.execute_line(&format!("mission save c1 {file}"))
            .await
            .unwrap();
        exec.execute_line("cluster-waypoint c1 9,9").await.unwrap();
        let loaded = exec
            .execute_line(&format!("mission load c1 {file}"))
            .await
            .unwrap();
        assert!(loaded.summary.contains("3 waypoints, looped"), "{loaded:?}");
        let (after, looped) = exec.control().cluster_draft("c1").unwrap();
        assert!(looped, "{name}");
        assert_eq!(after.len(), 3);
        for (a, b) in after.iter().zip(&cluster_before.0) {
            assert!(
                (a.x - b.x).abs() < 1e-8 && (a.y - b.y).abs() < 1e-8,
                "{name}"
            );
            match (a.heading, b.heading) {
                (Some(h), Some(k)) => assert!((h - k).abs() < 1e-6, "{name}: {h} {k}"),
                (None, None) => {}
                other => panic!("{name}: {other:?}"),
            }
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn times_loops_and_a_clusters_headings_survive_mechs_format() {
    let dir = tempfile::tempdir().unwrap();
    let (gcs, _robots) = station(None).await;
    let mut exec = Executor::new(gcs.clone());
    exec.execute_line("waypoint robot_1 1,2 3,2@15s 3.5,-1,0.5@20.5s loop")
        .await
        .unwrap();
    let before = draft(&gcs, "robot_1");
    let file = path(dir.path(), "timed.toml");
    let saved = exec
        .execute_line(&format!("mission save robot_1 {file}"))
        .await
        .unwrap();
    assert!(
        saved
            .summary
            .contains("3 waypoints, looped, 2 timed saved to"),
        "{saved:?}"
    );
    exec.execute_line("waypoint robot_1 clear").await.unwrap();
    exec.execute_line(&format!("mission load robot_1 {file}"))
        .await
        .unwrap();
    assert_eq!(draft(&gcs, "robot_1"), before);

    // QGC WPL has no arrival times: the outcome says they were dropped.
    let wpl = path(dir.path(), "timed.waypoints");
    let saved = exec
        .execute_line(&format!("mission save robot_1 {wpl}"))
        .await
        .unwrap();
    assert!(
        saved.details[0].starts_with("2 arrival time(s) not written"),
        "{saved:?}"
    );

    a_clusters_waypoints_round_trip(&mut exec, dir.path()).await;
    let e = exec
        .execute_line(&format!(
            "mission load robot_1 {}",
            path(dir.path(), "c1.toml")
        ))
        .await
        .unwrap_err();
    assert!(e.message.contains("load it into a cluster"), "{e}");
    let no_draft = exec
        .execute_line(&format!(
            "mission save robot_2 {}",
            path(dir.path(), "x.toml")
        ))
        .await
        .unwrap_err();
    assert!(
        no_draft.message.contains("robot_2 has no waypoints"),
        "{no_draft}"
    );
    let bad_name = exec
        .execute_line(&format!(
            "mission save robot_1 {}",
            path(dir.path(), "x.json")
        ))
        .await
        .unwrap_err();
    assert!(bad_name.message.contains("name it .toml"), "{bad_name}");
    gcs.shutdown().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_operators_session_reads_and_writes_only_in_the_missions_directory() {
    let dir = tempfile::tempdir().unwrap();
    let missions = dir.path().join("missions");
    let (gcs, _robots) = station(Some(&missions)).await;
    let mut ana = Executor::new(gcs.clone()).with_sender("ana");
    ana.execute_line("waypoint robot_1 1,1 2,1").await.unwrap();
    let outside = path(dir.path(), "outside.toml");
    for bad in [
        outside.as_str(),
        "../outside.toml",
        "lab/../../outside.toml",
    ] {
        let e = ana
            .execute_line(&format!("mission save robot_1 {bad}"))
            .await
            .unwrap_err();
        assert!(e.message.contains("missions directory"), "{bad}: {e}");
    }
    assert!(!Path::new(&outside).exists());
    let saved = ana
        .execute_line("mission save robot_1 lab/line.toml")
        .await
        .unwrap();
    assert!(missions.join("lab/line.toml").is_file(), "{saved:?}");
    ana.execute_line("mission load robot_2 lab/line.toml")
        .await
        .unwrap();
    assert_eq!(draft(&gcs, "robot_2").0.len(), 2);
    let e = ana
        .execute_line("mission load robot_2 /etc/hostname")
        .await
        .unwrap_err();
    assert!(e.message.contains("missions directory"), "{e}");
    gcs.shutdown().await;
}

/// A mission file's arrival time past a day is refused at load, as
/// `waypoint` refuses it, with the file, the line and the key.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn mission_load_refuses_an_arrival_time_past_a_day_at_its_line() {
    let dir = tempfile::tempdir().unwrap();
    let (gcs, _robots) = station(None).await;
    let mut exec = Executor::new(gcs.clone());
    let file = path(dir.path(), "late.toml");
    std::fs::write(
        &file,
        "mech_mission = 1\nkind = \"robot\"\n[[waypoint]]\nx = 1\ny = 2\nt = 1e20\n",
    )
    .unwrap();
    let e = exec
        .execute_line(&format!("mission load robot_1 {file}"))
        .await
        .unwrap_err();
    assert!(
        e.message
            .starts_with(&format!("{file}: line 6: waypoint 1: `t` = ")),
        "{e}"
    );
    assert!(e.message.contains("(a day)"), "{e}");
    assert!(draft(&gcs, "robot_1").0.is_empty(), "nothing loaded");
    gcs.shutdown().await;
}

/// An operator's `record start FILE` writes only inside the recording
/// directory, replaces nothing unless told `overwrite`, and follows no
/// link out; the station's own script names any path but overwrites
/// nothing unless told either.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_operators_recording_stays_in_the_recording_directory_and_replaces_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let recordings = dir.path().join("recordings");
    std::fs::create_dir_all(&recordings).unwrap();
    let (gcs, _robots) = station(Some(&dir.path().join("missions"))).await;
    let mut ana = Executor::new(gcs.clone())
        .with_record_dir(recordings.clone())
        .with_sender("ana");
    let victim = path(dir.path(), "victim.mcap");
    std::fs::write(&victim, "an earlier experiment").unwrap();
    std::os::unix::fs::symlink(dir.path(), recordings.join("up")).unwrap();
    for (bad, why) in [
        (victim.as_str(), "recording directory"),
        ("../escape.mcap", "recording directory"),
        ("a/../../escape.mcap", "recording directory"),
        ("up/escape.mcap", "leads out of the recording directory"),
    ] {
        let e = ana
            .execute_line(&format!("record start {bad}"))
            .await
            .unwrap_err();
        assert!(e.message.contains(why), "{bad}: {e}");
        assert!(e.message.starts_with(&format!("{bad:?}")), "{bad}: {e}");
    }
    assert_eq!(
        std::fs::read_to_string(&victim).unwrap(),
        "an earlier experiment"
    );
    assert!(!dir.path().join("escape.mcap").exists());
    assert!(gcs.recording().is_none(), "nothing started");

    let started = ana.execute_line("record start run.mcap").await.unwrap();
    let run = recordings.join("run.mcap");
    assert_eq!(started.summary, format!("recording to {}", run.display()));
    ana.execute_line("record stop").await.unwrap();
    let size = std::fs::metadata(&run).unwrap().len();
    let e = ana.execute_line("record start run.mcap").await.unwrap_err();
    assert!(e.message.contains("exists"), "{e}");
    assert!(e.message.contains("overwrite"), "{e}");
    assert_eq!(std::fs::metadata(&run).unwrap().len(), size, "untouched");
    ana.execute_line("record start run.mcap overwrite")
        .await
        .unwrap();
    ana.execute_line("record stop").await.unwrap();
    let inside = recordings.join("lab/abs.mcap");
    ana.execute_line(&format!("record start {}", inside.display()))
        .await
        .unwrap();
    ana.execute_line("record stop").await.unwrap();
    assert!(inside.is_file());

    // An operator of a station without a recording directory names none.
    let mut bo = Executor::new(gcs.clone()).with_sender("bo");
    let e = bo.execute_line("record start run.mcap").await.unwrap_err();
    assert!(e.message.contains("has none"), "{e}");

    // The station's own script: any path, but an existing file only with
    // `overwrite`.
    let mut own = Executor::new(gcs.clone());
    let e = own
        .execute_line(&format!("record start {victim}"))
        .await
        .unwrap_err();
    assert!(e.message.contains("exists"), "{e}");
    assert_eq!(
        std::fs::read_to_string(&victim).unwrap(),
        "an earlier experiment"
    );
    own.execute_line(&format!("record start {victim} overwrite"))
        .await
        .unwrap();
    own.execute_line("record stop").await.unwrap();
    assert!(mech_core::replay::Replay::open(Path::new(&victim)).is_ok());
    gcs.shutdown().await;
}

/// An operator's `arena load FILE` reads only in the missions directory;
/// the station's own script reads any path.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_operators_arena_file_is_read_only_in_the_missions_directory() {
    let dir = tempfile::tempdir().unwrap();
    let missions = dir.path().join("missions");
    std::fs::create_dir_all(&missions).unwrap();
    let (gcs, _robots) = station(Some(&missions)).await;
    let arena = "boundary = [[0, 0], [5, 0], [5, 4], [0, 4]]\n";
    std::fs::write(missions.join("lab.toml"), arena).unwrap();
    let outside = path(dir.path(), "outside.toml");
    std::fs::write(&outside, arena).unwrap();
    let mut ana = Executor::new(gcs.clone()).with_sender("ana");
    for bad in [outside.as_str(), "../outside.toml", "/etc/hostname"] {
        let e = ana
            .execute_line(&format!("arena load {bad}"))
            .await
            .unwrap_err();
        assert!(e.message.contains("missions directory"), "{bad}: {e}");
    }
    assert!(gcs.router().arena().is_none(), "nothing loaded");
    let loaded = ana.execute_line("arena load lab.toml").await.unwrap();
    assert!(loaded.summary.contains("4 vertices"), "{loaded:?}");
    let mut own = Executor::new(gcs.clone());
    own.execute_line(&format!("arena load {outside}"))
        .await
        .unwrap();
    gcs.shutdown().await;
}

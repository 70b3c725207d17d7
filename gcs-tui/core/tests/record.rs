//! Recording and replay: a real router on loopback, recorded while test
//! robots and a controller talk to it, then read back with the replay
//! reader. What was recorded must be exactly what the router saw.

#![allow(clippy::unwrap_used)]

#[path = "support/agent.rs"]
mod agent;

use std::collections::BTreeMap;
use std::net::UdpSocket;
use std::path::Path;
use std::time::Duration;

use agent::{Peer, config, eventually, telemetry};
use mech_core::replay::{Entry, Replay};
use mech_core::{Event, Gcs, RecordTarget, Stamped};
use mech_proto::Body;

async fn gcs() -> Gcs {
    Gcs::start(config()).await.unwrap()
}

/// A station recording to `name` in a directory of its own (kept while
/// the directory is).
async fn recording_to(name: &str) -> (tempfile::TempDir, std::path::PathBuf, Gcs) {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join(name);
    let gcs = gcs().await;
    gcs.start_recording(RecordTarget::File(file.clone()))
        .unwrap();
    (dir, file, gcs)
}

async fn registered(gcs: &Gcs, name: &str) -> Peer {
    let mut p = Peer::new(name, gcs.router().udp_addr()).await;
    p.register().await;
    p
}

/// Every event the subscription got, telemetry included.
fn drain(sub: &mut mech_core::Subscription) -> Vec<Stamped> {
    let mut out = Vec::new();
    while let Some(e) = sub.try_recv() {
        out.push((*e).clone());
    }
    out
}

fn telemetry_of(events: &[Stamped], robot: &str) -> Vec<f64> {
    events
        .iter()
        .filter_map(|s| match &s.event {
            Event::Telemetry {
                robot: r,
                telemetry,
            } if r == robot => Some(telemetry.pose.x),
            _ => None,
        })
        .collect()
}

/// What the recording holds: commands from a pad (one to a robot routed
/// to none), a garbage packet, telemetry from both robots.
async fn talk(gcs: &Gcs, r1: &mut Peer, r2: &mut Peer) {
    let mut pad = Peer::new("pad", gcs.router().udp_addr()).await;
    for i in 0..3 {
        pad.command("robot_1", "joy/0", 0.1 * f64::from(i)).await;
    }
    pad.command("robot_2", "joy/0", 0.5).await; // robot_2 is routed to none
    pad.send_raw(b"\x93garbage").await;
    for i in 0..10 {
        r1.send_telemetry(telemetry(f64::from(i), 1.0, "joy/0", None))
            .await;
        if i < 5 {
            r2.send_telemetry(telemetry(-f64::from(i), 2.0, "", None))
                .await;
        }
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_recording_holds_what_the_router_saw_and_replays_it() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("run.mcap");
    let gcs = gcs().await;
    let mut sub = gcs.router().subscribe(65_536, true);
    gcs.start_recording(RecordTarget::File(file.clone()))
        .unwrap();
    let mut r1 = registered(&gcs, "robot_1").await;
    let mut r2 = registered(&gcs, "robot_2").await;
    gcs.router()
        .set_route("robot_1", Some("joy/0"))
        .await
        .unwrap();
    r1.follow_route().await;
    talk(&gcs, &mut r1, &mut r2).await;
    gcs.router().estop().await;
    let counted = |g: &Gcs| g.router().counters().received;
    let settled = eventually(Duration::from_secs(5), || {
        gcs.recording().unwrap().messages == counted(&gcs)
    })
    .await;
    assert!(settled, "{:?} vs {}", gcs.recording(), counted(&gcs));
    let status = gcs.stop_recording().await.unwrap();
    let received = gcs.router().counters().received;
    let seen = drain(&mut sub);
    gcs.shutdown().await;

    assert_eq!(
        (status.dropped, status.messages),
        (0, received),
        "{status:?}"
    );
    assert!(!status.active && status.error.is_none(), "{status:?}");
    let replay = Replay::open(&file).unwrap();
    assert_eq!(replay.damage(), None);
    assert_eq!(replay.counts()["/mech/raw"], received);
    let end = replay.end_metadata().unwrap();
    assert_eq!(end["router_received"], received.to_string());
    assert_eq!(end["dropped"], "0");
    // Exactly the events a subscriber got, in the same order and times.
    let replayed: Vec<Stamped> = replay.events().collect();
    assert_eq!(replayed, seen);
    assert_eq!(telemetry_of(&replayed, "robot_1").len(), 10);
    assert_eq!(
        telemetry_of(&replayed, "robot_2"),
        [0.0, -1.0, -2.0, -3.0, -4.0]
    );
    assert_eq!(replay.counts()["/robots/robot_1/pose"], 10);
    let fleet = replay.fleet_at(replay.end());
    let r = fleet.robot("robot_1").unwrap();
    assert_eq!(
        (r.telemetry.pose.x, r.route.requested.as_deref()),
        (9.0, Some("joy/0"))
    );
    assert!(fleet.estop.engaged);
    // Half way through, robot_1 was half way along.
    let mid = telemetry_at(&replayed, "robot_1", 4);
    assert_eq!(
        replay
            .fleet_at(mid)
            .robot("robot_1")
            .unwrap()
            .telemetry
            .pose
            .x,
        4.0
    );
    decisions_say_why(&replay, received);
}

/// Router time of the `n`th telemetry of `robot`.
fn telemetry_at(events: &[Stamped], robot: &str, n: usize) -> Duration {
    events
        .iter()
        .filter(|s| matches!(&s.event, Event::Telemetry { robot: r, .. } if r == robot))
        .nth(n)
        .unwrap()
        .at
}

/// The decisions topic says what happened to the commands and the garbage;
/// read with the mcap crate's own reader, independently of [`Replay`].
fn decisions_say_why(replay: &Replay, received: u64) {
    let bytes = std::fs::read(replay.path()).unwrap();
    let mut outcomes: BTreeMap<String, u64> = BTreeMap::new();
    let mut raw = 0u64;
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        match m.channel.topic.as_str() {
            "/mech/raw" => raw += 1,
            "/mech/decisions" => {
                let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
                let key = format!(
                    "{} {} {}",
                    v["kind"].as_str().unwrap(),
                    v["outcome"].as_str().unwrap(),
                    v["reason"].as_str().unwrap_or("")
                );
                *outcomes.entry(key).or_default() += 1;
                if v["kind"] == "unreadable" {
                    assert!(v["detail"].as_str().unwrap().len() > 5, "{v}");
                }
            }
            _ => {}
        }
    }
    assert_eq!(raw, received);
    assert_eq!(outcomes["Command forwarded "], 3, "{outcomes:?}");
    assert_eq!(outcomes["Command dropped not-routed"], 1, "{outcomes:?}");
    assert_eq!(outcomes["unreadable dropped bad-packet"], 1, "{outcomes:?}");
    assert_eq!(outcomes["Hello consumed "], 2, "{outcomes:?}");
}

/// Robots sending telemetry from a thread of their own, `rounds` samples
/// each paced at `hz` (a starved thread sends late, never fewer); returns
/// how many each sent.
fn send_telemetry(socks: Vec<(String, UdpSocket)>, hz: u32, rounds: u32) -> Vec<u64> {
    let period = Duration::from_secs(1) / hz;
    let start = std::time::Instant::now();
    let mut sent = vec![0u64; socks.len()];
    let mut round = 0u32;
    while round < rounds {
        for (i, (name, s)) in socks.iter().enumerate() {
            let t = telemetry(f64::from(round), 0.0, "", None);
            let bytes = mech_proto::encode(&agent::envelope(
                name,
                mech_proto::ROUTER,
                "",
                round,
                Body::Telemetry(t),
            ))
            .unwrap();
            s.send(&bytes).unwrap();
            sent[i] += 1;
        }
        round += 1;
        let next = start + period * round;
        std::thread::sleep(next.saturating_duration_since(std::time::Instant::now()));
    }
    sent
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn no_telemetry_sample_of_100_robots_at_20_hz_is_missing() {
    const ROBOTS: usize = 100;
    /// Three seconds at 20 Hz: a count, so a loaded machine sends them all
    /// (later) rather than fewer.
    const ROUNDS: u32 = 60;
    let (_dir, file, gcs) = recording_to("fleet.mcap").await;
    let router = gcs.router().udp_addr();
    let mut socks = Vec::new();
    for i in 0..ROBOTS {
        let name = format!("robot_{i}");
        let s = UdpSocket::bind("127.0.0.1:0").unwrap();
        s.connect(router).unwrap();
        let hello = mech_proto::Hello {
            name: name.clone(),
            platform: "diff-drive".into(),
            capabilities: vec![],
            motors: 2,
            max_speed: 1.0,
            max_yaw_rate: 2.0,
            agent_version: "test".into(),
        };
        let env = agent::envelope(&name, mech_proto::ROUTER, "", 0, Body::Hello(hello));
        s.send(&mech_proto::encode(&env).unwrap()).unwrap();
        socks.push((name, s));
    }
    let all = eventually(Duration::from_secs(10), || {
        gcs.with_fleet(|f| f.robots.len()) == ROBOTS
    });
    assert!(all.await, "every robot registered");
    let names: Vec<String> = socks.iter().map(|(n, _)| n.clone()).collect();
    let sent = tokio::task::spawn_blocking(move || send_telemetry(socks, 20, ROUNDS))
        .await
        .unwrap();
    let total: u64 = sent.iter().sum();
    eventually(Duration::from_secs(10), || {
        gcs.recording().unwrap().messages >= gcs.router().counters().received
    })
    .await;
    let status = gcs.stop_recording().await.unwrap();
    gcs.shutdown().await;
    assert_eq!(status.dropped, 0, "{status:?}");
    let replay = Replay::open(&file).unwrap();
    let counts = replay.counts();
    for (name, sent) in names.iter().zip(&sent) {
        let recorded = counts.get(&format!("/robots/{name}/telemetry")).copied();
        assert_eq!(recorded, Some(*sent), "{name}");
    }
    assert_eq!(total, ROBOTS as u64 * u64::from(ROUNDS));
}

/// A recording of a few robots' telemetry over `secs` seconds (several
/// chunks: one a second).
async fn recording_over(dir: &Path, secs: u64) -> (std::path::PathBuf, Vec<Stamped>) {
    let file = dir.join("long.mcap");
    let gcs = gcs().await;
    gcs.start_recording(RecordTarget::File(file.clone()))
        .unwrap();
    let mut r = registered(&gcs, "robot_1").await;
    let end = tokio::time::Instant::now() + Duration::from_secs(secs);
    let mut i = 0;
    while tokio::time::Instant::now() < end {
        r.send_telemetry(telemetry(f64::from(i), 0.0, "", None))
            .await;
        i += 1;
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    gcs.shutdown().await;
    let events = Replay::open(&file).unwrap().events().collect();
    (file, events)
}

/// Where the last chunk of an MCAP file begins and how long it is, from
/// the chunk indexes of its summary: a cut inside it leaves every chunk
/// before it whole (the summary repeats every schema, so a cut at half the
/// file may leave the data whole, and the first chunk, holding the
/// schemas, may be most of the data).
fn last_chunk(bytes: &[u8]) -> (usize, usize) {
    let summary = mcap::Summary::read(bytes).unwrap().expect("a summary");
    let last = summary
        .chunk_indexes
        .iter()
        .max_by_key(|c| c.chunk_start_offset)
        .expect("chunks");
    assert!(summary.chunk_indexes.len() > 1, "several chunks");
    (
        usize::try_from(last.chunk_start_offset).unwrap(),
        usize::try_from(last.chunk_length).unwrap(),
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_damaged_file_replays_up_to_the_damage_and_says_so() {
    let dir = tempfile::tempdir().unwrap();
    let (file, all) = recording_over(dir.path(), 3).await;
    let bytes = std::fs::read(&file).unwrap();
    let cut = dir.path().join("cut.mcap");
    // Inside the data (the summary at the end of a short file is large:
    // it repeats every schema).
    let (chunk, length) = last_chunk(&bytes);
    std::fs::write(&cut, &bytes[..chunk + length / 2]).unwrap();
    let replay = Replay::open(&cut).unwrap();
    let damage = replay.damage().unwrap();
    assert!(damage.contains("truncated or corrupt"), "{damage}");
    let events: Vec<Stamped> = replay.events().collect();
    assert!(
        !events.is_empty() && events.len() < all.len(),
        "{} of {}",
        events.len(),
        all.len()
    );
    assert_eq!(events[..], all[..events.len()], "a prefix of the whole");

    let mut corrupt = bytes.clone();
    let mid = chunk + length / 3;
    for b in &mut corrupt[mid..mid + 64] {
        *b ^= 0x5a;
    }
    let bad = dir.path().join("corrupt.mcap");
    std::fs::write(&bad, &corrupt).unwrap();
    let replay = Replay::open(&bad).unwrap();
    assert!(replay.damage().is_some());
    let events: Vec<Stamped> = replay.events().collect();
    assert_eq!(events[..], all[..events.len()]);

    // A chunk header damaged to claim an absurd size is damage, not an
    // attempt to allocate it.
    let mut huge = bytes.clone();
    let first = mcap::read::LinearReader::new(&bytes)
        .unwrap()
        .find_map(|r| match r {
            Ok(mcap::records::Record::Chunk { header, .. }) => Some(header),
            _ => None,
        })
        .expect("a chunk");
    let mut pattern = first.message_start_time.to_le_bytes().to_vec();
    pattern.extend(first.message_end_time.to_le_bytes());
    pattern.extend(first.uncompressed_size.to_le_bytes());
    let at = huge
        .windows(pattern.len())
        .position(|w| w == pattern)
        .expect("the chunk header's bytes")
        + 16;
    huge[at..at + 8].copy_from_slice(&0x3a3a_3a3a_3a3a_3a3a_u64.to_le_bytes());
    let bad = dir.path().join("huge.mcap");
    std::fs::write(&bad, &huge).unwrap();
    let replay = Replay::open(&bad).unwrap();
    let damage = replay.damage().unwrap();
    assert!(damage.contains("claims"), "{damage}");

    // Damage anywhere: a replay says so or reads past it, never crashes.
    for step in 0..48 {
        let mut damaged = bytes.clone();
        let from = damaged.len() * step / 48;
        let to = (from + 64).min(damaged.len());
        for b in &mut damaged[from..to] {
            *b ^= 0xa5;
        }
        let path = dir.path().join("damaged.mcap");
        std::fs::write(&path, &damaged).unwrap();
        if let Ok(replay) = Replay::open(&path) {
            let _ = replay.events().count();
            let _ = replay.fleet_at(replay.end());
        }
    }

    let other = dir.path().join("notes.mcap");
    std::fs::write(&other, b"not a recording at all").unwrap();
    let e = Replay::open(&other).unwrap_err().to_string();
    assert!(e.contains("is not a MECH recording"), "{e}");
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn rotating_files_keep_the_newest_and_each_replays_alone() {
    let dir = tempfile::tempdir().unwrap();
    let gcs = gcs().await;
    let target = RecordTarget::Rotating {
        dir: dir.path().to_owned(),
        max_file_bytes: 4_000,
        keep: 2,
    };
    gcs.start_recording(target).unwrap();
    let mut r = registered(&gcs, "robot_1").await;
    gcs.router()
        .set_route("robot_1", Some("joy/0"))
        .await
        .unwrap();
    r.follow_route().await;
    let end = tokio::time::Instant::now() + Duration::from_millis(4_500);
    let mut i = 0;
    while tokio::time::Instant::now() < end {
        r.send_telemetry(telemetry(f64::from(i), 0.0, "joy/0", None))
            .await;
        i += 1;
        tokio::time::sleep(Duration::from_millis(10)).await;
    }
    let status = gcs.stop_recording().await.unwrap();
    gcs.shutdown().await;
    assert!(status.files.len() >= 3, "{status:?}");
    let mut left: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    left.sort();
    assert_eq!(left.len(), 2, "{left:?}");
    assert_eq!(left[1], *status.files.last().unwrap());
    for f in &left {
        let replay = Replay::open(f).unwrap();
        assert_eq!(replay.damage(), None, "{}", f.display());
        // The file begins with the robot registered and routed.
        let first = replay.fleet_at(replay.start());
        let robot = first.robot("robot_1").unwrap();
        assert_eq!(robot.route.requested.as_deref(), Some("joy/0"));
        assert!(replay.entries().any(|e| matches!(e, Entry::Snapshot(_))));
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_recording_begun_mid_run_starts_from_the_fleet_as_it_stood() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("late.mcap");
    let gcs = gcs().await;
    let mut r = registered(&gcs, "robot_1").await;
    gcs.router()
        .set_route("robot_1", Some("joy/0"))
        .await
        .unwrap();
    r.follow_route().await;
    r.send_telemetry(telemetry(1.5, 0.5, "joy/0", None)).await;
    let seen = eventually(Duration::from_secs(3), || {
        gcs.with_fleet(|f| {
            f.robot("robot_1")
                .is_some_and(|r| r.telemetry.pose.x == 1.5)
        })
    });
    assert!(seen.await);
    gcs.update_fleet(|f| f.set_cluster("c1", vec!["robot_1".into()]));
    gcs.start_recording(RecordTarget::File(file.clone()))
        .unwrap();
    r.send_telemetry(telemetry(2.5, 0.5, "joy/0", None)).await;
    tokio::time::sleep(Duration::from_millis(200)).await;
    gcs.shutdown().await;
    let replay = Replay::open(&file).unwrap();
    let start = replay.fleet_at(replay.start());
    let robot = start.robot("robot_1").unwrap();
    assert_eq!(robot.route.acknowledged.as_deref(), Some("joy/0"));
    assert_eq!((robot.telemetry.pose.x, robot.telemetry.pose.y), (1.5, 0.5));
    assert_eq!(
        robot.registration.hello.agent_version, "test",
        "the registration as the robot sent it"
    );
    assert_eq!(start.clusters["c1"].members, ["robot_1"]);
    let events: Vec<Stamped> = replay.events().collect();
    assert!(
        !events
            .iter()
            .any(|e| matches!(e.event, Event::Registered { .. })),
        "snapshot only"
    );
    assert_eq!(telemetry_of(&events, "robot_1"), [2.5]);
    // A cursor moves forward and back.
    let mut c = replay.cursor();
    c.advance_to(replay.end());
    assert_eq!(c.fleet().robot("robot_1").unwrap().telemetry.pose.x, 2.5);
    c.seek(replay.start());
    assert_eq!(c.fleet().robot("robot_1").unwrap().telemetry.pose.x, 1.5);
}

/// A stranger's flood of garbage while recording: the first refused
/// messages of each second are recorded whole, the rest only counted, and
/// the fleet's own traffic is all there.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_strangers_flood_is_counted_not_recorded_whole() {
    const FLOOD: u64 = 3000;
    let (_dir, file, gcs) = recording_to("flood.mcap").await;
    let mut r1 = registered(&gcs, "robot_1").await;
    let stranger = UdpSocket::bind("127.0.0.1:0").unwrap();
    let started = std::time::Instant::now();
    for i in 0..FLOOD {
        let _ = stranger.send_to(&i.to_be_bytes(), gcs.router().udp_addr());
        if i % 300 == 0 {
            r1.send_telemetry(telemetry(i as f64, 1.0, "", None)).await;
        }
        if i % 200 == 199 {
            // Paced so the kernel's buffers drop none of it: every datagram
            // reaches the router (read and refused, or shed unread while it
            // is behind: counted either way).
            tokio::time::sleep(Duration::from_millis(2)).await;
        }
    }
    let refused = |g: &Gcs| {
        let d = g.router().counters().dropped;
        d.bad_packet + d.shed
    };
    let read = eventually(Duration::from_secs(20), || refused(&gcs) == FLOOD).await;
    assert!(read, "{} of {FLOOD} refused", refused(&gcs));
    // Every second the flood was read in may begin a new budget.
    let seconds = started.elapsed().as_secs() + 1;
    let counted = |g: &Gcs| g.router().counters().received;
    let settled = eventually(Duration::from_secs(10), || {
        let s = gcs.recording().unwrap();
        s.messages + s.refused_unrecorded + s.dropped == counted(&gcs)
    })
    .await;
    assert!(settled, "{:?} vs {}", gcs.recording(), counted(&gcs));
    let status = gcs.stop_recording().await.unwrap();
    gcs.shutdown().await;

    assert_eq!(status.dropped, 0, "{status:?}");
    let replay = Replay::open(&file).unwrap();
    let whole = refused_recorded(&replay);
    assert_eq!(whole + status.refused_unrecorded, FLOOD, "{status:?}");
    assert!(
        whole <= 100 * (seconds + 1),
        "{whole} refused recorded whole in {seconds} s: {status:?}"
    );
    assert_eq!(replay.counts()["/robots/robot_1/pose"], 10);
    let end = replay.end_metadata().unwrap();
    assert_eq!(
        end["refused_unrecorded"],
        status.refused_unrecorded.to_string()
    );
}

/// Refused messages a recording holds whole: its decisions that say so.
fn refused_recorded(replay: &Replay) -> u64 {
    let bytes = std::fs::read(replay.path()).unwrap();
    let mut refused = 0;
    for m in mcap::MessageStream::new(&bytes).unwrap() {
        let m = m.unwrap();
        if m.channel.topic == "/mech/decisions" {
            let v: serde_json::Value = serde_json::from_slice(&m.data).unwrap();
            if matches!(v["reason"].as_str(), Some("bad-packet" | "shed")) {
                refused += 1;
            }
        }
    }
    refused
}

/// A recording that must be new never replaces what is there: an existing
/// file is refused and left as it was, a symbolic link is refused, not
/// followed; a new name is recorded to.
#[tokio::test]
async fn a_new_file_recording_refuses_an_existing_file_or_link() {
    let dir = tempfile::tempdir().unwrap();
    let gcs = gcs().await;
    let existing = dir.path().join("keep.mcap");
    std::fs::write(&existing, "an earlier experiment").unwrap();
    let e = gcs
        .start_recording(RecordTarget::NewFile(existing.clone()))
        .unwrap_err();
    assert!(e.to_string().contains("keep.mcap"), "{e}");
    assert_eq!(
        std::fs::read_to_string(&existing).unwrap(),
        "an earlier experiment"
    );
    let target = dir.path().join("target.txt");
    std::fs::write(&target, "not a recording").unwrap();
    let link = dir.path().join("link.mcap");
    std::os::unix::fs::symlink(&target, &link).unwrap();
    assert!(
        gcs.start_recording(RecordTarget::NewFile(link.clone()))
            .is_err()
    );
    assert_eq!(std::fs::read_to_string(&target).unwrap(), "not a recording");
    let fresh = dir.path().join("fresh.mcap");
    assert_eq!(
        gcs.start_recording(RecordTarget::NewFile(fresh.clone()))
            .unwrap(),
        fresh
    );
    let status = gcs.stop_recording().await.unwrap();
    assert_eq!(status.file, fresh);
    assert!(Replay::open(&fresh).is_ok());
    gcs.shutdown().await;
}

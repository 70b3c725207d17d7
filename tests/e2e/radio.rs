//! A serial radio at the station, end to end: the real `mech-gcs` with a
//! `[[router.serial]]` endpoint on a pseudo-terminal, two real agents on
//! the same "radio" (a frame hub between pseudo-terminal pairs), one of
//! them also on UDP (through a proxy that can cut it). When its UDP goes
//! silent the station commands it over the radio before its failsafe
//! trips, and back over UDP when UDP returns.

use std::path::Path;
use std::time::{Duration, Instant};

use mech_proto::FailsafeState;

use mech_e2e::harness::agent::{self, Agent};
use mech_e2e::harness::controller::Controller;
use mech_e2e::harness::proxy::UdpProxy;
use mech_e2e::harness::radio::{PtyPair, RadioHub};
use mech_e2e::harness::station::{self, Line, Station};
use mech_e2e::harness::unix_us;

/// The robots' failsafe: a 1 s channel timeout, twice the default. The
/// switch to the radio takes the router's link timeout (0.3 s of silence
/// on UDP) plus up to a telemetry and a command period (50 ms each) and
/// the radio hop: 0.32-0.35 s measured, inside the default 0.5 s; a loaded
/// machine (a CPU hog per core beside the suite) stretched it to 0.6 s
/// once, and rb's failsafe tripped for 0.1 s. The switch time is printed.
const FAILSAFE: &str = "channel_timeout = 1.0\nrouter_timeout = 2.0";

/// The active link of `robot` in the last `links` event before `until_us`.
fn active_at(lines: &[Line], robot: &str, until_us: u64) -> String {
    lines
        .iter()
        .rfind(|l| l.is_event("links") && l.robot() == robot && l.at_us <= until_us)
        .map(|l| l.json["active"].as_str().unwrap_or("").to_string())
        .unwrap_or_default()
}

/// Robot `ra` on the radio alone, `rb` on UDP through `wifi` first and
/// the radio second.
fn start_robots(
    dir: &std::path::Path,
    ra: &std::path::Path,
    rb: &std::path::Path,
    wifi: std::net::SocketAddr,
) -> (Agent, Agent) {
    let serial = |p: &std::path::Path| {
        format!(
            "kind = \"serial\"\nport = \"{}\"\nbaud = 115200\ntelemetry_rate_hz = 10",
            p.display()
        )
    };
    let a_links = format!("[link]\n{}", serial(ra));
    let b_links = format!(
        "[[links]]\nkind = \"udp\"\nrouter = \"{}\"\n[[links]]\n{}",
        wifi,
        serial(rb)
    );
    let a = Agent::start(
        "ra",
        &agent::config(dir, "ra", 1.0, &a_links, FAILSAFE),
        None,
    );
    let b = Agent::start(
        "rb",
        &agent::config(dir, "rb", 2.0, &b_links, FAILSAFE),
        None,
    );
    (a, b)
}

/// Waits (30 s at most) for a telemetry sample of `robot` stamped after
/// `end` whose failsafe holds for a silent channel.
fn wait_failsafe_tripped(ctl: &Controller, gcs: &Station, robot: &str, end: u64) {
    let deadline = Instant::now() + Duration::from_secs(30);
    while ctl
        .first(robot, end, |s| s.failsafe == FailsafeState::ChannelSilent)
        .is_none()
    {
        assert!(
            Instant::now() < deadline,
            "{robot}'s failsafe did not trip after the controller stopped (end {end}); \
             its last samples: {:#?}\nstation: {:#?}",
            last_samples(ctl, robot, 8),
            gcs.tail()
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// The last `n` telemetry samples of `robot` the controller received.
fn last_samples(
    ctl: &Controller,
    robot: &str,
    n: usize,
) -> Vec<mech_e2e::harness::controller::Sample> {
    let mut s: Vec<_> = ctl
        .samples()
        .into_iter()
        .filter(|s| s.robot == robot)
        .collect();
    let keep = s.len().saturating_sub(n);
    s.drain(..keep);
    s
}

/// The station saw rb on UDP until `cut`, then on the radio only until
/// `back`, then on UDP again by `end`; ra on the radio, with a budget.
fn the_station_followed_rbs_links(gcs: &Station, cut: u64, back: u64, end: u64) {
    let lines = gcs.lines();
    assert_eq!(active_at(&lines, "rb", cut), "udp", "{:#?}", gcs.tail());
    assert_eq!(active_at(&lines, "rb", back), "radio", "{:#?}", gcs.tail());
    assert_eq!(active_at(&lines, "rb", end), "udp", "{:#?}", gcs.tail());
    assert_eq!(
        active_at(&lines, "ra", end),
        "radio",
        "ra has only the radio"
    );
    let budget = lines
        .iter()
        .filter(|l| l.is_event("links") && l.robot() == "ra")
        .filter_map(|l| l.json["radio_budget_hz"].as_f64())
        .next_back();
    assert!(
        budget.is_some_and(|hz| hz > 0.0),
        "a radio budget: {budget:?}"
    );
    let switch = |after: u64, to: &str| {
        lines
            .iter()
            .find(|l| {
                l.is_event("links")
                    && l.robot() == "rb"
                    && l.at_us > after
                    && l.json["active"] == to
            })
            .map(|l| (l.at_us - after) / 1000)
    };
    println!(
        "rb: UDP cut -> radio active at the station after {:?} ms; UDP back -> UDP active after {:?} ms",
        switch(cut, "radio"),
        switch(back, "udp")
    );
}

#[test]
fn two_robots_share_a_radio_and_one_fails_over_from_udp_to_the_radio_and_back() {
    let dir = tempfile::tempdir().unwrap();
    let (air, ra, rb) = (
        PtyPair::new(dir.path(), "station"),
        PtyPair::new(dir.path(), "ra"),
        PtyPair::new(dir.path(), "rb"),
    );
    let _hub = RadioHub::start(&air.b, &[&ra.b, &rb.b], 0.0, 1);
    let port = station::free_port();
    let wifi = UdpProxy::start(
        "127.0.0.1:0".parse().unwrap(),
        format!("127.0.0.1:{port}").parse().unwrap(),
        2,
    );
    let radio = format!(
        "[[router.serial]]\nport = \"{}\"\nbaud = 115200\n",
        air.a.display()
    );
    let config = station::config(dir.path(), port, &radio);
    let script = "wait connected ra 20s\nwait connected rb 20s\nroute all ext/t\n\
                  wait route ra ext/t 5s\nwait route rb ext/t 5s\nlog routed\nsleep 60s\n";
    let gcs = Station::start(&config, script, dir.path());
    let (mut a, mut b) = start_robots(dir.path(), &ra.a, &rb.a, wifi.addr);
    let ctl = Controller::start(
        format!("127.0.0.1:{port}").parse().unwrap(),
        &["ra", "rb"],
        "ext/t",
        0.1,
    );
    ctl.publish(true);
    gcs.wait_log("routed", Duration::from_secs(40));
    std::thread::sleep(Duration::from_secs(2));

    let cut = unix_us();
    wifi.faults.block(true);
    std::thread::sleep(Duration::from_secs(3));
    let back = unix_us();
    wifi.faults.block(false);
    std::thread::sleep(Duration::from_secs(3));
    let end = unix_us();
    ctl.publish(false);
    // The final silence: each robot's failsafe trips a channel timeout
    // after the controller stopped, waited for in its telemetry.
    for robot in ["ra", "rb"] {
        wait_failsafe_tripped(&ctl, &gcs, robot, end);
    }
    let (ca, cb) = (a.stop(), b.stop());
    let logs = format!("ra:\n{}\nrb:\n{}", a.log(), b.log());

    the_station_followed_rbs_links(&gcs, cut, back, end);
    // rb kept driving while UDP was cut: its telemetry came over the radio.
    let during = ctl
        .samples()
        .into_iter()
        .filter(|s| s.robot == "rb" && s.stamp_us > cut + 1_000_000 && s.stamp_us < back)
        .collect::<Vec<_>>();
    assert!(
        !during.is_empty() && during.iter().all(|s| s.moving),
        "rb over the radio: {during:?}"
    );
    // Neither failsafe tripped before the controller stopped: the commands
    // never paused for the channel timeout (1 s), not even while rb
    // moved to the radio and back. The one trip each is the final silence.
    for (name, c) in [("ra", ca), ("rb", cb)] {
        let c = c.unwrap_or_else(|| panic!("{name} printed no counters"));
        assert_eq!(c["failsafe_trips"], 1, "{name}: {c}\n{logs}");
        assert!(c["commands"].as_u64().unwrap_or(0) > 100, "{name}: {c}");
    }
}

/// What the station's log files (`$XDG_STATE_HOME/mech/mech-gcs.log.*`)
/// hold so far.
fn station_log_files(state: &std::path::Path) -> String {
    std::fs::read_dir(state.join("mech"))
        .into_iter()
        .flatten()
        .flatten()
        .filter(|e| e.file_name().to_string_lossy().starts_with("mech-gcs.log"))
        .filter_map(|e| std::fs::read_to_string(e.path()).ok())
        .collect()
}

/// The radio unplugged at both ends (both `socat` pairs killed with
/// SIGKILL, their device names gone) and plugged back (new pairs under the
/// same names): the station and the agent each report the outage once,
/// the station shows the radio and the robot's radio link as down
/// meanwhile, and the robot is back on both links within 2 s of the
/// devices returning, with no process restarted.
#[test]
fn a_radio_unplugged_and_plugged_back_is_reopened_at_both_ends() {
    let dir = tempfile::tempdir().unwrap();
    let mut air = PtyPair::new(dir.path(), "station");
    let mut rb = PtyPair::new(dir.path(), "rb");
    let hub = RadioHub::start(&air.b, &[&rb.b], 0.0, 1);
    let (gcs, mut b) = station_and_robot(dir.path(), &air.a, &rb.a);
    gcs.wait(Duration::from_secs(20), on_both_links)
        .unwrap_or_else(|| panic!("rb never on both links: {:#?}", gcs.tail()));

    // Unplugged at both ends.
    let out = unix_us();
    drop(hub);
    air.unplug();
    rb.unplug();
    the_outage_is_shown(&gcs, dir.path(), out);

    // Plugged back in.
    let air = PtyPair::new(dir.path(), "station");
    let rb_back = PtyPair::new(dir.path(), "rb");
    let _hub = RadioHub::start(&air.b, &[&rb_back.b], 0.0, 2);
    let back = unix_us();
    let again = gcs
        .wait(Duration::from_secs(20), |l| {
            on_both_links(l) && l.at_us > back
        })
        .unwrap_or_else(|| panic!("rb never back on both links: {:#?}", gcs.tail()));
    let took_ms = (again.at_us - back) / 1000;
    println!("rb back on Wi-Fi and radio {took_ms} ms after the radio returned");
    assert!(took_ms < 2_000, "{took_ms} ms: {:#?}", gcs.tail());
    // The station's end may reopen before the robot's returns.
    assert!(
        gcs.wait(Duration::from_secs(20), radio_event(true, out))
            .is_some(),
        "the station said its radio reopened: {:#?}",
        gcs.tail()
    );
    let lines = gcs.lines();
    let failures = lines.iter().filter(|l| radio_event(false, 0)(l)).count();
    assert_eq!(failures, 1, "one outage, reported once");

    b.stop();
    let log = b.log();
    let said = |what: &str| log.lines().filter(|l| l.contains(what)).count();
    assert_eq!(said("serial link failed"), 1, "once per outage:\n{log}");
    assert_eq!(said("serial link reopened"), 1, "{log}");
    assert_eq!(said("write error"), 0, "{log}");
}

/// A station with its radio on `station_port`, and robot `rb` on Wi-Fi and
/// on a radio at `robot_port`, once it is connected.
fn station_and_robot(dir: &Path, station_port: &Path, robot_port: &Path) -> (Station, Agent) {
    let port = station::free_port();
    let radio = format!(
        "[[router.serial]]\nport = \"{}\"\nbaud = 115200\n",
        station_port.display()
    );
    let config = station::config(dir, port, &radio);
    let gcs = Station::start(
        &config,
        "wait connected rb 20s\nlog connected\nsleep 120s\n",
        dir,
    );
    let links = format!(
        "[[links]]\nkind = \"udp\"\nrouter = \"127.0.0.1:{port}\"\n[[links]]\n\
         kind = \"serial\"\nport = \"{}\"\nbaud = 115200\ntelemetry_rate_hz = 10",
        robot_port.display()
    );
    let b = Agent::start("rb", &agent::config(dir, "rb", 1.0, &links, FAILSAFE), None);
    gcs.wait_log("connected", Duration::from_secs(40));
    (gcs, b)
}

/// The station says rb is heard on both links.
fn on_both_links(l: &Line) -> bool {
    l.is_event("links") && l.robot() == "rb" && l.json["udp"] == true && l.json["radio"].is_string()
}

/// A `radio` event saying the radio is `up` (or not), after `after` (µs).
fn radio_event(up: bool, after: u64) -> impl Fn(&Line) -> bool {
    move |l: &Line| l.is_event("radio") && l.json["up"] == up && l.at_us > after
}

/// After the radio was unplugged at `out` (µs): the station reports its
/// radio failed, shows rb's radio link down with Wi-Fi live, and has rb's
/// own outage notice (sent over Wi-Fi) in its log file.
fn the_outage_is_shown(gcs: &Station, dir: &Path, out: u64) {
    let failed = gcs
        .wait(Duration::from_secs(20), radio_event(false, out))
        .unwrap_or_else(|| panic!("no radio failure reported: {:#?}", gcs.tail()));
    assert!(
        failed.json["port"]
            .as_str()
            .is_some_and(|p| p.ends_with("station-a")),
        "{}",
        failed.json
    );
    let radio_down = gcs.wait(Duration::from_secs(20), |l| {
        l.is_event("links")
            && l.robot() == "rb"
            && l.at_us > out
            && l.json["udp"] == true
            && l.json["radio"].is_null()
            && l.json["down"]
                .as_array()
                .is_some_and(|d| d.contains(&"radio".into()))
    });
    assert!(
        radio_down.is_some(),
        "rb's radio link shown as down, Wi-Fi live: {:#?}",
        gcs.tail()
    );
    mech_e2e::harness::poll(Duration::from_secs(20), || {
        station_log_files(dir)
            .lines()
            .any(|l| l.contains("notice: serial link") && l.contains("down"))
            .then_some(())
    })
    .unwrap_or_else(|| {
        panic!(
            "rb's outage notice not in the station's log file:\n{}\n{:#?}",
            station_log_files(dir),
            gcs.tail()
        )
    });
}

//! A serial radio at the station, end to end: the real `mech-gcs` with a
//! `[[router.serial]]` endpoint on a pseudo-terminal, two real agents on
//! the same "radio" (a frame hub between pseudo-terminal pairs), one of
//! them also on UDP (through a proxy that can cut it). When its UDP goes
//! silent the station commands it over the radio before its failsafe
//! trips, and back over UDP when UDP returns.

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
        let deadline = Instant::now() + Duration::from_secs(30);
        while ctl
            .first(robot, end, |s| s.failsafe == FailsafeState::ChannelSilent)
            .is_none()
        {
            assert!(
                Instant::now() < deadline,
                "{robot}'s failsafe did not trip after the controller stopped"
            );
            std::thread::sleep(Duration::from_millis(50));
        }
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

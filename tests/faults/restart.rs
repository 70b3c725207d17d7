//! Restarts: the station killed (SIGKILL) and started again while robots
//! drive; an agent killed in the middle of a waypoint mission and started
//! again.

use std::time::Duration;

use crate::figures::Figures;
use crate::rig::{CHANNEL, Rig, names};
use mech_e2e::harness::station::{Line, Station};
use mech_e2e::harness::unix_us;

/// The restarted station's script: registration, two seconds in which
/// nobody has routed the robots, then routing.
fn after_restart(robots: &[String]) -> String {
    let mut s = String::new();
    for r in robots {
        s += &format!("wait connected {r} 10s\n");
    }
    s += "log registered\nsleep 2s\nlog holding\nsleep 500ms\n";
    s + &format!("route all {CHANNEL}\nsleep 600s\n")
}

/// The station is killed while three robots drive and started again half
/// a second later. Required: each robot registered within 1 s of the
/// station being back, and held still (routed to none, though the
/// controller kept publishing) until routed. The robots' router timeout
/// is 2 s (a radio robot's): they learn of the restart from the station,
/// not from their timeout.
pub fn station(failures: &mut Vec<String>) -> Figures {
    let mut rig = Rig::udp(
        3,
        false,
        "channel_timeout = 0.5\nrouter_timeout = 2.0",
        None,
    );
    rig.wait_routed();
    std::thread::sleep(Duration::from_secs(2));
    rig.station.kill();
    std::thread::sleep(Duration::from_millis(500));
    let config = rig.dir.path().join("gcs.toml");
    rig.station = Station::start(&config, &after_restart(&names(3)), rig.dir.path());
    let holding = rig.station.wait_log("holding", Duration::from_secs(30));
    std::thread::sleep(Duration::from_secs(1));
    let lines = rig.station.lines();
    let registered: Vec<&Line> = lines.iter().filter(|l| l.is_event("registered")).collect();
    let worst = registered.iter().map(|l| l.t()).fold(0.0, f64::max);
    if registered.len() < 3 || worst > 1.0 {
        failures.push(format!(
            "station restart: every robot must register within 1 s of the station being back; \
             {} did, the last after {worst:.3} s",
            registered.len()
        ));
    }
    for r in &names(3) {
        let since = registered
            .iter()
            .find(|l| l.robot() == r)
            .map_or(holding.at_us, |l| l.at_us);
        let held: Vec<_> = rig
            .ctl
            .samples()
            .into_iter()
            .filter(|s| &s.robot == r && s.stamp_us > since && s.stamp_us < holding.at_us)
            .collect();
        if held.is_empty() || held.iter().any(|s| s.moving || !s.channel.is_empty()) {
            failures.push(format!(
                "station restart: {r} must hold still, routed to none, until routed: {held:?}"
            ));
        }
    }
    Figures {
        scenario: "station kill -9, restarted after 0.5 s, 3 robots".into(),
        recovery_ms: Some(worst * 1000.0),
        note: "recovery: station back to every robot registered".into(),
        ..Figures::default()
    }
}

/// The restarted agent's station script: r1 runs a looping waypoint
/// mission, r2 is driven; when r1 comes back, its status is asked.
fn mission_script() -> String {
    format!(
        "wait connected r1 30s\nwait connected r2 30s\nwaypoint r1 3.0,2.0 0.5,1.0 loop\nsend r1\n\
         route r1 wp/gcs\nroute r2 {CHANNEL}\nwait route r1 wp/gcs 20s\nlog mission\n\
         wait lost r1 30s\nwait connected r1 30s\nlog back\nsleep 3s\nstatus r1\nlog done\nsleep 600s\n"
    )
}

/// An agent is killed in the middle of its mission and started again.
/// Required: it does not resume the mission by itself (it holds still),
/// and the station reports the mission lost.
pub fn agent(failures: &mut Vec<String>) -> Figures {
    let mut rig = Rig::udp(2, false, crate::rig::FAILSAFE, Some(&mission_script()));
    let mission = rig.station.wait_log("mission", Duration::from_secs(60));
    // Killed only once seen running its mission (on a loaded machine that
    // can take a while after the route is acknowledged), and a moment
    // into it.
    let deadline = std::time::Instant::now() + Duration::from_secs(15);
    let ran = loop {
        let ran = rig
            .ctl
            .first("r1", mission.at_us, |s| s.moving && s.mission.is_some());
        if ran.is_some() || std::time::Instant::now() > deadline {
            break ran;
        }
        std::thread::sleep(Duration::from_millis(100));
    };
    std::thread::sleep(Duration::from_millis(500));
    rig.agents[0].kill();
    // Restart once the script has seen the robot lost (not only the event:
    // on a loaded machine the script could otherwise miss a lost state
    // that lasts a few milliseconds).
    let lost = rig.station.wait(Duration::from_secs(15), |l| {
        l.json["type"] == "result" && l.json["command"] == "wait lost r1 30s"
    });
    let restarted = unix_us();
    rig.agents[0].restart(None);
    let done = rig.station.wait_log("done", Duration::from_secs(40));
    let lines = rig.station.lines();
    let after: Vec<_> = rig
        .ctl
        .samples()
        .into_iter()
        .filter(|s| s.robot == "r1" && s.stamp_us > restarted && s.stamp_us < done.at_us)
        .collect();
    let held = after.len() >= 10 && after.iter().all(|s| !s.moving && s.mission.is_none());
    let status = lines
        .iter()
        .find(|l| l.json["command"] == "status r1")
        .map(|l| l.json.to_string())
        .unwrap_or_default();
    if ran.is_none() || lost.is_none() || !held || !status.contains("lost") {
        failures.push(format!(
            "agent restart: it must not resume its mission by itself, and the station must say \
             the mission was lost; ran before: {}, held after: {held} ({} samples), status: {status}",
            ran.is_some(),
            after.len()
        ));
    }
    let back = lines
        .iter()
        .filter(|l| l.is_event("registered") && l.robot() == "r1" && l.at_us > restarted)
        .map(|l| (l.at_us - restarted) as f64 / 1000.0)
        .next();
    Figures {
        scenario: "agent kill -9 mid-mission, restarted".into(),
        recovery_ms: back,
        note: "recovery: restart to registered; held still, mission reported lost".into(),
        ..Figures::default()
    }
}

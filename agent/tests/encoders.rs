//! Wheel encoders on a simulated robot, driven through the real agent core
//! in stepped time: the speed loop holds the commanded wheel speed on a full
//! and on a half-charged battery, a jammed wheel is caught within the stall
//! time, and telemetry says whether its velocity was measured.
#![allow(clippy::unwrap_used)]

use std::time::Duration;

use mech_agent::AgentSettings;
use mech_agent::platform::PlatformSpec;
use mech_agent::sim::{SimAgent, SimEncoderModel};
use mech_agent::wheels::{PiGains, StallSettings, WheelSettings};
use mech_proto::{
    Body, Command, Envelope, FailsafeState, Header, Health, Heartbeat, NoticeCode, Pose, Route,
    Twist, VelocitySource, Welcome,
};

const PERIOD: Duration = Duration::from_millis(20);

fn wheels(model: &SimEncoderModel, closed_loop: bool) -> WheelSettings {
    WheelSettings {
        counting: model.counting,
        counts_per_revolution: model.counts_per_revolution,
        wheel_radius: model.wheel_radius,
        speed_loop: closed_loop.then(PiGains::default),
        stall: StallSettings::default(),
    }
}

/// A simulated diff-drive (0.5 m/s wheels) routed to `joy/0`, with
/// encoders of the default model when `wheels` is set, at `battery`.
fn robot(wheel_settings: Option<WheelSettings>, battery: f64) -> SimAgent {
    let mut settings = AgentSettings::new("r1");
    settings.wheels = wheel_settings;
    let mut sim = SimAgent::new(
        settings,
        &PlatformSpec::diff_drive(),
        Pose::default(),
        None,
        0,
    )
    .with_encoders(SimEncoderModel::default(), 7);
    sim.robot.set_battery(battery);
    let welcome = Body::Welcome(Welcome {
        robot_id: 1,
        route: Route {
            robot: "r1".into(),
            channel: "joy/0".into(),
            epoch: 1,
        },
        router_version: "t".into(),
    });
    sim.tick(Duration::ZERO);
    sim.handle(message("", 0, welcome), Duration::ZERO);
    sim
}

fn message(channel: &str, seq: u32, body: Body) -> Envelope {
    Envelope::new(
        Header {
            seq,
            sender: "ctl".into(),
            destination: "r1".into(),
            channel: channel.into(),
            ..Header::default()
        },
        body,
    )
}

/// Drives `sim` with a forward twist of `vx` from `from` until `until`
/// (a command and a router heartbeat every 100 ms), calling `each` after
/// every tick with the outgoing messages.
fn drive(
    sim: &mut SimAgent,
    vx: f64,
    from: Duration,
    until: Duration,
    mut each: impl FnMut(&mut SimAgent, Duration, Vec<Envelope>),
) {
    let mut now = from;
    let mut seq = from.as_millis() as u32;
    while now < until {
        now += PERIOD;
        if now.as_millis().is_multiple_of(100) {
            seq += 1;
            let twist = Body::Command(Command::Twist(Twist {
                vx,
                ..Twist::default()
            }));
            sim.handle(message("joy/0", seq, twist), now);
            sim.handle(
                message("", seq, Body::Heartbeat(Heartbeat { uptime_ms: 0 })),
                now,
            );
        }
        let out = sim.tick(now);
        each(sim, now, out);
    }
}

/// Mean true rim speed of each wheel over the last second of 3 s driving
/// forward at `vx`.
fn settled_wheel_speeds(sim: &mut SimAgent, vx: f64) -> Vec<f64> {
    let mut sums = [0.0; 2];
    let mut n = 0.0;
    drive(
        sim,
        vx,
        Duration::ZERO,
        Duration::from_secs(3),
        |s, now, _| {
            if now > Duration::from_secs(2) {
                for (sum, w) in sums.iter_mut().zip(s.robot.wheel_speeds()) {
                    *sum += w;
                }
                n += 1.0;
            }
        },
    );
    sums.iter().map(|s| s / n).collect()
}

#[test]
fn speed_loop_reaches_the_commanded_wheel_speed_at_full_and_half_battery() {
    let model = SimEncoderModel::default();
    for battery in [1.0, 0.5] {
        let mut sim = robot(Some(wheels(&model, true)), battery);
        for (i, v) in settled_wheel_speeds(&mut sim, 0.2).iter().enumerate() {
            assert!(
                (v - 0.2).abs() <= 0.2 * 0.05,
                "battery {battery}: wheel {i} at {v} m/s, 0.2 commanded"
            );
        }
    }
    // Open loop, the same half battery makes half the speed.
    let mut open = robot(None, 0.5);
    for v in settled_wheel_speeds(&mut open, 0.2) {
        assert!((v - 0.1).abs() < 0.01, "open loop at half battery: {v}");
    }
}

#[test]
fn a_jammed_wheel_is_caught_within_the_stall_time() {
    let model = SimEncoderModel::default();
    let stall_time = StallSettings::default().time;
    let mut sim = robot(Some(wheels(&model, true)), 1.0);
    let jam = Duration::from_secs(1);
    let mut caught = None;
    let mut notices = vec![];
    drive(
        &mut sim,
        0.2,
        Duration::ZERO,
        Duration::from_millis(3100),
        |s, now, out| {
            if now == jam {
                s.robot.set_jammed(0, true);
            }
            notices.extend(out.into_iter().filter_map(|e| match e.body {
                Body::Notice(n) => Some(n),
                _ => None,
            }));
            if caught.is_none() && s.agent.failsafe_state(now) == FailsafeState::Fault {
                caught = Some(now);
                assert!(
                    s.agent.outputs().iter().all(|u| *u == 0.0),
                    "outputs zeroed"
                );
                assert_eq!(s.agent.telemetry(now).health, Health::Fault);
            }
        },
    );
    let caught = caught.expect("the stall was caught");
    let after = caught - jam;
    assert!(
        after >= stall_time && after <= stall_time + PERIOD,
        "caught {after:?} after the jam (stall time {stall_time:?})"
    );
    // Held at zero for a second; the controller still commands, so the
    // wheel is tried again and, still jammed, caught again a stall time on.
    assert_eq!(sim.agent.counters().stalls, 2);
    let fault = notices
        .iter()
        .find(|n| n.code == NoticeCode::DriverFault)
        .expect("a driver fault notice");
    assert!(
        fault.text.starts_with("left wheel stalled"),
        "{:?}",
        fault.text
    );
}

#[test]
fn no_stall_without_a_jam_even_on_a_weak_battery() {
    let model = SimEncoderModel::default();
    let mut sim = robot(Some(wheels(&model, true)), 0.4);
    drive(
        &mut sim,
        0.3,
        Duration::ZERO,
        Duration::from_secs(5),
        |s, now, _| {
            assert_ne!(
                s.agent.failsafe_state(now),
                FailsafeState::Fault,
                "at {now:?}"
            );
        },
    );
    assert_eq!(sim.agent.counters().stalls, 0);
}

#[test]
fn telemetry_says_whether_its_velocity_was_measured() {
    let model = SimEncoderModel::default();
    // Measuring only (open loop) on a half battery: the encoders see the
    // robot make half of what its outputs ask for.
    let mut sim = robot(Some(wheels(&model, false)), 0.5);
    let mut last = None;
    drive(
        &mut sim,
        0.2,
        Duration::ZERO,
        Duration::from_secs(2),
        |s, now, _| {
            last = Some(s.agent.telemetry(now));
        },
    );
    let t = last.unwrap();
    assert_eq!(t.velocity_source, VelocitySource::Measured);
    assert!((t.velocity.vx - 0.1).abs() < 0.01, "{:?}", t.velocity);

    let mut blind = robot(None, 0.5);
    let mut last = None;
    drive(
        &mut blind,
        0.2,
        Duration::ZERO,
        Duration::from_secs(2),
        |s, now, _| {
            last = Some(s.agent.telemetry(now));
        },
    );
    let t = last.unwrap();
    assert_eq!(t.velocity_source, VelocitySource::Commanded);
    assert!((t.velocity.vx - 0.2).abs() < 1e-9, "{:?}", t.velocity);
}

//! Fixed fleets with known values, for screen snapshots, benchmarks and
//! trying the UI without a router. Deterministic: no clock, no randomness.

use std::time::{Duration, Instant};

use mech_proto::{Computation, ControlMode, FailsafeState, Health, MissionProgress, Velocity};

use super::app::{Action, App};
use super::view::{
    ArenaBounds, ChannelView, FleetSnapshot, LinkQuality, LinkState, RobotView, RouteView, Security,
};

const PLATFORMS: [&str; 3] = ["diff-drive", "kiwi", "quadcopter"];

/// `n` robots on a ring, with a mix of platforms, routes, links and states.
pub fn fleet(n: usize) -> FleetSnapshot {
    FleetSnapshot {
        robots: (0..n).map(|i| robot(i, n)).collect(),
        security: Security::Authenticated,
        rejected: 0,
        replay: None,
        arena: None,
        channels: vec![
            ChannelView {
                name: "joy/0".into(),
                publisher: "gcs".into(),
                rate_hz: 20.0,
            },
            ChannelView {
                name: "wp/gcs".into(),
                publisher: "gcs".into(),
                rate_hz: 0.5,
            },
        ],
        estop: false,
        clusters: None,
    }
}

/// Robot `i` of a ring of `n`: its place, platform, battery, speed and
/// link quality vary with `i`, and its route and state with `i % 4`.
fn robot(i: usize, n: usize) -> RobotView {
    let a = i as f64 * std::f64::consts::TAU / n.max(1) as f64;
    let radius = 1.5 + (i % 3) as f64 * 0.5;
    let mut r = RobotView::at(
        &format!("robot_{}", i + 1),
        (i + 1) as u16,
        PLATFORMS[i % PLATFORMS.len()],
        radius * a.cos(),
        radius * a.sin(),
        a + std::f64::consts::FRAC_PI_2,
    );
    r.telemetry.battery = Some(1.0 - (i % 10) as f64 * 0.07);
    r.telemetry.velocity = Velocity {
        vx: 0.1 * (i % 4) as f64,
        vy: 0.0,
        vz: 0.0,
        wz: 0.0,
    };
    r.quality = LinkQuality {
        rx_hz: 21.0 - (i % 5) as f64,
        tx_hz: 4.0 + (i % 3) as f64 * 10.0,
        loss: Some((i % 5) as f64 * 0.06),
        rtt: Some(Duration::from_micros(300 + 700 * (i % 7) as u64)),
        window: Duration::from_secs(5),
        received: 1000 + i as u64,
        sent: 200 + i as u64,
        lost: (i % 5) as u64 * 60,
    };
    match i % 4 {
        0 => {
            r.route = RouteView {
                channel: "wp/gcs".into(),
                acknowledged: true,
            };
            r.telemetry.mode = ControlMode::Waypoints;
            r.telemetry.mission = Some(MissionProgress {
                id: 1,
                next: 1,
                total: 3,
            });
        }
        1 => {
            r.route = RouteView {
                channel: "joy/0".into(),
                acknowledged: false,
            };
            r.telemetry.mode = ControlMode::Twist;
        }
        2 => {
            r.link = LinkState::Stale;
            r.telemetry.failsafe = FailsafeState::ChannelSilent;
            r.route = RouteView {
                channel: "offboard/robot_3".into(),
                acknowledged: true,
            };
            r.telemetry.computation = Computation::Offboard;
            r.telemetry.health = Health::Degraded;
        }
        _ => {
            r.link = LinkState::Lost;
            r.telemetry.failsafe = FailsafeState::RouterLost;
        }
    }
    r
}

/// An App showing [`fleet`]`(n)` on a `w x h` terminal, with the arena,
/// the first robot selected and the view fitted.
pub fn app(n: usize, w: u16, h: u16) -> App {
    let now = Instant::now();
    let mut app = App::new("127.0.0.1:7700", now);
    app.map.arena = Some(ArenaBounds {
        min_x: -3.0,
        min_y: -3.0,
        max_x: 3.0,
        max_y: 3.0,
    });
    app.update(Action::Resize(w, h));
    app.update(Action::Fleet(fleet(n)));
    app.update(Action::FitFleet);
    app
}

/// The last minute of [`fleet`]`(n)`, played into `app`: a snapshot every
/// [`SAMPLE_PERIOD`](super::app::SAMPLE_PERIOD) on the App's clock, each
/// robot driving along its heading at 5 cm/s more than its fixture speed
/// (and reporting a little less a minute ago), turning a little, its
/// battery draining and its link's loss and round trip wandering, so that
/// the last snapshot is `fleet(n)` but for the speeds. Deterministic: every
/// value is a function of the robot and the time.
pub fn minute(app: &mut App, n: usize) {
    // After the App's first snapshot, which falls out of the minute.
    let start = app.manual.now + Duration::from_secs_f64(super::app::SAMPLE_PERIOD);
    let steps = (super::app::HISTORY_SECONDS / super::app::SAMPLE_PERIOD) as u32;
    for k in 0..=steps {
        let t = f64::from(k) * super::app::SAMPLE_PERIOD;
        let ago = super::app::HISTORY_SECONDS - t;
        let mut f = fleet(n);
        for (i, r) in f.robots.iter_mut().enumerate() {
            let phase = i as f64;
            let speed = r.telemetry.velocity.vx + 0.05;
            let turn = 0.004 * (i % 3) as f64;
            r.telemetry.pose.heading -= turn * ago;
            r.telemetry.pose.x -= speed * ago * r.telemetry.pose.heading.cos();
            r.telemetry.pose.y -= speed * ago * r.telemetry.pose.heading.sin();
            r.telemetry.velocity.vx = speed * (1.0 - ago / 120.0);
            r.telemetry.battery = r.telemetry.battery.map(|b| (b + 0.002 * ago).min(1.0));
            let wave = ((t / 6.0 + phase).sin() * 0.5 + 0.5) * (ago / 60.0);
            r.quality.loss = r.quality.loss.map(|l| l + 0.04 * wave);
            r.quality.rtt = r
                .quality
                .rtt
                .map(|d| d + Duration::from_micros((800.0 * wave) as u64));
        }
        app.update(Action::Tick(start + Duration::from_secs_f64(t)));
        app.update(Action::Fleet(f));
    }
}

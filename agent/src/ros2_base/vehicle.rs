//! [`Ros2Vehicle`]: the agent core driving a ROS 2 mobile base. Each
//! control period it takes in what the base said (odometry as the position
//! and the measured velocity, transforms, battery, other writers on its
//! `cmd_vel`), runs the core, turns the core's outputs into the body twist
//! they mean (the platform's forward kinematics) and publishes it on the
//! base's `cmd_vel`, and puts the battery into the telemetry.
//!
//! Safety: whenever the core holds its outputs at zero (channel silent,
//! router lost, e-stop, routed to none, a fault) the published twist is
//! zero, and it is published every period, since bases differ in whether
//! they stop by themselves when `cmd_vel` goes quiet. While the base's
//! odometry is silent or refused, or another node writes on its `cmd_vel`,
//! the outputs are held at zero too (state `Fault`, said to the station),
//! and a mission waits for the base rather than ending. When the agent stops it publishes zero a few times; when it
//! dies the stream stops and only a base's own `cmd_vel` timeout stops it.

use std::time::Duration;

use mech_proto::Envelope;

use super::link::{BasePort, FromBase};
use super::session::BaseSession;
use crate::hal::PositionSample;
use crate::machine::Agent;
use crate::runtime::{Report, Vehicle};

/// At most this many samples are taken in per control period; the rest
/// wait for the next (a flood cannot hold the loop).
const INTAKE: usize = 1024;

/// How long a refused odometry sample holds the outputs at zero.
const REFUSED_HOLD: Duration = Duration::from_secs(1);

/// A hold for the period at hand (renewed each period while it lasts).
const HOLD_NOW: Duration = Duration::from_millis(1);

/// How many zero twists the agent publishes as it stops.
const LAST_ZEROS: usize = 3;

/// The agent core, what it knows of the base, and the base's topics.
#[derive(Debug)]
pub struct Ros2Vehicle<P> {
    pub agent: Agent,
    pub session: BaseSession,
    pub port: P,
    /// Microseconds since the Unix epoch at the agent's time zero, for
    /// `TwistStamped` stamps.
    stamp_origin: u64,
}

impl<P: BasePort> Ros2Vehicle<P> {
    pub fn new(agent: Agent, session: BaseSession, port: P, stamp_origin: u64) -> Ros2Vehicle<P> {
        Ros2Vehicle {
            agent,
            session,
            port,
            stamp_origin,
        }
    }

    fn say(&mut self, r: Report, now: Duration, out: &mut Vec<Envelope>) {
        out.push(r.notice(&mut self.agent, now));
    }

    /// Everything the base said since the last period.
    fn take_in(&mut self, now: Duration, out: &mut Vec<Envelope>) {
        for _ in 0..INTAKE {
            let Some(sample) = self.port.try_recv() else {
                break;
            };
            match sample {
                FromBase::Odometry(o) => match self.session.odometry(&o, now) {
                    Ok(report) => {
                        if let Some(r) = report {
                            self.say(r, now, out);
                        }
                    }
                    Err(why) => {
                        self.agent.count_refused();
                        if let Some(r) = self.session.refusal(why.clone(), now) {
                            self.say(r, now, out);
                        }
                        out.extend(self.agent.hold_outputs(&why, now + REFUSED_HOLD, now));
                    }
                },
                FromBase::Transforms(tf) => self.session.transforms(&tf),
                FromBase::Battery(b) => self.session.battery(&b),
                FromBase::ForeignCmdVel { writer } => {
                    if let Some(r) = self.session.foreign_cmd_vel(&writer, now) {
                        self.say(r, now, out);
                    }
                }
                FromBase::Unreadable { topic, error } => {
                    self.agent.count_refused();
                    let why = format!("a sample on {topic} does not decode: {error}");
                    if let Some(r) = self.session.refusal(why, now) {
                        self.say(r, now, out);
                    }
                }
            }
        }
        for r in self.session.check(now) {
            self.say(r, now, out);
        }
        if let Some((twist, at)) = self.session.twist() {
            self.agent.observe_velocity(twist, at);
        }
        if let Some(pose) = self.session.take_pose() {
            self.agent.observe_position(PositionSample {
                pose,
                stamp: now,
                quality: 1.0,
                has_heading: true,
            });
        }
        if let Some(why) = self.session.hold(now) {
            // Held at zero (state fault) for this period; said again each
            // period while it lasts. A mission waits.
            out.extend(self.agent.hold_outputs(&why, now + HOLD_NOW, now));
        }
    }

    fn publish(&mut self, twist: &mech_proto::Twist, now: Duration, out: &mut Vec<Envelope>) {
        let stamp = self.stamp_origin + now.as_micros() as u64;
        if let Err(e) = self.port.publish(&BaseSession::command(twist), stamp) {
            tracing::warn!(error = %e, "ROS 2 base");
            out.extend(self.agent.actuator_fault(&e.to_string(), now));
        }
    }
}

impl<P: BasePort> Vehicle for Ros2Vehicle<P> {
    fn agent(&self) -> &Agent {
        &self.agent
    }

    fn agent_mut(&mut self) -> &mut Agent {
        &mut self.agent
    }

    fn tick(&mut self, now: Duration) -> Vec<Envelope> {
        let mut out = Vec::new();
        self.take_in(now, &mut out);
        let tick = self.agent.tick(now);
        let twist = self.agent.platform().motion(&tick.outputs);
        self.publish(&twist, now, &mut out);
        let mut outgoing = tick.outgoing;
        crate::runtime::patch_telemetry(&mut outgoing, |t| self.session.patch(t));
        outgoing.extend(out);
        outgoing
    }

    /// Zero, a few times (a best-effort reader may miss one); then the
    /// stream stops.
    fn stop(&mut self, now: Duration) -> Envelope {
        let mut ignored = Vec::new();
        for _ in 0..LAST_ZEROS {
            self.publish(&mech_proto::Twist::default(), now, &mut ignored);
        }
        self.agent.bye("shutdown", now)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::hal::HalError;
    use crate::machine::AgentSettings;
    use crate::platform::PlatformSpec;
    use crate::ros2_base::config::Ros2Config;
    use mech_proto::{
        Body, Command, EStop, FailsafeState, Header, Heartbeat, Route, Twist, Welcome,
    };
    use mech_ros2_dds::msgs::geometry::{Quaternion, Twist as RosTwist};
    use mech_ros2_dds::msgs::nav::Odometry;
    use mech_ros2_dds::msgs::sensor::BatteryState;
    use std::collections::VecDeque;

    /// A base the test plays: what the agent published, what it hears.
    #[derive(Debug, Default)]
    struct Bench {
        published: Vec<RosTwist>,
        heard: VecDeque<FromBase>,
    }

    impl BasePort for Bench {
        fn publish(&mut self, twist: &RosTwist, _: u64) -> Result<(), HalError> {
            self.published.push(*twist);
            Ok(())
        }
        fn try_recv(&mut self) -> Option<FromBase> {
            self.heard.pop_front()
        }
    }

    const MS: Duration = Duration::from_millis(1);

    fn vehicle() -> Ros2Vehicle<Bench> {
        let mut settings = AgentSettings::new("tb3_1");
        settings.has_position = true;
        settings.filter_window = 1;
        settings.safety.position_error = 0.0;
        let agent = Agent::new(settings, PlatformSpec::diff_drive().build(), 0);
        let config: Ros2Config = toml::from_str("namespace = \"/tb3_1\"").unwrap();
        Ros2Vehicle::new(agent, BaseSession::new(&config), Bench::default(), 0)
    }

    fn odometry(x: f64, vx: f64) -> FromBase {
        let mut o = Odometry::default();
        o.header.frame_id = "odom".into();
        o.pose.pose.position.x = x;
        o.pose.pose.orientation = Quaternion::from_yaw(0.0);
        o.twist.twist.linear.x = vx;
        FromBase::Odometry(Box::new(o))
    }

    fn msg(channel: &str, body: Body) -> Envelope {
        Envelope::new(
            Header {
                destination: "tb3_1".into(),
                channel: channel.into(),
                ..Header::default()
            },
            body,
        )
    }

    fn routed(v: &mut Ros2Vehicle<Bench>, now: Duration) {
        let welcome = Welcome {
            robot_id: 1,
            route: Route {
                robot: "tb3_1".into(),
                channel: "joy/0".into(),
                epoch: 1,
            },
            router_version: "t".into(),
        };
        v.handle(msg("", Body::Welcome(welcome)), now);
    }

    fn drive(v: &mut Ros2Vehicle<Bench>, now: Duration) {
        let forward = Command::Twist(Twist {
            vx: 0.2,
            ..Twist::default()
        });
        v.handle(msg("joy/0", Body::Command(forward)), now);
    }

    fn last(v: &Ros2Vehicle<Bench>) -> (f64, f64) {
        let t = v.port.published.last().expect("published");
        (t.linear.x, t.angular.z)
    }

    fn notices(out: &[Envelope]) -> Vec<String> {
        out.iter()
            .filter_map(|e| match &e.body {
                Body::Notice(n) => Some(n.text.clone()),
                _ => None,
            })
            .collect()
    }

    #[test]
    fn a_routed_twist_drives_the_base_and_the_pose_is_its_odometry() {
        let mut v = vehicle();
        v.port.heard.push_back(odometry(1.0, 0.0));
        v.tick(Duration::ZERO);
        assert_eq!(last(&v), (0.0, 0.0), "unrouted: zero");
        routed(&mut v, 10 * MS);
        drive(&mut v, 20 * MS);
        v.port.heard.push_back(odometry(1.0, 0.1));
        let out = v.tick(40 * MS);
        assert_eq!(last(&v), (0.2, 0.0));
        assert_eq!(v.agent.estimate().unwrap().pose.x, 1.0);
        let t = out
            .iter()
            .find_map(|e| match &e.body {
                Body::Telemetry(t) => Some(t.clone()),
                _ => None,
            })
            .expect("telemetry");
        assert_eq!(t.velocity_source, mech_proto::VelocitySource::Measured);
        assert!((t.velocity.vx - 0.1).abs() < 1e-9, "{:?}", t.velocity);
    }

    #[test]
    fn zero_is_published_every_period_while_held() {
        let mut v = vehicle();
        routed(&mut v, Duration::ZERO);
        v.port.heard.push_back(odometry(0.0, 0.0));
        drive(&mut v, 10 * MS);
        v.tick(20 * MS);
        assert_eq!(last(&v), (0.2, 0.0));
        // Controller silent: zero, every period.
        for t in [600u32, 650, 700] {
            v.handle(
                msg("", Body::Heartbeat(Heartbeat::new(u64::from(t)))),
                t * MS,
            );
            v.port.heard.push_back(odometry(0.0, 0.0));
            v.tick(t * MS);
            assert_eq!(last(&v), (0.0, 0.0));
        }
        assert_eq!(
            v.agent.failsafe_state(700 * MS),
            FailsafeState::ChannelSilent
        );
        // E-stop: zero too, and the station loss after it.
        drive(&mut v, 710 * MS);
        v.handle(
            msg(
                "",
                Body::EStop(EStop {
                    engage: true,
                    id: 1,
                }),
            ),
            720 * MS,
        );
        v.port.heard.push_back(odometry(0.0, 0.0));
        v.tick(740 * MS);
        assert_eq!(last(&v), (0.0, 0.0));
        let count = v.port.published.len();
        v.stop(800 * MS);
        assert_eq!(v.port.published.len(), count + LAST_ZEROS);
        assert_eq!(last(&v), (0.0, 0.0));
    }

    #[test]
    fn silent_or_refused_odometry_and_another_writer_hold_at_zero() {
        let mut v = vehicle();
        routed(&mut v, Duration::ZERO);
        v.port.heard.push_back(odometry(0.0, 0.0));
        drive(&mut v, 10 * MS);
        v.tick(20 * MS);
        assert_eq!(last(&v), (0.2, 0.0));
        // NaN odometry: refused, said, held.
        v.port.heard.push_back(odometry(f64::NAN, 0.0));
        drive(&mut v, 30 * MS);
        let out = v.tick(40 * MS);
        assert_eq!(last(&v), (0.0, 0.0));
        assert!(
            notices(&out)
                .iter()
                .any(|n| n.contains("odometry on /tb3_1/odom refused")),
            "{:?}",
            notices(&out)
        );
        assert_eq!(v.agent.estimate().unwrap().pose.x, 0.0, "never the pose");
        // Another writer on cmd_vel: said once, held while heard.
        let mut v = vehicle();
        routed(&mut v, Duration::ZERO);
        v.port.heard.push_back(odometry(0.0, 0.0));
        v.port
            .heard
            .push_back(FromBase::ForeignCmdVel { writer: "w".into() });
        drive(&mut v, 10 * MS);
        let out = v.tick(20 * MS);
        assert_eq!(last(&v), (0.0, 0.0));
        assert!(
            notices(&out)
                .iter()
                .any(|n| n.contains("another node publishes on /tb3_1/cmd_vel")),
            "{:?}",
            notices(&out)
        );
        // Silence: said once, held.
        let mut out = Vec::new();
        for t in (100..=2400u32).step_by(100) {
            drive(&mut v, t * MS);
            out.extend(v.tick(t * MS));
        }
        assert_eq!(last(&v), (0.0, 0.0));
        let said: Vec<String> = notices(&out)
            .into_iter()
            .filter(|n| n.starts_with("no odometry on /tb3_1/odom for 2 s"))
            .collect();
        assert_eq!(said.len(), 1, "{:?}", notices(&out));
    }

    #[test]
    fn the_battery_goes_into_the_telemetry() {
        let mut v = vehicle();
        routed(&mut v, Duration::ZERO);
        v.port.heard.push_back(odometry(0.0, 0.0));
        v.port.heard.push_back(FromBase::Battery(BatteryState {
            percentage: 0.75,
            ..BatteryState::default()
        }));
        let out = v.tick(10 * MS);
        let t = out
            .iter()
            .find_map(|e| match &e.body {
                Body::Telemetry(t) => Some(t.clone()),
                _ => None,
            })
            .expect("telemetry");
        assert_eq!(t.battery, Some(0.75));
    }
}

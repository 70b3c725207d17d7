//! [`AutopilotVehicle`]: the agent core flying a vehicle through its
//! autopilot. Each control period it takes in what the autopilot said
//! (position into the estimate, reports as notices), carries out operators'
//! requests, runs the core, turns the core's outputs into the body twist
//! they mean (the platform's forward kinematics) and sends that as a
//! velocity setpoint, and puts the autopilot's velocity and battery into
//! the telemetry.
//!
//! Safety: whenever the core holds its outputs at zero (channel silent,
//! router lost, e-stop, driver fault, routed to none) the setpoint is zero
//! velocity: the vehicle holds where it is, in the air if flying. The agent
//! keeps streaming setpoints so the autopilot stays in offboard/guided;
//! when the agent itself dies the stream stops and the autopilot's own
//! offboard-loss failsafe (PX4 `COM_OBL_RC_ACT`, ArduPilot's guided
//! timeout) takes over. While the autopilot is silent the outputs are held
//! at zero too (state fault). It never arms, disarms or switches modes
//! except on an operator's request.

use std::time::Duration;

use mavlink::MavHeader;
use mavlink::dialects::common::MavMessage;
use mech_proto::{Envelope, Level};

use super::link::MavlinkPort;
use super::session::{Report, Session};
use crate::hal::PositionSample;
use crate::machine::Agent;
use crate::runtime::Vehicle;

/// How often the agent's own HEARTBEAT goes to the autopilot.
const HEARTBEAT_PERIOD: Duration = Duration::from_secs(1);

/// The agent core, the MAVLink session and the link; see the module docs.
#[derive(Debug)]
pub struct AutopilotVehicle<L> {
    pub agent: Agent,
    pub session: Session,
    pub link: L,
    next_heartbeat: Duration,
    /// Whether the agent was registered at the last period: on each
    /// registration the station is told again whether the vehicle is armed
    /// and its mode (it may have started after they changed, or missed
    /// those notices).
    registered: bool,
}

impl<L: MavlinkPort> AutopilotVehicle<L> {
    pub fn new(agent: Agent, session: Session, link: L) -> AutopilotVehicle<L> {
        AutopilotVehicle {
            agent,
            session,
            link,
            next_heartbeat: Duration::ZERO,
            registered: false,
        }
    }

    fn send(
        &mut self,
        header: &MavHeader,
        msg: &MavMessage,
        now: Duration,
        out: &mut Vec<Envelope>,
    ) {
        if let Err(e) = self.link.send(header, msg) {
            tracing::warn!(error = %e, "autopilot link");
            out.extend(
                self.agent
                    .actuator_fault(&format!("autopilot link: {e}"), now),
            );
        }
    }

    fn report(&mut self, r: Report, now: Duration, out: &mut Vec<Envelope>) {
        out.push(r.notice(&mut self.agent, now));
    }

    /// Everything the autopilot sent since the last period.
    fn take_in(&mut self, now: Duration, out: &mut Vec<Envelope>) {
        let mut reports = Vec::new();
        while let Some(item) = self.link.try_recv() {
            match item {
                Ok((header, msg)) => reports.extend(self.session.receive(&header, &msg, now)),
                Err(e) => {
                    out.extend(
                        self.agent
                            .driver_fault(&format!("autopilot link: {e}"), now),
                    );
                    break;
                }
            }
        }
        reports.extend(self.session.check_link(now));
        if self.session.target().is_some() && !self.session.connected(now) {
            // Outputs held at zero (state fault) while the autopilot is silent.
            out.extend(self.agent.actuator_fault("autopilot heartbeat lost", now));
        }
        for r in reports {
            self.report(r, now, out);
        }
        if let Some(pose) = self.session.take_pose() {
            self.agent.observe_position(PositionSample {
                pose,
                stamp: now,
                quality: 1.0,
                has_heading: true,
            });
            // The velocity the autopilot measures, not the one commanded,
            // is what the safety layer judges.
            if let Some(twist) = self.session.body_twist() {
                self.agent.observe_velocity(twist, now);
            }
        }
    }

    /// Operators' requests: one COMMAND_LONG each, or a notice saying why not.
    fn carry_out_requests(&mut self, now: Duration, out: &mut Vec<Envelope>) {
        let header = self.session.header();
        for r in self.agent.take_autopilot_requests() {
            match self.session.request(r.action, r.altitude) {
                Ok(msg) => {
                    self.send(&header, &msg, now, out);
                    let text = format!("{} sent to the autopilot", r.action.as_str());
                    self.report(
                        Report {
                            level: Level::Info,
                            text,
                        },
                        now,
                        out,
                    );
                }
                Err(why) => {
                    let text = format!("{} not sent: {why}", r.action.as_str());
                    self.report(
                        Report {
                            level: Level::Warn,
                            text,
                        },
                        now,
                        out,
                    );
                }
            }
        }
    }
}

impl<L: MavlinkPort> Vehicle for AutopilotVehicle<L> {
    fn agent(&self) -> &crate::machine::Agent {
        &self.agent
    }

    fn agent_mut(&mut self) -> &mut crate::machine::Agent {
        &mut self.agent
    }

    fn tick(&mut self, now: Duration) -> Vec<Envelope> {
        let mut out = Vec::new();
        self.take_in(now, &mut out);
        self.carry_out_requests(now, &mut out);
        let tick = self.agent.tick(now);
        let registered = self.agent.registered();
        if registered && !std::mem::replace(&mut self.registered, registered) {
            for r in self.session.state_reports() {
                self.report(r, now, &mut out);
            }
        }
        self.registered = registered;
        let twist = self.agent.platform().motion(&tick.outputs);
        let header = self.session.header();
        if let Some(setpoint) = self.session.setpoint(&twist, now) {
            self.send(&header, &setpoint, now, &mut out);
        }
        if now >= self.next_heartbeat {
            self.next_heartbeat = now + HEARTBEAT_PERIOD;
            let hb = self.session.heartbeat_message();
            self.send(&header, &hb, now, &mut out);
        }
        let mut outgoing = tick.outgoing;
        crate::runtime::patch_telemetry(&mut outgoing, |t| self.session.patch(t));
        outgoing.extend(out);
        outgoing
    }

    /// One last zero setpoint; then the stream stops and the autopilot's
    /// offboard-loss failsafe decides.
    fn stop(&mut self, now: Duration) -> Envelope {
        let header = self.session.header();
        if let Some(hold) = self.session.setpoint(&mech_proto::Twist::default(), now)
            && let Err(e) = self.link.send(&header, &hold)
        {
            tracing::error!(error = %e, "could not send the last hold setpoint");
        }
        self.agent.bye("shutdown", now)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::autopilot::config::AutopilotConfig;
    use crate::hal::HalError;
    use crate::machine::AgentSettings;
    use crate::platform::PlatformSpec;
    use mavlink::dialects::common::{
        ATTITUDE_DATA, HEARTBEAT_DATA, LOCAL_POSITION_NED_DATA, MavAutopilot, MavCmd, MavModeFlag,
        MavState, MavType,
    };
    use mech_proto::{
        AutopilotAction, AutopilotRequest, Body, Command, EStop, FailsafeState, Header, Route,
        Twist, Welcome,
    };
    use std::collections::VecDeque;

    /// A link whose autopilot side the test plays.
    #[derive(Debug, Default)]
    struct Bench {
        to_autopilot: Vec<MavMessage>,
        from_autopilot: VecDeque<(MavHeader, MavMessage)>,
    }

    impl MavlinkPort for Bench {
        fn send(&mut self, _: &MavHeader, msg: &MavMessage) -> Result<(), HalError> {
            self.to_autopilot.push(msg.clone());
            Ok(())
        }
        fn try_recv(&mut self) -> Option<Result<(MavHeader, MavMessage), HalError>> {
            self.from_autopilot.pop_front().map(Ok)
        }
    }

    fn vehicle() -> AutopilotVehicle<Bench> {
        let mut settings = AgentSettings::new("drone");
        settings.autopilot = true;
        settings.filter_window = 1;
        let agent = Agent::new(settings, PlatformSpec::quadcopter().build(), 0);
        let config: AutopilotConfig = toml::from_str("link = \"udpin:127.0.0.1:0\"").unwrap();
        AutopilotVehicle::new(agent, Session::new(&config), Bench::default())
    }

    fn px4(v: &mut AutopilotVehicle<Bench>, armed: bool) {
        let ap = MavHeader {
            system_id: 1,
            component_id: 1,
            sequence: 0,
        };
        let mut base_mode = MavModeFlag::MAV_MODE_FLAG_CUSTOM_MODE_ENABLED;
        if armed {
            base_mode |= MavModeFlag::MAV_MODE_FLAG_SAFETY_ARMED;
        }
        let q = &mut v.link.from_autopilot;
        q.push_back((
            ap,
            MavMessage::HEARTBEAT(HEARTBEAT_DATA {
                custom_mode: 6 << 16,
                mavtype: MavType::MAV_TYPE_QUADROTOR,
                autopilot: MavAutopilot::MAV_AUTOPILOT_PX4,
                base_mode,
                system_status: MavState::MAV_STATE_ACTIVE,
                mavlink_version: 3,
            }),
        ));
        q.push_back((
            ap,
            MavMessage::ATTITUDE(ATTITUDE_DATA {
                time_boot_ms: 0,
                roll: 0.0,
                pitch: 0.0,
                yaw: std::f32::consts::FRAC_PI_2,
                rollspeed: 0.0,
                pitchspeed: 0.0,
                yawspeed: 0.0,
            }),
        ));
        q.push_back((
            ap,
            MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
                time_boot_ms: 0,
                x: 1.0,
                y: 2.0,
                z: -3.0,
                vx: 0.0,
                vy: 0.0,
                vz: 0.0,
            }),
        ));
    }

    fn msg(channel: &str, body: Body) -> Envelope {
        Envelope::new(
            Header {
                destination: "drone".into(),
                channel: channel.into(),
                ..Header::default()
            },
            body,
        )
    }

    fn setpoints(v: &AutopilotVehicle<Bench>) -> Vec<(f32, f32, f32, f32)> {
        v.link
            .to_autopilot
            .iter()
            .filter_map(|m| match m {
                MavMessage::SET_POSITION_TARGET_LOCAL_NED(s) => {
                    Some((s.vx, s.vy, s.vz, s.yaw_rate))
                }
                _ => None,
            })
            .collect()
    }

    fn commands(v: &AutopilotVehicle<Bench>) -> Vec<MavCmd> {
        v.link
            .to_autopilot
            .iter()
            .filter_map(|m| match m {
                MavMessage::COMMAND_LONG(c) => Some(c.command),
                _ => None,
            })
            .collect()
    }

    const MS: Duration = Duration::from_millis(1);

    #[test]
    fn each_registration_tells_the_station_whether_armed_and_the_mode() {
        let notices = |out: &[Envelope]| -> Vec<String> {
            out.iter()
                .filter_map(|e| match &e.body {
                    Body::Notice(n) => Some(n.text.clone()),
                    _ => None,
                })
                .collect()
        };
        let mut v = vehicle();
        px4(&mut v, true);
        // Heard before registering: said, but to a router that may not
        // know the robot yet.
        let before = notices(&v.tick(Duration::ZERO));
        assert!(
            before.contains(&"autopilot armed".to_string()),
            "{before:?}"
        );
        let welcome = || {
            let route = Route {
                robot: "drone".into(),
                channel: String::new(),
                epoch: 1,
            };
            Body::Welcome(Welcome {
                robot_id: 1,
                route,
                router_version: "t".into(),
            })
        };
        v.handle(msg("", welcome()), 10 * MS);
        let said = notices(&v.tick(20 * MS));
        assert_eq!(said, ["autopilot armed", "autopilot mode OFFBOARD"]);
        assert!(
            notices(&v.tick(40 * MS)).is_empty(),
            "once per registration"
        );
        // The router is lost and found again: said again.
        v.tick(3_000 * MS);
        assert!(!v.agent.registered());
        v.handle(msg("", welcome()), 3_010 * MS);
        let again = notices(&v.tick(3_020 * MS));
        assert!(
            again.contains(&"autopilot mode OFFBOARD".to_string()),
            "{again:?}"
        );
    }

    #[test]
    fn a_routed_twist_flies_and_every_failsafe_holds() {
        let mut v = vehicle();
        px4(&mut v, true);
        let out = v.tick(Duration::ZERO);
        assert!(
            out.iter()
                .any(|e| matches!(&e.body, Body::Notice(n) if n.text.contains("autopilot found"))),
            "{out:?}"
        );
        let route = Route {
            robot: "drone".into(),
            channel: "joy/0".into(),
            epoch: 1,
        };
        let welcome = Welcome {
            robot_id: 1,
            route,
            router_version: "t".into(),
        };
        v.handle(msg("", Body::Welcome(welcome)), 10 * MS);
        // The pose came from the autopilot, in ENU.
        let pose = v.agent.estimate().unwrap().pose;
        assert_eq!((pose.x, pose.y, pose.z), (2.0, 1.0, 3.0));
        let forward = Command::Twist(Twist {
            vx: 0.5,
            ..Twist::default()
        });
        v.handle(msg("joy/0", Body::Command(forward)), 20 * MS);
        v.tick(40 * MS);
        // Facing east: forward is +east (NED y).
        let (vn, ve, _, _) = *setpoints(&v).last().unwrap();
        assert!(
            vn.abs() < 1e-6 && (ve - 0.5).abs() < 1e-6,
            "{:?}",
            setpoints(&v)
        );
        // Channel silent: zero-velocity hold, streamed every period.
        for t in [600u32, 620, 640] {
            let hb = mech_proto::Heartbeat::new(u64::from(t));
            v.handle(msg("", Body::Heartbeat(hb)), t * MS);
            px4(&mut v, true);
            v.tick(t * MS);
        }
        assert_eq!(
            v.agent.failsafe_state(640 * MS),
            FailsafeState::ChannelSilent
        );
        assert_eq!(setpoints(&v).last(), Some(&(0.0, 0.0, 0.0, 0.0)));
        // Router lost: hold too.
        px4(&mut v, true);
        v.tick(3000 * MS);
        assert_eq!(v.agent.failsafe_state(3000 * MS), FailsafeState::RouterLost);
        assert_eq!(setpoints(&v).last(), Some(&(0.0, 0.0, 0.0, 0.0)));
        assert!(
            commands(&v).is_empty(),
            "no arming or mode change by itself"
        );
        // Shutting down sends one last hold.
        let count = setpoints(&v).len();
        v.stop(3100 * MS);
        assert_eq!(setpoints(&v).len(), count + 1);
    }

    #[test]
    fn only_an_operators_request_arms_and_not_while_estopped() {
        let mut v = vehicle();
        px4(&mut v, false);
        v.tick(Duration::ZERO);
        let request = |action| {
            msg(
                "",
                Body::Autopilot(AutopilotRequest {
                    robot: "drone".into(),
                    action,
                    altitude: 0.0,
                }),
            )
        };
        v.handle(
            msg(
                "",
                Body::EStop(EStop {
                    engage: true,
                    id: 1,
                }),
            ),
            MS,
        );
        let refused = v.handle(request(AutopilotAction::Arm), 2 * MS);
        assert!(
            matches!(&refused[0].body, Body::Notice(n) if n.text.contains("e-stopped")),
            "{refused:?}"
        );
        v.tick(20 * MS);
        assert!(commands(&v).is_empty());
        v.handle(
            msg(
                "",
                Body::EStop(EStop {
                    engage: false,
                    id: 2,
                }),
            ),
            30 * MS,
        );
        v.handle(request(AutopilotAction::Arm), 40 * MS);
        let out = v.tick(60 * MS);
        assert_eq!(commands(&v), [MavCmd::MAV_CMD_COMPONENT_ARM_DISARM]);
        assert!(
            out.iter().any(
                |e| matches!(&e.body, Body::Notice(n) if n.text == "arm sent to the autopilot")
            ),
            "{out:?}"
        );
    }

    #[test]
    fn a_silent_autopilot_is_a_fault_and_the_setpoints_hold() {
        let mut v = vehicle();
        px4(&mut v, true);
        let route = Route {
            robot: "drone".into(),
            channel: "joy/0".into(),
            epoch: 1,
        };
        let welcome = Welcome {
            robot_id: 1,
            route,
            router_version: "t".into(),
        };
        v.handle(msg("", Body::Welcome(welcome)), Duration::ZERO);
        v.tick(Duration::ZERO);
        let mut out = Vec::new();
        for t in (100..=2500u32).step_by(100) {
            let forward = Command::Twist(Twist {
                vx: 0.5,
                ..Twist::default()
            });
            v.handle(msg("joy/0", Body::Command(forward)), t * MS);
            out.extend(v.tick(t * MS));
        }
        assert_eq!(v.agent.failsafe_state(2500 * MS), FailsafeState::Fault);
        assert_eq!(setpoints(&v).last(), Some(&(0.0, 0.0, 0.0, 0.0)));
        let lost: Vec<&str> = out
            .iter()
            .filter_map(|e| match &e.body {
                Body::Notice(n) if n.text.contains("autopilot") => Some(n.text.as_str()),
                _ => None,
            })
            .collect();
        assert!(
            lost.iter().any(|t| t.starts_with("autopilot lost")),
            "{lost:?}"
        );
    }

    #[test]
    fn a_robot_without_an_autopilot_refuses_requests() {
        let mut agent = Agent::new(
            AgentSettings::new("rover"),
            PlatformSpec::diff_drive().build(),
            0,
        );
        let request = Body::Autopilot(AutopilotRequest {
            robot: "rover".into(),
            action: AutopilotAction::Disarm,
            altitude: 0.0,
        });
        let mut env = msg("", request);
        env.header.destination = "rover".into();
        let out = agent.handle(env, MS);
        assert!(
            matches!(&out[0].body, Body::Notice(n) if n.text.contains("has no autopilot")),
            "{out:?}"
        );
        assert!(agent.take_autopilot_requests().is_empty());
        assert_eq!(agent.counters().refused, 1);
    }

    #[test]
    fn telemetry_carries_the_autopilots_velocity_and_battery() {
        let mut v = vehicle();
        px4(&mut v, true);
        let ap = MavHeader {
            system_id: 1,
            component_id: 1,
            sequence: 0,
        };
        v.link.from_autopilot.push_back((
            ap,
            MavMessage::LOCAL_POSITION_NED(LOCAL_POSITION_NED_DATA {
                time_boot_ms: 0,
                x: 1.0,
                y: 2.0,
                z: -3.0,
                vx: 0.4,
                vy: 0.0,
                vz: 0.0,
            }),
        ));
        let welcome = Welcome {
            robot_id: 1,
            route: Route {
                robot: "drone".into(),
                channel: String::new(),
                epoch: 1,
            },
            router_version: "t".into(),
        };
        v.handle(msg("", Body::Welcome(welcome)), Duration::ZERO);
        let out = v.tick(MS);
        let t = out
            .iter()
            .find_map(|e| match &e.body {
                Body::Telemetry(t) => Some(t.clone()),
                _ => None,
            })
            .expect("telemetry");
        // 0.4 m/s north is vy = 0.4 in ENU.
        assert!((t.velocity.vy - 0.4).abs() < 1e-6 && t.velocity.vx.abs() < 1e-6);
        assert_eq!(t.velocity_source, mech_proto::VelocitySource::Measured);
        // The core itself knows it (the safety layer judges it), not only
        // the telemetry sent: facing east, 0.4 m/s north is to its left.
        let own = v.agent.telemetry(MS);
        assert_eq!(own.velocity_source, mech_proto::VelocitySource::Measured);
        assert!(
            (own.velocity.vy - 0.4).abs() < 1e-6 && own.velocity.vx.abs() < 1e-6,
            "{:?}",
            own.velocity
        );
        assert!((v.session.body_twist().unwrap().vy - 0.4).abs() < 1e-6);
    }
}

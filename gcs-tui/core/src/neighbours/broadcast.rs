//! The neighbour broadcaster: a task beside the router, not in its
//! forwarding path, that while the station has an arena sends each of its
//! robots the states of the robots near it, `rate_hz` times a second. Each
//! round it reads the fleet model under its lock (this station's robots,
//! and other stations' shown through a bridge), releases it, picks each
//! robot's neighbours ([`super::select`]) and hands each list to the router
//! ([`RouterHandle::send_neighbours`]), which signs it for its robot.
//!
//! A robot gets lists while it is registered here, reachable, has its
//! layer on and has sent telemetry (before that the station does not know
//! where it is, and the robot crawls, as without lists). Every robot with
//! a known position is someone's neighbour: a robot the station has lost
//! (silent, or gone) as standing where it was last seen, its disc grown by
//! the way it could have gone before its failsafe stopped it; another
//! station's robot as not cooperating (it may not know ours).

use std::sync::{Arc, Mutex};
use std::time::Duration;

use mech_proto::{Neighbours, Obstacle, SafetyState};
use tokio::task::JoinHandle;

use super::{NeighbourConfig, RobotState, select};
use crate::event::LinkState;
use crate::fleet::Fleet;
use crate::router::RouterHandle;
use crate::sync::lock;

/// How long a robot the station lost may have kept going before its
/// failsafe stopped it: the agent's router timeout (1 s by default).
pub const LOST_TRAVEL: Duration = Duration::from_secs(1);

/// One round's states, read from the fleet model.
#[derive(Debug, Clone, PartialEq)]
pub struct Gathered {
    /// Every robot with a known position.
    pub states: Vec<RobotState>,
    /// Whether `states[i]` is to be sent a list.
    pub recipients: Vec<bool>,
    pub obstacles: Vec<Obstacle>,
}

/// What the fleet model says this round, at router time `now`; `None`
/// while the station has no arena (nothing is sent).
pub fn gather(fleet: &Fleet, now: Duration, config: &NeighbourConfig) -> Option<Gathered> {
    let arena = fleet.arena.as_ref()?;
    let mut states = Vec::with_capacity(fleet.robots.len());
    let mut recipients = Vec::with_capacity(fleet.robots.len());
    for r in fleet.robots.values() {
        let Some(heard) = r.last_telemetry else {
            continue;
        };
        // Its disc grown by how far its position estimate may be off (a
        // bound that is not a number is no report).
        let radius = r
            .telemetry
            .safety
            .map(|s| s.radius + s.position_error)
            .filter(|v| *v > 0.0 && v.is_finite())
            .unwrap_or(config.default_radius);
        let t = &r.telemetry;
        let v = [t.velocity.vx, t.velocity.vy, t.velocity.vz];
        let mut state = RobotState {
            name: r.name.clone(),
            id: r.registration.id,
            position: [t.pose.x, t.pose.y, t.pose.z],
            velocity: v,
            radius,
            age: now.saturating_sub(heard),
            cooperative: r.is_local() && t.safety.is_some_and(|s| s.state == SafetyState::On),
        };
        if r.link == LinkState::Lost {
            // Stopped by its failsafe by now, somewhere along its way.
            let speed = v[0].hypot(v[1]);
            state.radius += speed * LOST_TRAVEL.as_secs_f64()
                + speed * speed / (2.0 * config.lost_deceleration);
            state.velocity = [0.0; 3];
            state.age = Duration::ZERO;
            state.cooperative = false;
        }
        recipients.push(r.is_local() && r.safety_enabled && r.link != LinkState::Lost);
        states.push(state);
    }
    Some(Gathered {
        states,
        recipients,
        obstacles: arena.obstacle_list(),
    })
}

/// The lists of one round (station time `stamp_us`), for the recipients
/// only.
pub fn lists(g: &Gathered, config: &NeighbourConfig, stamp_us: u64) -> Vec<Neighbours> {
    select(&g.states, &config.policy(), &g.obstacles, stamp_us)
        .into_iter()
        .zip(&g.recipients)
        .filter_map(|(n, to)| to.then_some(n))
        .collect()
}

/// The running broadcaster; stopped by [`Broadcaster::stop`] (or when the
/// runtime ends).
#[derive(Debug)]
pub struct Broadcaster {
    task: JoinHandle<()>,
}

impl Broadcaster {
    /// Starts broadcasting on the current tokio runtime: every
    /// `config.period()`, the fleet model `fleet` is read and each robot's
    /// list sent through `router`.
    pub fn start(
        router: RouterHandle,
        fleet: Arc<Mutex<Fleet>>,
        config: NeighbourConfig,
    ) -> Broadcaster {
        let task = tokio::spawn(async move {
            let mut tick = tokio::time::interval(config.period());
            tick.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
            loop {
                tick.tick().await;
                let now = router.elapsed();
                // The fleet lock is held for the copy only, not the choice.
                let Some(gathered) = gather(&lock(&fleet), now, &config) else {
                    continue;
                };
                for n in lists(&gathered, &config, mech_proto::unix_micros()) {
                    router.send_neighbours(n).await;
                }
            }
        });
        Broadcaster { task }
    }

    /// Stops sending.
    pub fn stop(&self) {
        self.task.abort();
    }
}

#[cfg(test)]
mod tests {
    use mech_proto::{Hello, InterventionCounts, Pose, SafetyReport, Telemetry, Velocity};

    use super::*;
    use crate::arena::ArenaConfig;
    use crate::event::{Event, LinkAddr, Stamped};
    use crate::fleet::FleetConfig;

    fn at(ms: u64, event: Event) -> Stamped {
        Stamped {
            at: Duration::from_millis(ms),
            event,
        }
    }

    fn registered(name: &str, id: u16) -> Event {
        Event::Registered {
            hello: Hello {
                name: name.into(),
                platform: "kiwi".into(),
                capabilities: vec![],
                motors: 3,
                max_speed: 1.0,
                max_yaw_rate: 2.0,
                agent_version: "t".into(),
            },
            id,
            addr: LinkAddr::Udp("127.0.0.1:9000".parse().unwrap()),
            known: false,
        }
    }

    fn telemetry(name: &str, x: f64, vx: f64, state: SafetyState) -> Event {
        Event::Telemetry {
            robot: name.into(),
            telemetry: Telemetry {
                pose: Pose {
                    x,
                    y: 1.0,
                    ..Pose::default()
                },
                velocity: Velocity {
                    vx,
                    ..Velocity::default()
                },
                mode: Default::default(),
                channel: String::new(),
                computation: Default::default(),
                failsafe: Default::default(),
                health: Default::default(),
                battery: None,
                position_quality: 1.0,
                actuators: vec![],
                mission: None,
                stale: 0,
                velocity_source: Default::default(),
                safety: Some(SafetyReport {
                    state,
                    arena: 1,
                    intervention: Default::default(),
                    counts: InterventionCounts::default(),
                    radius: 0.2,
                    position_error: 0.0,
                }),
            },
        }
    }

    #[test]
    fn a_robot_is_told_of_its_neighbours_disc_grown_by_their_position_error() {
        let config = NeighbourConfig::default();
        let mut fleet = Fleet::new(FleetConfig::default());
        fleet.apply(&at(
            0,
            Event::Arena {
                arena: Some(ArenaConfig::demo().shape()),
            },
        ));
        for (i, error) in [(1, 0.05), (2, f64::NAN)] {
            let name = format!("robot_{i}");
            fleet.apply(&at(0, registered(&name, i)));
            let mut t = telemetry(&name, f64::from(i), 0.0, SafetyState::On);
            if let Event::Telemetry { telemetry, .. } = &mut t {
                telemetry.safety.as_mut().unwrap().position_error = error;
            }
            fleet.apply(&at(10, t));
        }
        let g = gather(&fleet, Duration::from_millis(50), &config).unwrap();
        let sent = lists(&g, &config, 7);
        let (about_2, about_1) = (sent[0].robots[0], sent[1].robots[0]);
        assert!((about_1.radius - 0.25).abs() < 1e-12, "{about_1:?}");
        assert_eq!(
            about_2.radius, config.default_radius,
            "no number: no report"
        );
    }

    #[test]
    fn each_robot_gets_the_others_near_it_while_there_is_an_arena() {
        let config = NeighbourConfig::default();
        let mut fleet = Fleet::new(FleetConfig::default());
        fleet.apply(&at(0, registered("robot_1", 1)));
        fleet.apply(&at(0, registered("robot_2", 2)));
        fleet.apply(&at(0, registered("robot_3", 3)));
        fleet.apply(&at(10, telemetry("robot_1", 1.0, 0.5, SafetyState::On)));
        fleet.apply(&at(
            20,
            telemetry("robot_2", 2.0, 0.0, SafetyState::NoArena),
        ));
        let now = Duration::from_millis(100);
        assert_eq!(gather(&fleet, now, &config), None, "no arena: nothing sent");
        fleet.apply(&at(
            30,
            Event::Arena {
                arena: Some(ArenaConfig::demo().shape()),
            },
        ));
        let g = gather(&fleet, now, &config).unwrap();
        // robot_3 has sent no telemetry: not placed, not sent a list.
        assert_eq!(g.states.len(), 2);
        let sent = lists(&g, &config, 7);
        let to: Vec<&str> = sent.iter().map(|n| n.robot.as_str()).collect();
        assert_eq!(to, ["robot_1", "robot_2"]);
        let about_2 = sent[0].robots[0];
        assert_eq!((about_2.id, about_2.x, about_2.age_ms), (2, 2.0, 80));
        assert!(!about_2.cooperative, "robot_2 has no arena yet");
        assert_eq!(about_2.radius, 0.2, "the radius it reports");
        let about_1 = sent[1].robots[0];
        assert!(about_1.cooperative && about_1.vx == 0.5 && about_1.age_ms == 90);
        assert_eq!(sent[0].stamp_us, 7);
        // Switched off: no list for it, still someone's neighbour.
        fleet.apply(&at(
            40,
            Event::SafetySwitched {
                robot: "robot_2".into(),
                enabled: false,
                id: 5,
            },
        ));
        let g = gather(&fleet, now, &config).unwrap();
        let sent = lists(&g, &config, 8);
        assert_eq!(sent.len(), 1);
        assert_eq!(sent[0].robots[0].id, 2);
    }

    #[test]
    fn a_lost_robot_stands_where_it_was_its_disc_grown_by_its_way() {
        let config = NeighbourConfig::default();
        let mut fleet = Fleet::new(FleetConfig::default());
        fleet.arena = Some(ArenaConfig::demo().shape());
        fleet.apply(&at(0, registered("robot_1", 1)));
        fleet.apply(&at(0, registered("robot_2", 2)));
        fleet.apply(&at(10, telemetry("robot_1", 1.0, 0.0, SafetyState::On)));
        fleet.apply(&at(10, telemetry("robot_2", 2.0, 0.5, SafetyState::On)));
        fleet.apply(&at(
            1100,
            Event::Link {
                robot: "robot_2".into(),
                state: LinkState::Lost,
            },
        ));
        let g = gather(&fleet, Duration::from_millis(3000), &config).unwrap();
        let sent = lists(&g, &config, 1);
        assert_eq!(sent.len(), 1, "no list for a robot the station lost");
        let lost = sent[0].robots[0];
        assert_eq!((lost.vx, lost.age_ms, lost.cooperative), (0.0, 0, false));
        // 0.5 m/s for a second, then braking at 1 m/s²: 0.625 m.
        assert!(
            (lost.radius - (0.2 + 0.625)).abs() < 1e-9,
            "{}",
            lost.radius
        );
    }
}

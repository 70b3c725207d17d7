//! Fleet safety in the agent core: the robot's [`SafetyLayer`], fed with
//! what the station sends it (its [`Arena`], acknowledged; its
//! [`Neighbours`]; a new registration), applied in
//! `super::actuation::Actuation::obey` to whatever the robot is about to
//! obey, and reported: in telemetry (state, the intervention now, counts)
//! and in a notice when an intervention begins or the layer is switched
//! on or off (one per change, never one per control period).

use std::time::Duration;

use mech_proto::{
    Arena, Body, Intervention, Level, Neighbours, NoticeCode, Pose, SafetyReport, SafetyState,
};

use super::step::Step;
use crate::platform::Platform;
use crate::safety::{SafetyConfig, SafetyLayer, Vec2};

/// Shortest time between two notices of the same intervention: a robot
/// that is limited, freed and limited again every other control period
/// (a diff-drive creeping along a wall) tells the station once a second,
/// not fifty times.
const NOTICE_GAP: Duration = Duration::from_secs(1);

/// The safety layer and what the station was last told about it.
#[derive(Debug)]
pub(crate) struct Safety {
    layer: SafetyLayer,
    /// The intervention last noticed, and when.
    noticed: Option<(Intervention, Duration)>,
    /// The layer's state last noticed (starts with no arena: nothing to
    /// say until the station sends one).
    state: SafetyState,
}

impl Safety {
    pub(crate) fn new(config: SafetyConfig) -> Safety {
        Safety {
            layer: SafetyLayer::new(config),
            noticed: None,
            state: SafetyState::NoArena,
        }
    }

    /// An arena from the router: applied when it is for this robot and not
    /// older than the one in force, and acknowledged (a repeat too, so an
    /// acknowledgement lost on the way is made good).
    pub(crate) fn arena(&mut self, arena: &Arena, step: &mut Step) {
        if arena.robot != step.robot() {
            return;
        }
        if let Some(ack) = self.layer.apply_arena(arena) {
            step.send(mech_proto::ROUTER, Body::ArenaAck(ack));
        }
        self.state_noticed(step);
    }

    /// The states of the robots near this one, received at `now`.
    pub(crate) fn neighbours(&mut self, n: &Neighbours, robot: &str, now: Duration) {
        if n.robot == robot {
            self.layer.apply_neighbours(n, now);
        }
    }

    /// The robot registered (again): a restarted station's next arena
    /// applies whatever its id.
    pub(crate) fn registered(&mut self, id: u16) {
        self.layer.registered(id);
    }

    /// The outputs to write instead of `outputs` (the controller's) for a
    /// robot of `platform` at `pose`, within its error bound (m; `None`:
    /// no estimate), moving at `velocity` (map frame); an intervention
    /// that begins is noticed.
    pub(crate) fn filter(
        &mut self,
        platform: &dyn Platform,
        pose: Option<(&Pose, f64)>,
        velocity: Vec2,
        outputs: Vec<f64>,
        step: &mut Step,
    ) -> Vec<f64> {
        let before = self.layer.report().intervention;
        let filtered = match pose {
            Some((pose, error)) => {
                self.layer.set_position_error(error);
                self.layer
                    .filter(platform, pose, velocity, &outputs, step.now)
            }
            None if self.layer.enforcing() => self.layer.hold(outputs.len()),
            None => return outputs,
        };
        self.intervention_noticed(before, filtered.intervention, step);
        filtered.outputs
    }

    /// How the command about to be filtered turns the robot
    /// ([`SafetyLayer::steered_by`]).
    pub(crate) fn steered_by(&mut self, gain: Option<f64>) {
        self.layer.steered_by(gain);
    }

    /// The outputs are held at zero this period for another reason
    /// (failsafe, e-stop, no position for the mode): the layer limits
    /// nothing.
    pub(crate) fn idle(&mut self) {
        self.layer.idle();
    }

    /// What telemetry reports.
    pub(crate) fn report(&self) -> SafetyReport {
        self.layer.report()
    }

    /// A notice when `now` begins an intervention (the period before had
    /// another, `before`), unless the same one was noticed less than
    /// [`NOTICE_GAP`] ago.
    fn intervention_noticed(&mut self, before: Intervention, now: Intervention, step: &mut Step) {
        if now == Intervention::None || now == before {
            return;
        }
        let recent = self
            .noticed
            .is_some_and(|(i, at)| i == now && step.now.saturating_sub(at) < NOTICE_GAP);
        if recent {
            return;
        }
        self.noticed = Some((now, step.now));
        let text = format!("safety: {} ({})", describe(now), now.as_str());
        step.notice(mech_proto::ROUTER, Level::Warn, NoticeCode::Safety, &text);
    }

    /// A notice when the layer's state changed (an arena came, was
    /// cleared, or the layer was switched on or off).
    fn state_noticed(&mut self, step: &mut Step) {
        let state = self.layer.state();
        if state == self.state {
            return;
        }
        self.state = state;
        let report = self.layer.report();
        let (level, text) = match state {
            SafetyState::On => (
                Level::Info,
                format!("safety on: arena {} enforced", report.arena),
            ),
            SafetyState::Off => (
                Level::Warn,
                format!(
                    "safety OFF: arena {} is not enforced, neighbours not kept apart from",
                    report.arena
                ),
            ),
            SafetyState::NoArena => (
                Level::Info,
                "safety: no arena (neighbours kept apart from if the station sends them)".into(),
            ),
        };
        step.notice(mech_proto::ROUTER, level, NoticeCode::Safety, &text);
    }
}

/// What an intervention does, as a notice says it.
fn describe(i: Intervention) -> &'static str {
    match i {
        Intervention::None => "commands obeyed as they are",
        Intervention::Fence => "limited so its stopping point stays inside the arena",
        Intervention::KeepOut => "limited so its stopping point stays out of a keep-out",
        Intervention::Separation => "limited to keep apart from a neighbour",
        Intervention::StaleNeighbours => "neighbour information is stale: crawling",
        Intervention::SlowZone => "speed capped by a slow zone",
        Intervention::Returning => "outside the free space: only moving back is allowed",
    }
}

#[cfg(test)]
mod tests {
    use super::super::testing::*;
    use mech_proto::{Arena, Intervention, Neighbour, Neighbours, Point, SafetyState};

    /// A 4 m x 3 m arena for `r1` (`enabled`: its layer on).
    fn arena(id: u32, enabled: bool) -> Body {
        let p = |x, y| Point { x, y };
        Body::Arena(Arena {
            robot: "r1".into(),
            id,
            enabled,
            boundary: vec![p(0.0, 0.0), p(4.0, 0.0), p(4.0, 3.0), p(0.0, 3.0)],
            keep_out: vec![],
            slow_zones: vec![],
            margin: 0.1,
        })
    }

    /// `r1` on a kiwi at (`x`, 1.5) facing +x, routed to `joy/0`.
    fn kiwi_at(x: f64) -> Agent {
        kiwi_with(AgentSettings::new("r1"), x)
    }

    /// `kiwi_at` with exact positions (no median window, no error), to be
    /// given a fix every period ([`fix`]).
    fn exact_kiwi_at(x: f64) -> Agent {
        let mut s = AgentSettings::new("r1");
        s.filter_window = 1;
        s.safety.position_error = 0.0;
        kiwi_with(s, x)
    }

    fn fix(a: &mut Agent, x: f64, now: Duration) {
        a.observe_position(PositionSample {
            pose: Pose {
                x,
                y: 1.5,
                ..Pose::default()
            },
            stamp: now,
            quality: 1.0,
            has_heading: true,
        });
    }

    fn kiwi_with(settings: AgentSettings, x: f64) -> Agent {
        let mut a = Agent::new(settings, PlatformSpec::kiwi().build(), 0);
        fix(&mut a, x, ms(0));
        let w = Body::Welcome(Welcome {
            robot_id: 1,
            route: Route {
                robot: "r1".into(),
                channel: "joy/0".into(),
                epoch: 1,
            },
            router_version: "t".into(),
        });
        a.handle(msg("", w), ms(0));
        a
    }

    fn safety_notices(out: &[Envelope]) -> Vec<String> {
        out.iter()
            .filter_map(|e| match &e.body {
                Body::Notice(n) if n.code == NoticeCode::Safety => Some(n.text.clone()),
                _ => None,
            })
            .collect()
    }

    fn neighbours(stamp_us: u64, robots: Vec<Neighbour>) -> Body {
        Body::Neighbours(Neighbours {
            robot: "r1".into(),
            stamp_us,
            robots,
            obstacles: vec![],
        })
    }

    #[test]
    fn an_arena_for_this_robot_is_applied_acknowledged_and_reported() {
        let mut a = kiwi_at(2.0);
        assert_eq!(a.telemetry(ms(0)).safety, Some(a.safety()));
        assert_eq!(a.safety().state, SafetyState::NoArena);
        let mut other = match arena(9, true) {
            Body::Arena(x) => x,
            _ => unreachable!(),
        };
        other.robot = "r2".into();
        assert!(a.handle(msg("", Body::Arena(other)), ms(5)).is_empty());
        let out = a.handle(msg("", arena(3, true)), ms(10));
        assert!(
            out.iter()
                .any(|e| matches!(&e.body, Body::ArenaAck(k) if k.id == 3 && k.robot == "r1"))
        );
        assert_eq!(safety_notices(&out), ["safety on: arena 3 enforced"]);
        let report = a.telemetry(ms(10)).safety.unwrap();
        assert_eq!((report.state, report.arena), (SafetyState::On, 3));
        // A repeat (the ack was lost) is acknowledged again, not noticed.
        let out = a.handle(msg("", arena(3, true)), ms(20));
        assert!(out.iter().any(|e| matches!(e.body, Body::ArenaAck(_))));
        assert!(safety_notices(&out).is_empty());
        // Switched off: an alarm, and commands pass untouched.
        let out = a.handle(msg("", arena(4, false)), ms(30));
        assert_eq!(a.safety().state, SafetyState::Off);
        assert!(safety_notices(&out)[0].starts_with("safety OFF"));
    }

    #[test]
    fn a_twist_at_the_wall_is_limited_counted_and_noticed_once() {
        // 0.4 m from the wall, the free space ends 0.15 m on: at 0.5 m/s
        // the stopping point (0.175 m on) would be beyond it.
        let mut a = exact_kiwi_at(3.6);
        a.handle(msg("", arena(1, true)), ms(0));
        a.handle(msg("", neighbours(1, vec![])), ms(0));
        let mut notices = Vec::new();
        let mut speeds = Vec::new();
        for k in 1..=20u32 {
            let now = ms(u64::from(k) * 20);
            let mut cmd = msg("joy/0", twist(0.5));
            cmd.header.seq = k;
            a.handle(cmd, now);
            a.handle(msg("", neighbours(u64::from(k) + 1, vec![])), now);
            fix(&mut a, 3.6, now);
            let t = a.tick(now);
            notices.extend(safety_notices(&t.outgoing));
            let kiwi = PlatformSpec::kiwi().build();
            speeds.push(kiwi.motion(&t.outputs).vx);
        }
        assert!(speeds.iter().all(|v| *v < 0.5 - 1e-6), "{speeds:?}");
        let report = a.safety();
        assert_eq!(report.intervention, Intervention::Fence);
        assert_eq!(report.counts.fence, 1, "one run of limited periods");
        assert_eq!(notices.len(), 1, "one notice per change: {notices:?}");
        assert!(notices[0].contains("(fence)"), "{notices:?}");
        // Held by the failsafe: the layer limits nothing.
        a.handle(msg("", estop(true, 1)), ms(500));
        a.tick(ms(520));
        assert_eq!(a.safety().intervention, Intervention::None);
        // Without the layer (no arena), the same command is obeyed as is.
        let mut b = kiwi_at(3.6);
        b.handle(msg("joy/0", twist(0.5)), ms(20));
        let out = b.tick(ms(40)).outputs;
        let v = PlatformSpec::kiwi().build().motion(&out).vx;
        assert!((v - 0.5).abs() < 1e-9, "{v}");
    }

    #[test]
    fn a_robot_unsure_where_it_is_keeps_its_distances_from_a_grown_disc() {
        // 0.4 m from the wall at 0.3 m/s: the stopping point (0.075 m on)
        // is inside the free space (0.15 m on) of an exact position, and
        // outside it (0.05 m on) when the position may be 0.1 m off.
        let kiwi = PlatformSpec::kiwi().build();
        let mut speeds = Vec::new();
        for error in [0.0, 0.1] {
            let mut s = AgentSettings::new("r1");
            s.filter_window = 1;
            s.safety.position_error = error;
            let mut a = kiwi_with(s, 3.6);
            a.handle(msg("", arena(1, true)), ms(0));
            a.handle(msg("", neighbours(1, vec![])), ms(0));
            a.handle(msg("joy/0", twist(0.3)), ms(20));
            fix(&mut a, 3.6, ms(20));
            speeds.push(kiwi.motion(&a.tick(ms(20)).outputs).vx);
            let report = a.telemetry(ms(20)).safety.unwrap();
            assert_eq!(report.position_error, error, "reported");
            assert_eq!(report.radius, 0.15, "the robot's own radius");
        }
        assert!((speeds[0] - 0.3).abs() < 1e-9, "{speeds:?}");
        assert!(speeds[1] < 0.3 - 0.05, "{speeds:?}");
    }

    #[test]
    fn a_moving_robots_median_of_fixes_is_moved_on_to_now() {
        // Nine fixes at 50 Hz: their median is where the robot was 80 ms
        // ago, 4 cm behind at 0.5 m/s.
        let mut a = kiwi_at(1.0);
        let mut now = ms(0);
        for k in 1..=50u32 {
            now = ms(u64::from(k) * 20);
            let mut cmd = msg("joy/0", twist(0.5));
            cmd.header.seq = k;
            a.handle(cmd, now);
            let truth = 1.0 + 0.5 * (now.as_secs_f64() - 0.02).max(0.0);
            fix(&mut a, truth, now);
            a.tick(now);
        }
        let truth = 1.0 + 0.5 * (now.as_secs_f64() - 0.02);
        let lagging = a.estimate().unwrap().pose.x;
        assert!((truth - lagging - 0.04).abs() < 1e-9, "{truth} {lagging}");
        let t = a.telemetry(now);
        assert!((t.pose.x - truth).abs() < 1e-9, "{} {truth}", t.pose.x);
        // The source's 0.05 m and a·t²/2 over the 80 ms moved on.
        let error = t.safety.unwrap().position_error;
        assert!((error - (0.05 + 0.0032)).abs() < 1e-9, "{error}");
    }

    #[test]
    fn stale_neighbours_slow_the_robot_to_a_crawl() {
        let mut a = exact_kiwi_at(2.0);
        a.handle(msg("", arena(1, true)), ms(0));
        let far = Neighbour {
            id: 2,
            x: 0.5,
            y: 0.5,
            z: 0.0,
            vx: 0.0,
            vy: 0.0,
            vz: 0.0,
            radius: 0.15,
            age_ms: 0,
            cooperative: true,
        };
        a.handle(msg("", neighbours(1, vec![far])), ms(0));
        a.handle(msg("joy/0", twist(0.3)), ms(20));
        let kiwi = PlatformSpec::kiwi().build();
        fix(&mut a, 2.0, ms(40));
        let fresh = kiwi.motion(&a.tick(ms(40)).outputs).vx;
        assert!((fresh - 0.3).abs() < 1e-9, "{fresh}");
        // No neighbour list since 0 ms: stale after 300 ms. Moving faster
        // than the crawl, the robot is first stopped, then crawls.
        let mut speeds = Vec::new();
        for k in 2..=10u32 {
            let now = ms(300 + u64::from(k) * 20);
            router_heartbeat(&mut a, now);
            let mut cmd = msg("joy/0", twist(0.3));
            cmd.header.seq = k;
            a.handle(cmd, now);
            fix(&mut a, 2.0, now);
            speeds.push(kiwi.motion(&a.tick(now).outputs).vx);
            assert_eq!(a.safety().intervention, Intervention::StaleNeighbours);
        }
        assert!(speeds.iter().all(|v| *v <= 0.05 + 1e-9), "{speeds:?}");
        assert!((speeds[speeds.len() - 1] - 0.05).abs() < 1e-9, "{speeds:?}");
    }

    #[test]
    fn after_registering_again_a_restarted_stations_arena_applies() {
        let mut a = kiwi_at(2.0);
        a.handle(msg("", arena(50, true)), ms(0));
        let out = a.handle(msg("", arena(2, false)), ms(10));
        assert!(out.is_empty(), "older, same station: ignored");
        // The router lost the robot and it registered again.
        a.handle(
            msg(
                "",
                Body::Notice(Notice {
                    level: Level::Warn,
                    code: NoticeCode::UnknownRobot,
                    text: String::new(),
                }),
            ),
            ms(20),
        );
        let w = Body::Welcome(Welcome {
            robot_id: 1,
            route: Route {
                robot: "r1".into(),
                channel: "joy/0".into(),
                epoch: 1,
            },
            router_version: "t".into(),
        });
        a.handle(msg("", w), ms(30));
        let out = a.handle(msg("", arena(2, false)), ms(40));
        assert!(
            out.iter()
                .any(|e| matches!(&e.body, Body::ArenaAck(k) if k.id == 2))
        );
        assert_eq!(a.safety().state, SafetyState::Off);
    }
}

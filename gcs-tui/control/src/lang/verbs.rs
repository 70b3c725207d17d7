//! Every verb of the language, one file each: the verb's parsed form, its
//! `parse` (from the argument cursor) and its `apply` (against the
//! executor's context). This file holds what they share: the verb table
//! [`VERBS`] that the parser and `help` read, the [`Command`] enum with its
//! dispatch, and the poll loop of the waiting verbs.

pub mod arena;
pub mod autopilot;
pub mod channels;
pub mod cluster;
pub mod cluster_expect;
pub mod cluster_hold;
pub mod cluster_move;
pub mod cluster_status;
pub mod cluster_wait;
pub mod cluster_waypoint;
pub mod drive;
pub mod estop;
pub mod expect;
pub mod follow;
pub mod formation;
pub mod help;
pub mod log;
pub mod mission;
pub mod mode;
pub mod nav;
pub mod nav_wait;
pub mod record;
pub mod route;
pub mod safety;
pub mod send;
pub mod sleep;
pub mod spawn;
pub mod status;
pub mod stop;
pub mod wait;
pub mod waypoint;

use std::time::Duration;

use tokio::time::Instant;

use super::args::{Args, Target};
use super::context::Context;
use super::{LangError, Outcome, Span};
use crate::hub::{ClusterView, ControlError};

/// Default timeout of `wait` when none is written: registrations, routes and
/// e-stop acknowledgements come within seconds.
pub const WAIT_TIMEOUT: Duration = Duration::from_secs(10);

/// Default timeout of `cluster-wait` and `nav-wait` when none is written: a
/// cluster's or a robot's waypoints take a minute to drive.
pub const CONTROL_WAIT_TIMEOUT: Duration = Duration::from_secs(60);

/// How often the waiting verbs re-check their condition.
const POLL: Duration = Duration::from_millis(10);

/// One verb of the language: its name, usage line and help text (shown by
/// `help` and in `docs/commands.md`), and its parser.
#[derive(Debug)]
pub struct Verb {
    pub name: &'static str,
    pub usage: &'static str,
    pub help: &'static str,
    pub(super) parse: fn(&mut Args<'_>) -> Result<Command, LangError>,
}

/// Every verb, in the order `help` lists them.
pub static VERBS: &[Verb] = &[
    Verb {
        name: "route",
        usage: "route TARGET CHANNEL|none",
        help: "route robots to a channel (takes effect for the next message)",
        parse: |a| route::Route::parse(a).map(Command::Route),
    },
    Verb {
        name: "mode",
        usage: "mode TARGET MODE",
        help: "control mode `drive` uses: actuators, steering-throttle, velocity-heading, twist, stop",
        parse: |a| mode::Mode::parse(a).map(Command::Mode),
    },
    Verb {
        name: "drive",
        usage: "drive TARGET NUMBER...",
        help: "publish one command in the robots' mode on the GCS command channel",
        parse: |a| drive::Drive::parse(a).map(Command::Drive),
    },
    Verb {
        name: "waypoint",
        usage: "waypoint ROBOT X,Y[,Z][@T]... [loop] | waypoint ROBOT clear",
        help: "set a robot's waypoint list (T = arrival time, e.g. @15s)",
        parse: |a| waypoint::SetWaypoints::parse(a).map(Command::SetWaypoints),
    },
    Verb {
        name: "send",
        usage: "send TARGET [CHANNEL]",
        help: "send each robot's waypoint list as a mission (default channel wp/gcs)",
        parse: |a| send::SendWaypoints::parse(a).map(Command::SendWaypoints),
    },
    Verb {
        name: "mission",
        usage: "mission save|load TARGET FILE [origin LAT,LON[,ALT]|home]",
        help: "save a robot's (or a cluster's) waypoints, times and loop to FILE on the station, or load them (.toml: MECH's format; .waypoints, .txt: QGC WPL 110)",
        parse: |a| mission::MissionFile::parse(a).map(Command::MissionFile),
    },
    Verb {
        name: "cluster",
        usage: "cluster NAME ROBOT...",
        help: "define a named set of robots",
        parse: |a| cluster::Cluster::parse(a).map(Command::Cluster),
    },
    Verb {
        name: "stop",
        usage: "stop TARGET",
        help: "controlled stop on each robot's current channel (not latched)",
        parse: |a| stop::Stop::parse(a).map(Command::Stop),
    },
    Verb {
        name: "estop",
        usage: "estop",
        help: "emergency stop every robot (latched until release)",
        parse: |_| Ok(Command::EStop),
    },
    Verb {
        name: "release",
        usage: "release",
        help: "release the emergency stop",
        parse: |_| Ok(Command::Release),
    },
    Verb {
        name: "wait",
        usage: "wait connected|lost|arrived TARGET [TIMEOUT] | wait robots N [TIMEOUT] | wait route TARGET CHANNEL|none [TIMEOUT] | wait near TARGET X,Y TOLERANCE [TIMEOUT] | wait moved TARGET METRES [TIMEOUT] | wait estop [TIMEOUT] | wait safety TARGET on|off|no-arena [TIMEOUT]",
        help: "wait until a condition holds (default timeout 10s)",
        parse: |a| wait::Wait::parse(a).map(Command::Wait),
    },
    Verb {
        name: "expect",
        usage: "expect near TARGET X,Y TOLERANCE | expect route TARGET CHANNEL|none | expect link TARGET connected|stale|lost | expect failsafe TARGET ok|channel-silent|router-lost|estopped|fault | expect safety TARGET on|off|no-arena | expect dropped CHANNEL N",
        help: "check a condition now; a script fails if it does not hold",
        parse: |a| expect::Expectation::parse(a).map(Command::Expect),
    },
    Verb {
        name: "sleep",
        usage: "sleep DURATION",
        help: "pause the script",
        parse: |a| sleep::Sleep::parse(a).map(Command::Sleep),
    },
    Verb {
        name: "log",
        usage: "log TEXT...",
        help: "write a line to the event log and output",
        parse: |a| log::Log::parse(a).map(Command::Log),
    },
    Verb {
        name: "spawn",
        usage: "spawn N",
        help: "start N simulated agents",
        parse: |a| spawn::Spawn::parse(a).map(Command::Spawn),
    },
    Verb {
        name: "channels",
        usage: "channels",
        help: "list live channels, their publisher and rate",
        parse: |_| Ok(Command::Channels),
    },
    Verb {
        name: "status",
        usage: "status [TARGET]",
        help: "one line per robot",
        parse: |a| status::Status::parse(a).map(Command::Status),
    },
    Verb {
        name: "formation",
        usage: "formation CLUSTER line|column|wedge|circle [SPACING] | formation CLUSTER custom X,Y...",
        help: "set a cluster's formation (slots re-assigned to minimise travel)",
        parse: |a| formation::SetFormation::parse(a).map(Command::SetFormation),
    },
    Verb {
        name: "cluster-move",
        usage: "cluster-move CLUSTER VX VY WZ [SCALE_RATE]",
        help: "move a cluster at a cluster-frame velocity (route its members to fleet/CLUSTER)",
        parse: |a| cluster_move::ClusterMove::parse(a).map(Command::ClusterMove),
    },
    Verb {
        name: "cluster-hold",
        usage: "cluster-hold CLUSTER",
        help: "stop a cluster where it is",
        parse: |a| cluster_hold::ClusterHold::parse(a).map(Command::ClusterHold),
    },
    Verb {
        name: "cluster-status",
        usage: "cluster-status CLUSTER",
        help: "cluster pose (desired and measured), slot targets and tracking errors",
        parse: |a| cluster_status::ClusterStatus::parse(a).map(Command::ClusterStatus),
    },
    Verb {
        name: "cluster-waypoint",
        usage: "cluster-waypoint CLUSTER X,Y[,HEADING]... [loop]",
        help: "set a cluster's waypoints (heading in rad, or deg suffix); start with `send CLUSTER`",
        parse: |a| {
            cluster_waypoint::SetClusterWaypoints::parse(a).map(Command::SetClusterWaypoints)
        },
    },
    Verb {
        name: "cluster-wait",
        usage: "cluster-wait CLUSTER [TIMEOUT] | cluster-wait CLUSTER settled TOLERANCE [TIMEOUT]",
        help: "wait until a cluster has done its waypoints, or every member is routed to it, reporting, and within TOLERANCE m of its slot (default 60s)",
        parse: |a| cluster_wait::ClusterWait::parse(a).map(Command::ClusterWait),
    },
    Verb {
        name: "cluster-expect",
        usage: "cluster-expect CLUSTER max-error|rms-error METRES",
        help: "check a cluster's slot tracking error since its waypoints were sent",
        parse: |a| cluster_expect::ClusterExpect::parse(a).map(Command::ClusterExpect),
    },
    Verb {
        name: "follow",
        usage: "follow ROBOT LEADER DX,DY | follow ROBOT none",
        help: "keep an offset in the leader's frame (route ROBOT to follow/LEADER)",
        parse: |a| follow::Follow::parse(a).map(Command::Follow),
    },
    Verb {
        name: "nav",
        usage: "nav ROBOT offboard|onboard|toggle",
        help: "switch waypoint navigation between the GCS loop and the robot, keeping progress",
        parse: |a| nav::Nav::parse(a).map(Command::Nav),
    },
    Verb {
        name: "nav-wait",
        usage: "nav-wait ROBOT NEXT [TIMEOUT]",
        help: "wait until a robot's next waypoint index reaches NEXT (default 60s)",
        parse: |a| nav_wait::NavWait::parse(a).map(Command::NavWait),
    },
    Verb {
        name: "record",
        usage: "record start [FILE [overwrite]] | record stop | record toggle | record",
        help: "record everything the router sees to MCAP (no FILE: rotating files in the recording directory; a FILE that exists is refused unless `overwrite`); `record` says how it goes",
        parse: |a| record::Record::parse(a).map(Command::Record),
    },
    Verb {
        name: "autopilot",
        usage: "autopilot TARGET arm|disarm|offboard|hold|land | autopilot TARGET takeoff ALTITUDE",
        help: "ask robots' autopilots (PX4, ArduPilot) to arm, disarm, change mode, land or take off",
        parse: |a| autopilot::Autopilot::parse(a).map(Command::Autopilot),
    },
    Verb {
        name: "arena",
        usage: "arena | arena load FILE | arena demo | arena clear",
        help: "the arena robots are kept inside: show it, load a file (the [arena] keys), the simulator's, or none",
        parse: |a| arena::Arena::parse(a).map(Command::Arena),
    },
    Verb {
        name: "safety",
        usage: "safety on|off TARGET",
        help: "switch robots' fleet safety layer on or off (off shows as an alarm)",
        parse: |a| safety::Safety::parse(a).map(Command::Safety),
    },
    Verb {
        name: "help",
        usage: "help",
        help: "list commands",
        parse: |_| Ok(Command::Help),
    },
];

/// One command of the language, as parsed: one variant per verb. Verbs
/// without arguments are unit variants (the TUI matches `Command::EStop`
/// and `Command::Release` to act on them at once).
#[derive(Debug, Clone, PartialEq)]
pub enum Command {
    Route(route::Route),
    Mode(mode::Mode),
    Drive(drive::Drive),
    SetWaypoints(waypoint::SetWaypoints),
    SendWaypoints(send::SendWaypoints),
    MissionFile(mission::MissionFile),
    Cluster(cluster::Cluster),
    Stop(stop::Stop),
    EStop,
    Release,
    Wait(wait::Wait),
    Expect(expect::Expectation),
    Sleep(sleep::Sleep),
    Log(log::Log),
    Spawn(spawn::Spawn),
    Channels,
    Status(status::Status),
    Help,
    SetFormation(formation::SetFormation),
    ClusterMove(cluster_move::ClusterMove),
    ClusterHold(cluster_hold::ClusterHold),
    ClusterStatus(cluster_status::ClusterStatus),
    SetClusterWaypoints(cluster_waypoint::SetClusterWaypoints),
    ClusterWait(cluster_wait::ClusterWait),
    ClusterExpect(cluster_expect::ClusterExpect),
    Follow(follow::Follow),
    Nav(nav::Nav),
    NavWait(nav_wait::NavWait),
    Record(record::Record),
    Autopilot(autopilot::Autopilot),
    Arena(arena::Arena),
    Safety(safety::Safety),
}

impl Command {
    /// Runs the command; `at` is where it was written, for errors about the
    /// command as a whole (timeouts, failed expectations).
    pub(super) async fn apply(&self, ctx: &mut Context, at: Span) -> Result<Outcome, LangError> {
        match self {
            Command::Route(c) => c.apply(ctx, at).await,
            Command::Mode(c) => c.apply(ctx, at).await,
            Command::Drive(c) => c.apply(ctx, at).await,
            Command::SetWaypoints(c) => c.apply(ctx, at).await,
            Command::SendWaypoints(c) => c.apply(ctx, at).await,
            Command::MissionFile(c) => c.apply(ctx, at).await,
            Command::Cluster(c) => c.apply(ctx, at).await,
            Command::Stop(c) => c.apply(ctx, at).await,
            Command::EStop => estop::engage(ctx).await,
            Command::Release => estop::release(ctx).await,
            Command::Wait(c) => c.apply(ctx, at).await,
            Command::Expect(c) => c.apply(ctx, at).await,
            Command::Sleep(c) => c.apply(ctx, at).await,
            Command::Log(c) => c.apply(ctx, at).await,
            Command::Spawn(c) => c.apply(ctx, at).await,
            Command::Channels => channels::apply(ctx).await,
            Command::Status(c) => c.apply(ctx, at).await,
            Command::Help => help::apply(ctx).await,
            Command::SetFormation(c) => c.apply(ctx, at).await,
            Command::ClusterMove(c) => c.apply(ctx, at).await,
            Command::ClusterHold(c) => c.apply(ctx, at).await,
            Command::ClusterStatus(c) => c.apply(ctx, at).await,
            Command::SetClusterWaypoints(c) => c.apply(ctx, at).await,
            Command::ClusterWait(c) => c.apply(ctx, at).await,
            Command::ClusterExpect(c) => c.apply(ctx, at).await,
            Command::Follow(c) => c.apply(ctx, at).await,
            Command::Nav(c) => c.apply(ctx, at).await,
            Command::NavWait(c) => c.apply(ctx, at).await,
            Command::Record(c) => c.apply(ctx, at).await,
            Command::Autopilot(c) => c.apply(ctx, at).await,
            Command::Arena(c) => c.apply(ctx, at).await,
            Command::Safety(c) => c.apply(ctx, at).await,
        }
    }
}

/// The poll loop of every waiting verb: runs `check` at once and then every
/// [`POLL`] until it returns `Ok` (the condition holds; returned with the
/// time that took) or `timeout` has passed, which is an error at `at`:
/// `timed out after T s: ` and the last reason `check` gave.
async fn poll_until<T>(
    timeout: Duration,
    at: Span,
    mut check: impl FnMut() -> Result<T, String>,
) -> Result<(T, Duration), LangError> {
    let start = Instant::now();
    loop {
        match check() {
            Ok(done) => return Ok((done, start.elapsed())),
            Err(reason) if start.elapsed() >= timeout => {
                return Err(LangError::new(
                    at,
                    format!("timed out after {:.1} s: {reason}", timeout.as_secs_f64()),
                ));
            }
            Err(_) => tokio::time::sleep(POLL).await,
        }
    }
}

/// A channel as the language writes it: its name, or `none`.
fn channel_name(c: &Option<String>) -> &str {
    c.as_deref().unwrap_or("none")
}

/// A controller's refusal, as an error at the target it was about.
fn control_error(target: &Target, e: ControlError) -> LangError {
    LangError::new(target.span, e.to_string())
}

/// The cluster controller's view of `cluster`, or an error at it if there
/// is no such cluster.
fn cluster_view(ctx: &Context, cluster: &Target) -> Result<ClusterView, LangError> {
    ctx.control
        .cluster_view(&cluster.name)
        .ok_or_else(|| control_error(cluster, ControlError::UnknownCluster(cluster.name.clone())))
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use mech_proto::{ClusterVelocity, FormationKind, Offset};

    use super::cluster_expect::{ClusterExpect, ErrorMetric};
    use super::cluster_hold::ClusterHold;
    use super::cluster_move::ClusterMove;
    use super::cluster_status::ClusterStatus;
    use super::cluster_wait::{ClusterUntil, ClusterWait};
    use super::cluster_waypoint::SetClusterWaypoints;
    use super::follow::Follow;
    use super::formation::SetFormation;
    use super::nav::{Nav, NavSide};
    use super::nav_wait::NavWait;
    use super::*;
    use crate::lang::parse_line;

    fn control(line: &str) -> Command {
        parse_line(line).unwrap().unwrap().command
    }

    #[test]
    fn every_control_verb_parses() {
        let Command::SetFormation(SetFormation { formation, .. }) =
            control("formation c1 custom 0,0.5 0,-0.5 -0.7,0")
        else {
            panic!()
        };
        assert_eq!(formation.kind, FormationKind::Custom);
        assert_eq!(formation.offsets[2], Offset { x: -0.7, y: 0.0 });
        let Command::SetFormation(SetFormation { formation, .. }) =
            control("formation c1 wedge 0.8")
        else {
            panic!()
        };
        assert_eq!(
            (formation.kind, formation.spacing),
            (FormationKind::Wedge, 0.8)
        );
        assert_eq!(
            control("cluster-move c1 0.2 0 0.1"),
            Command::ClusterMove(ClusterMove {
                cluster: Target {
                    name: "c1".into(),
                    span: Span {
                        line: 1,
                        column: 14
                    }
                },
                velocity: ClusterVelocity {
                    vx: 0.2,
                    vy: 0.0,
                    wz: 0.1,
                    scale_rate: 0.0
                },
            })
        );
        let Command::SetClusterWaypoints(SetClusterWaypoints {
            waypoints, looped, ..
        }) = control("cluster-waypoint c1 2,1 2,2,90deg loop")
        else {
            panic!()
        };
        assert_eq!(waypoints.len(), 2);
        assert!(looped);
        assert!(matches!(
            control("cluster-wait c1 settled 0.05 10s"),
            Command::ClusterWait(ClusterWait { until: ClusterUntil::Settled(t), timeout, .. })
                if t == 0.05 && timeout == Duration::from_secs(10)
        ));
        assert!(matches!(
            control("cluster-wait c1"),
            Command::ClusterWait(ClusterWait {
                until: ClusterUntil::Arrived,
                ..
            })
        ));
        assert!(matches!(
            control("cluster-expect c1 rms-error 0.05"),
            Command::ClusterExpect(ClusterExpect {
                metric: ErrorMetric::Rms,
                ..
            })
        ));
        assert!(matches!(
            control("cluster-hold c1"),
            Command::ClusterHold(ClusterHold { .. })
        ));
        assert!(matches!(
            control("cluster-status c1"),
            Command::ClusterStatus(ClusterStatus { .. })
        ));
        assert!(matches!(
            control("follow robot_2 robot_1 -0.8,0.5"),
            Command::Follow(Follow { leader: Some(_), offset: Offset { x, y }, .. }) if x == -0.8 && y == 0.5
        ));
        assert!(matches!(
            control("follow robot_2 none"),
            Command::Follow(Follow { leader: None, .. })
        ));
        assert!(matches!(
            control("nav robot_1 offboard"),
            Command::Nav(Nav {
                side: NavSide::Offboard,
                ..
            })
        ));
        assert!(matches!(
            control("nav-wait robot_1 3 5s"),
            Command::NavWait(NavWait { next: 3, .. })
        ));
    }

    #[test]
    fn a_named_word_is_read_by_its_name_and_a_wrong_one_lists_the_names() {
        assert!(matches!(
            control("cluster-expect c1 max-error 0.2"),
            Command::ClusterExpect(ClusterExpect {
                metric: ErrorMetric::Max,
                ..
            })
        ));
        let e = parse_line("cluster-expect c1 mean-error 0.2").unwrap_err();
        assert_eq!(e.span.column, 19);
        assert_eq!(
            e.message,
            "unknown error metric \"mean-error\"; use max-error, rms-error"
        );
        let e = parse_line("expect failsafe robot_1 broken").unwrap_err();
        assert_eq!(e.span.column, 25);
        assert_eq!(
            e.message,
            "unknown failsafe state \"broken\"; use ok, channel-silent, router-lost, estopped, fault"
        );
        let e = parse_line("expect link robot_1 gone").unwrap_err();
        assert!(
            e.message.ends_with("use connected, stale, lost"),
            "{}",
            e.message
        );
    }

    #[test]
    fn bad_arguments_point_at_the_word() {
        let e = parse_line("formation c1 blob").unwrap_err();
        assert_eq!(e.span.column, 14);
        assert!(e.message.contains("unknown formation"));
        let e = parse_line("nav robot_1 sideways").unwrap_err();
        assert!(
            e.message
                .contains("unknown navigation side \"sideways\"; use onboard, offboard, toggle"),
            "{}",
            e.message
        );
        let e = parse_line("cluster-waypoint c1 1").unwrap_err();
        assert!(e.message.contains("cluster waypoint"));
        assert!(parse_line("cluster-move c1 0.1").is_err());
        assert!(parse_line("follow robot_2 robot_1").is_err());
    }
}

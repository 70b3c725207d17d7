//! The command-language verbs of fleet and offboard control, parsed from the
//! shared argument cursor and run against a [`ControlHub`]:
//!
//! ```text
//! formation c1 line|column|wedge|circle [SPACING]
//! formation c1 custom X,Y X,Y ...
//! cluster-move c1 VX VY WZ [SCALE_RATE]      # cluster frame, m/s rad/s 1/s
//! cluster-hold c1
//! cluster-waypoint c1 X,Y[,HEADING] ... [loop]   # then `send c1`
//! cluster-wait c1 [TIMEOUT]                  # until the waypoints are done
//! cluster-wait c1 settled TOLERANCE [TIMEOUT] # every member routed, reporting, within TOLERANCE of its slot
//! cluster-expect c1 max-error|rms-error METRES
//! cluster-status c1                          # pose, slots, tracking errors
//! follow robot_2 robot_1 DX,DY               # offset in robot_1's frame
//! follow robot_2 none
//! nav robot_1 offboard|onboard
//! nav-wait robot_1 NEXT [TIMEOUT]            # until the next waypoint >= NEXT
//! ```
//!
//! Routing is separate, as for every controller: `route c1 fleet/c1` puts a
//! cluster's members under the cluster controller, `route robot_2
//! follow/robot_1` a follower under follow-the-leader. `nav` routes by
//! itself, because the switch must keep the mission's progress.

use std::time::Duration;

use mech_proto::{ClusterVelocity, Formation, Offset};
use tokio::time::Instant;

use super::parse::Args;
use super::{Command, LangError, Outcome, Span, Target};
use crate::cluster::{ClusterMotion, ClusterWaypoint};
use crate::hub::{ClusterView, ControlError, ControlHub, cluster_channel, follow_channel};
use crate::spec::{formation_name, parse_cluster_waypoint, parse_formation, parse_offset};

/// How often the waiting verbs re-check.
const POLL: Duration = Duration::from_millis(10);

/// Default timeout of `cluster-wait` and `nav-wait`.
const DEFAULT_WAIT: Duration = Duration::from_secs(60);

/// Which tracking statistic `cluster-expect` checks.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ErrorMetric {
    Max,
    Rms,
}

/// What `cluster-wait` waits for.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum ClusterUntil {
    /// The waypoints sent last are done.
    Arrived,
    /// Every commanded member is within this distance (m) of its slot.
    Settled(f64),
}

/// Where navigation should run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum NavSide {
    Onboard,
    Offboard,
}

/// A fleet- or offboard-control command of the language.
#[derive(Debug, Clone, PartialEq)]
pub enum ControlCommand {
    Formation {
        cluster: Target,
        formation: Formation,
    },
    ClusterMove {
        cluster: Target,
        velocity: ClusterVelocity,
    },
    ClusterHold {
        cluster: Target,
    },
    ClusterStatus {
        cluster: Target,
    },
    ClusterWaypoints {
        cluster: Target,
        waypoints: Vec<ClusterWaypoint>,
        looped: bool,
    },
    ClusterWait {
        cluster: Target,
        until: ClusterUntil,
        timeout: Duration,
    },
    ClusterExpect {
        cluster: Target,
        metric: ErrorMetric,
        limit: f64,
    },
    Follow {
        follower: Target,
        leader: Option<Target>,
        offset: Offset,
    },
    Nav {
        robot: Target,
        side: NavSide,
    },
    NavWait {
        robot: Target,
        next: u32,
        timeout: Duration,
    },
}

fn keyword(a: &Args<'_>, word: &str) -> bool {
    a.peek().is_some_and(|w| w.text == word && !w.quoted)
}

fn spec_error(span: Span, e: impl std::fmt::Display) -> LangError {
    LangError::new(span, e.to_string())
}

/// `formation CLUSTER KIND [SPACING]` / `formation CLUSTER custom X,Y...`
pub fn parse_formation_verb(a: &mut Args<'_>) -> Result<Command, LangError> {
    let cluster = a.target()?;
    let first = a.next("formation (line, column, wedge, circle, custom)")?;
    let mut words = vec![first];
    while let Some(w) = a.peek() {
        words.push(w);
        a.next("formation argument")?;
    }
    let texts: Vec<&str> = words.iter().map(|w| w.text.as_str()).collect();
    let formation = parse_formation(&texts).map_err(|e| spec_error(first.span, e))?;
    Ok(Command::Control(ControlCommand::Formation {
        cluster,
        formation,
    }))
}

/// `cluster-move CLUSTER VX VY WZ [SCALE_RATE]`
pub fn parse_cluster_move(a: &mut Args<'_>) -> Result<Command, LangError> {
    let cluster = a.target()?;
    let vx = a.number("vx (m/s, cluster frame)")?;
    let vy = a.number("vy (m/s, cluster frame)")?;
    let wz = a.number("wz (rad/s)")?;
    let scale_rate = if a.is_empty() {
        0.0
    } else {
        a.number("scale rate (1/s)")?
    };
    Ok(Command::Control(ControlCommand::ClusterMove {
        cluster,
        velocity: ClusterVelocity {
            vx,
            vy,
            wz,
            scale_rate,
        },
    }))
}

/// `cluster-hold CLUSTER`
pub fn parse_cluster_hold(a: &mut Args<'_>) -> Result<Command, LangError> {
    Ok(Command::Control(ControlCommand::ClusterHold {
        cluster: a.target()?,
    }))
}

/// `cluster-status CLUSTER`
pub fn parse_cluster_status(a: &mut Args<'_>) -> Result<Command, LangError> {
    Ok(Command::Control(ControlCommand::ClusterStatus {
        cluster: a.target()?,
    }))
}

/// `cluster-waypoint CLUSTER X,Y[,HEADING]... [loop]`
pub fn parse_cluster_waypoint_verb(a: &mut Args<'_>) -> Result<Command, LangError> {
    let cluster = a.target()?;
    let mut waypoints = Vec::new();
    let mut looped = false;
    loop {
        if keyword(a, "loop") {
            a.next("loop")?;
            looped = true;
            break;
        }
        if a.is_empty() && !waypoints.is_empty() {
            break;
        }
        let w = a.next("cluster waypoint x,y[,heading]")?;
        waypoints.push(parse_cluster_waypoint(&w.text).map_err(|e| spec_error(w.span, e))?);
    }
    if waypoints.is_empty() {
        a.next("cluster waypoint x,y[,heading]")?;
    }
    Ok(Command::Control(ControlCommand::ClusterWaypoints {
        cluster,
        waypoints,
        looped,
    }))
}

/// `cluster-wait CLUSTER [TIMEOUT]` / `cluster-wait CLUSTER settled TOL [TIMEOUT]`
pub fn parse_cluster_wait(a: &mut Args<'_>) -> Result<Command, LangError> {
    let cluster = a.target()?;
    let until = if keyword(a, "settled") {
        a.next("settled")?;
        ClusterUntil::Settled(a.number("slot error tolerance (m)")?)
    } else {
        ClusterUntil::Arrived
    };
    let timeout = if a.is_empty() {
        DEFAULT_WAIT
    } else {
        a.duration()?
    };
    Ok(Command::Control(ControlCommand::ClusterWait {
        cluster,
        until,
        timeout,
    }))
}

/// `cluster-expect CLUSTER max-error|rms-error METRES`
pub fn parse_cluster_expect(a: &mut Args<'_>) -> Result<Command, LangError> {
    let cluster = a.target()?;
    let w = a.next("max-error or rms-error")?;
    let metric = match w.text.as_str() {
        "max-error" => ErrorMetric::Max,
        "rms-error" => ErrorMetric::Rms,
        other => {
            return Err(LangError::new(
                w.span,
                format!("expected max-error or rms-error, found {other:?}"),
            ));
        }
    };
    let limit = a.number("error limit (m)")?;
    Ok(Command::Control(ControlCommand::ClusterExpect {
        cluster,
        metric,
        limit,
    }))
}

/// `follow FOLLOWER LEADER DX,DY` / `follow FOLLOWER none`
pub fn parse_follow(a: &mut Args<'_>) -> Result<Command, LangError> {
    let follower = a.target()?;
    if keyword(a, "none") {
        a.next("none")?;
        return Ok(Command::Control(ControlCommand::Follow {
            follower,
            leader: None,
            offset: Offset { x: 0.0, y: 0.0 },
        }));
    }
    let leader = a.target()?;
    let w = a.next("offset dx,dy (m, leader frame)")?;
    let offset = parse_offset(&w.text).map_err(|e| spec_error(w.span, e))?;
    Ok(Command::Control(ControlCommand::Follow {
        follower,
        leader: Some(leader),
        offset,
    }))
}

/// `nav ROBOT offboard|onboard`
pub fn parse_nav(a: &mut Args<'_>) -> Result<Command, LangError> {
    let robot = a.target()?;
    let w = a.next("offboard or onboard")?;
    let side = match w.text.as_str() {
        "offboard" => NavSide::Offboard,
        "onboard" => NavSide::Onboard,
        other => {
            return Err(LangError::new(
                w.span,
                format!("expected offboard or onboard, found {other:?}"),
            ));
        }
    };
    Ok(Command::Control(ControlCommand::Nav { robot, side }))
}

/// `nav-wait ROBOT NEXT [TIMEOUT]`
pub fn parse_nav_wait(a: &mut Args<'_>) -> Result<Command, LangError> {
    let robot = a.target()?;
    let next = a.count("next waypoint index")?;
    let next = u32::try_from(next).unwrap_or(u32::MAX);
    let timeout = if a.is_empty() {
        DEFAULT_WAIT
    } else {
        a.duration()?
    };
    Ok(Command::Control(ControlCommand::NavWait {
        robot,
        next,
        timeout,
    }))
}

/// `cluster-status` output: one summary line, then one line per slot.
fn cluster_status(name: &str, v: &ClusterView) -> Outcome {
    let st = &v.status;
    let pose = |p: Option<mech_proto::ClusterPose>| match p {
        Some(p) => format!(
            "({:.2}, {:.2}) heading {:.2} rad scale {:.2}",
            p.x, p.y, p.heading, p.scale
        ),
        None => "unknown".to_string(),
    };
    let motion = match &v.motion {
        ClusterMotion::Hold => "holding".to_string(),
        ClusterMotion::Velocity(c) => {
            format!(
                "moving vx {} vy {} wz {} scale rate {}",
                c.vx, c.vy, c.wz, c.scale_rate
            )
        }
        ClusterMotion::Waypoints { list, next, .. } => {
            format!("waypoint {next} of {}", list.len())
        }
    };
    let mut details: Vec<String> = st
        .slots
        .iter()
        .map(|s| {
            format!(
                "{} slot {} at ({:.2}, {:.2}) error {:.3} m",
                s.robot, s.slot, s.x, s.y, s.error
            )
        })
        .collect();
    for r in &st.lost {
        details.push(format!("{r} lost (stale telemetry): not commanded"));
    }
    for r in &st.absent {
        details.push(format!("{r} not routed to {}", v.channel));
    }
    Outcome {
        summary: format!(
            "{name} {} {}: desired {}, measured {}; {motion}; slot error max {:.3} m, RMS {:.3} m since sent",
            formation_name(st.formation.kind),
            v.channel,
            pose(st.desired),
            pose(st.measured),
            v.stats.max,
            v.stats.rms()
        ),
        details,
    }
}

fn fail(target: &Target, e: ControlError) -> LangError {
    LangError::new(target.span, e.to_string())
}

fn outcome(summary: impl Into<String>) -> Outcome {
    Outcome {
        summary: summary.into(),
        details: Vec::new(),
    }
}

impl ControlHub {
    /// Runs one control command of the language.
    pub async fn execute(&self, command: &ControlCommand, at: Span) -> Result<Outcome, LangError> {
        match command {
            ControlCommand::Formation { cluster, formation } => {
                self.set_formation(&cluster.name, formation.clone())
                    .map_err(|e| fail(cluster, e))?;
                let shape = match formation.kind {
                    mech_proto::FormationKind::Custom => {
                        format!("custom, {} offsets", formation.offsets.len())
                    }
                    k => format!("{}, spacing {} m", formation_name(k), formation.spacing),
                };
                Ok(outcome(format!("{}: formation {shape}", cluster.name)))
            }
            ControlCommand::ClusterMove {
                cluster,
                velocity: v,
            } => {
                self.cluster_move(&cluster.name, *v)
                    .map_err(|e| fail(cluster, e))?;
                Ok(outcome(format!(
                    "{} moving at vx {} vy {} m/s, wz {} rad/s, scale rate {} /s (cluster frame) on {}",
                    cluster.name,
                    v.vx,
                    v.vy,
                    v.wz,
                    v.scale_rate,
                    cluster_channel(&cluster.name)
                )))
            }
            ControlCommand::ClusterHold { cluster } => {
                self.hold_cluster(&cluster.name)
                    .map_err(|e| fail(cluster, e))?;
                Ok(outcome(format!("{} holding", cluster.name)))
            }
            ControlCommand::ClusterStatus { cluster } => {
                let v = self.cluster_view(&cluster.name).ok_or_else(|| {
                    fail(cluster, ControlError::UnknownCluster(cluster.name.clone()))
                })?;
                Ok(cluster_status(&cluster.name, &v))
            }
            ControlCommand::ClusterWaypoints {
                cluster,
                waypoints,
                looped,
            } => {
                self.set_cluster_waypoints(&cluster.name, waypoints.clone(), *looped)
                    .map_err(|e| fail(cluster, e))?;
                let l = if *looped { ", looped" } else { "" };
                Ok(outcome(format!(
                    "{} cluster waypoints for {}{l}; start with `send {}`",
                    waypoints.len(),
                    cluster.name,
                    cluster.name
                )))
            }
            ControlCommand::ClusterWait {
                cluster,
                until: ClusterUntil::Settled(tolerance),
                timeout,
            } => {
                let start = Instant::now();
                loop {
                    let view = self.cluster_view(&cluster.name);
                    // Settled means every member routed here and reporting.
                    let worst = view
                        .as_ref()
                        .filter(|v| {
                            !v.status.slots.is_empty()
                                && v.status.absent.is_empty()
                                && v.status.lost.is_empty()
                        })
                        .map(|v| v.status.max_error());
                    if let Some(w) = worst.filter(|w| w <= tolerance) {
                        return Ok(outcome(format!(
                            "{} settled after {:.2} s: every slot error <= {w:.3} m",
                            cluster.name,
                            start.elapsed().as_secs_f64()
                        )));
                    }
                    if start.elapsed() >= *timeout {
                        return Err(LangError::new(
                            at,
                            format!(
                                "timed out after {:.1} s: {} largest slot error {:?} m",
                                timeout.as_secs_f64(),
                                cluster.name,
                                worst
                            ),
                        ));
                    }
                    tokio::time::sleep(POLL).await;
                }
            }
            ControlCommand::ClusterWait {
                cluster,
                until: ClusterUntil::Arrived,
                timeout,
            } => {
                let start = Instant::now();
                loop {
                    let view = self.cluster_view(&cluster.name);
                    if let Some(v) = view.as_ref().filter(|v| v.finished) {
                        return Ok(outcome(format!(
                            "{} finished its waypoints after {:.2} s; slot error max {:.3} m, RMS {:.3} m",
                            cluster.name,
                            start.elapsed().as_secs_f64(),
                            v.stats.max,
                            v.stats.rms()
                        )));
                    }
                    if start.elapsed() >= *timeout {
                        let why = match view.and_then(|v| v.status.waypoint) {
                            Some((next, total)) => format!("at waypoint {next} of {total}"),
                            None => "no waypoints running".to_string(),
                        };
                        return Err(LangError::new(
                            at,
                            format!(
                                "timed out after {:.1} s: {} {why}",
                                timeout.as_secs_f64(),
                                cluster.name
                            ),
                        ));
                    }
                    tokio::time::sleep(POLL).await;
                }
            }
            ControlCommand::ClusterExpect {
                cluster,
                metric,
                limit,
            } => {
                let v = self.cluster_view(&cluster.name).ok_or_else(|| {
                    fail(cluster, ControlError::UnknownCluster(cluster.name.clone()))
                })?;
                let (name, value) = match metric {
                    ErrorMetric::Max => ("max", v.stats.max),
                    ErrorMetric::Rms => ("RMS", v.stats.rms()),
                };
                let text = format!(
                    "{} slot error {name} {value:.3} m over {} samples (limit {limit} m)",
                    cluster.name, v.stats.samples
                );
                if v.stats.samples > 0 && value <= *limit {
                    Ok(outcome(text))
                } else {
                    Err(LangError::new(at, format!("expectation failed: {text}")))
                }
            }
            ControlCommand::Follow {
                follower,
                leader: None,
                ..
            } => {
                self.unfollow(&follower.name);
                Ok(outcome(format!("{} follows nobody", follower.name)))
            }
            ControlCommand::Follow {
                follower,
                leader: Some(leader),
                offset,
            } => {
                self.follow(&follower.name, &leader.name, *offset)
                    .map_err(|e| fail(follower, e))?;
                Ok(outcome(format!(
                    "{} follows {} at {},{} m (leader frame); route it to {}",
                    follower.name,
                    leader.name,
                    offset.x,
                    offset.y,
                    follow_channel(&leader.name)
                )))
            }
            ControlCommand::Nav {
                robot,
                side: NavSide::Offboard,
            } => {
                let v = self
                    .nav_offboard(&robot.name)
                    .await
                    .map_err(|e| fail(robot, e))?;
                let latency = match v.switch_latency {
                    Some(d) => format!(
                        "first command forwarded {:.3} ms after the request",
                        d.as_secs_f64() * 1e3
                    ),
                    None => "no command forwarded yet (no fresh telemetry?)".to_string(),
                };
                Ok(outcome(format!(
                    "{} offboard on {} from waypoint {} of {} (mission {}); {latency}",
                    robot.name, v.channel, v.progress.next, v.progress.total, v.progress.id
                )))
            }
            ControlCommand::Nav {
                robot,
                side: NavSide::Onboard,
            } => {
                let p = self
                    .nav_onboard(&robot.name)
                    .await
                    .map_err(|e| fail(robot, e))?;
                Ok(outcome(format!(
                    "{} onboard: mission {} resumes at waypoint {} of {}",
                    robot.name, p.id, p.next, p.total
                )))
            }
            ControlCommand::NavWait {
                robot,
                next,
                timeout,
            } => {
                let start = Instant::now();
                loop {
                    let offboard = self.nav_view(&robot.name).map(|v| v.progress.next);
                    let onboard = self.gcs().with_fleet(|f| {
                        f.robot(&robot.name).and_then(|r| r.mission).map(|m| m.next)
                    });
                    let at_now = offboard.or(onboard);
                    if at_now.is_some_and(|n| n >= *next) {
                        let side = if offboard.is_some() {
                            "offboard"
                        } else {
                            "onboard"
                        };
                        return Ok(outcome(format!(
                            "{} next waypoint {} ({side}) after {:.2} s",
                            robot.name,
                            at_now.unwrap_or_default(),
                            start.elapsed().as_secs_f64()
                        )));
                    }
                    if start.elapsed() >= *timeout {
                        return Err(LangError::new(
                            at,
                            format!(
                                "timed out after {:.1} s: {} next waypoint is {:?}",
                                timeout.as_secs_f64(),
                                robot.name,
                                at_now
                            ),
                        ));
                    }
                    tokio::time::sleep(POLL).await;
                }
            }
        }
    }
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use crate::lang::parse_line;
    use mech_proto::FormationKind;

    fn control(line: &str) -> ControlCommand {
        match parse_line(line).unwrap().unwrap().command {
            Command::Control(c) => c,
            other => panic!("{line}: not a control command: {other:?}"),
        }
    }

    #[test]
    fn every_control_verb_parses() {
        let ControlCommand::Formation { formation, .. } =
            control("formation c1 custom 0,0.5 0,-0.5 -0.7,0")
        else {
            panic!()
        };
        assert_eq!(formation.kind, FormationKind::Custom);
        assert_eq!(formation.offsets[2], Offset { x: -0.7, y: 0.0 });
        let ControlCommand::Formation { formation, .. } = control("formation c1 wedge 0.8") else {
            panic!()
        };
        assert_eq!(
            (formation.kind, formation.spacing),
            (FormationKind::Wedge, 0.8)
        );
        assert_eq!(
            control("cluster-move c1 0.2 0 0.1"),
            ControlCommand::ClusterMove {
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
            }
        );
        let ControlCommand::ClusterWaypoints {
            waypoints, looped, ..
        } = control("cluster-waypoint c1 2,1 2,2,90deg loop")
        else {
            panic!()
        };
        assert_eq!(waypoints.len(), 2);
        assert!(looped);
        assert!(matches!(
            control("cluster-wait c1 settled 0.05 10s"),
            ControlCommand::ClusterWait { until: ClusterUntil::Settled(t), timeout, .. }
                if t == 0.05 && timeout == Duration::from_secs(10)
        ));
        assert!(matches!(
            control("cluster-wait c1"),
            ControlCommand::ClusterWait {
                until: ClusterUntil::Arrived,
                ..
            }
        ));
        assert!(matches!(
            control("cluster-expect c1 rms-error 0.05"),
            ControlCommand::ClusterExpect {
                metric: ErrorMetric::Rms,
                ..
            }
        ));
        assert!(matches!(
            control("cluster-hold c1"),
            ControlCommand::ClusterHold { .. }
        ));
        assert!(matches!(
            control("cluster-status c1"),
            ControlCommand::ClusterStatus { .. }
        ));
        assert!(matches!(
            control("follow robot_2 robot_1 -0.8,0.5"),
            ControlCommand::Follow { leader: Some(_), offset: Offset { x, y }, .. } if x == -0.8 && y == 0.5
        ));
        assert!(matches!(
            control("follow robot_2 none"),
            ControlCommand::Follow { leader: None, .. }
        ));
        assert!(matches!(
            control("nav robot_1 offboard"),
            ControlCommand::Nav {
                side: NavSide::Offboard,
                ..
            }
        ));
        assert!(matches!(
            control("nav-wait robot_1 3 5s"),
            ControlCommand::NavWait { next: 3, .. }
        ));
    }

    #[test]
    fn bad_arguments_point_at_the_word() {
        let e = parse_line("formation c1 blob").unwrap_err();
        assert_eq!(e.span.column, 14);
        assert!(e.message.contains("unknown formation"));
        let e = parse_line("nav robot_1 sideways").unwrap_err();
        assert!(e.message.contains("offboard or onboard"));
        let e = parse_line("cluster-waypoint c1 1").unwrap_err();
        assert!(e.message.contains("cluster waypoint"));
        assert!(parse_line("cluster-move c1 0.1").is_err());
        assert!(parse_line("follow robot_2 robot_1").is_err());
    }
}

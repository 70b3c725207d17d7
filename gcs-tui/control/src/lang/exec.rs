//! Runs [`Statement`]s against a running [`Gcs`]: the one executor behind
//! the TUI command line and `--script`.

use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::time::Duration;

use futures::future::BoxFuture;
use mech_proto::{
    Actuators, Command as Cmd, CommandKind, SteeringThrottle, Stop, Twist, VelocityHeading,
};
use tokio::time::Instant;

use super::ast::{Command, Expectation, Statement, Target, WaitFor};
use super::parse::{VERBS, failsafe_name, parse_line};
use super::{LangError, Span};
use crate::hub::ControlHub;
use crate::spec::ClusterSpec;
use mech_core::fleet::{Fleet, MissionDelivery, Robot, Severity};
use mech_core::router::{Delivery, Publishers};
use mech_core::{Gcs, LinkState};

/// Sender name of everything the command language publishes.
pub const SENDER: &str = "gcs";

/// How often `wait` re-checks its condition.
const POLL: Duration = Duration::from_millis(10);

/// Starts and stops simulated agents for `spawn` and `--demo`. The GCS core
/// does not depend on the simulator; the binary plugs one in.
pub trait SimSpawner: Send + std::fmt::Debug {
    /// Starts `count` simulated agents registering with the router at
    /// `router`; returns their names.
    fn spawn(
        &mut self,
        count: usize,
        router: SocketAddr,
    ) -> BoxFuture<'_, Result<Vec<String>, String>>;
    /// Stops every agent this spawner started.
    fn shutdown(&mut self) -> BoxFuture<'_, ()>;
}

/// What a command did, for the operator.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Outcome {
    /// One line.
    pub summary: String,
    /// Further lines (`channels`, `status`, `help`).
    pub details: Vec<String>,
}

impl Outcome {
    fn new(summary: impl Into<String>) -> Outcome {
        Outcome {
            summary: summary.into(),
            details: Vec::new(),
        }
    }
}

/// Executes command-language statements. Holds the publishers it created
/// (one per channel, so sequence numbers continue) and the simulator.
#[derive(Debug)]
pub struct Executor {
    gcs: Gcs,
    spawner: Option<Box<dyn SimSpawner>>,
    publishers: Publishers,
    /// Fleet and offboard controllers started by this executor's commands.
    control: ControlHub,
}

impl Executor {
    pub fn new(gcs: Gcs) -> Executor {
        Executor {
            control: ControlHub::new(gcs.clone()),
            publishers: gcs.router().publishers(SENDER),
            gcs,
            spawner: None,
        }
    }

    /// Defines the clusters of the configuration (`[[cluster]]`) and their
    /// formations; a bad one is reported in the event log.
    pub fn with_clusters(self, clusters: &[ClusterSpec]) -> Executor {
        if let Err(e) = self.control.apply_config(clusters) {
            self.gcs
                .update_fleet(|f| f.log(Severity::Error, e.to_string()));
        }
        self
    }

    /// Enables `spawn` (and `--demo`).
    pub fn with_spawner(mut self, spawner: Box<dyn SimSpawner>) -> Executor {
        self.spawner = Some(spawner);
        self
    }

    pub fn gcs(&self) -> &Gcs {
        &self.gcs
    }

    /// The fleet and offboard controllers (cluster poses, slot targets,
    /// tracking errors, offboard progress for displays).
    pub fn control(&self) -> &ControlHub {
        &self.control
    }

    /// Parses and runs one command line (the TUI command line). A blank line
    /// does nothing.
    pub async fn execute_line(&mut self, line: &str) -> Result<Outcome, LangError> {
        match parse_line(line)? {
            Some(stmt) => self.execute(&stmt).await,
            None => Ok(Outcome::default()),
        }
    }

    /// Stops what the executor started (simulated agents).
    pub async fn shutdown(&mut self) {
        if let Some(s) = self.spawner.as_mut() {
            s.shutdown().await;
        }
    }

    /// Runs one statement. Errors point at the statement or the argument at
    /// fault.
    pub async fn execute(&mut self, stmt: &Statement) -> Result<Outcome, LangError> {
        let at = stmt.span;
        match &stmt.command {
            Command::Route { target, channel } => {
                let robots = self.resolve(target)?;
                for r in &robots {
                    self.gcs
                        .router()
                        .set_route(r, channel.as_deref())
                        .await
                        .map_err(|e| LangError::new(target.span, e.to_string()))?;
                }
                Ok(Outcome::new(format!(
                    "{} routed to {}",
                    robots.join(", "),
                    channel.as_deref().unwrap_or("none")
                )))
            }
            Command::Mode { target, mode } => {
                let robots = self.resolve(target)?;
                self.gcs.update_fleet(|f| {
                    for r in &robots {
                        let robot = f
                            .robot(r)
                            .ok_or_else(|| LangError::new(target.span, format!("no robot {r}")))?;
                        if !robot.can(*mode) {
                            return Err(LangError::new(
                                target.span,
                                format!("{r} ({}) cannot obey {mode} commands", robot.platform),
                            ));
                        }
                    }
                    for r in &robots {
                        if let Some(robot) = f.robot_mut(r) {
                            robot.gcs_mode = Some(*mode);
                        }
                    }
                    Ok(())
                })?;
                Ok(Outcome::new(format!(
                    "{} drive mode {mode}",
                    robots.join(", ")
                )))
            }
            Command::Drive { target, values } => self.drive(target, values).await,
            Command::Waypoint {
                target,
                points,
                looped,
            } => {
                let robots = self.resolve(target)?;
                self.gcs.update_fleet(|f| {
                    for r in &robots {
                        if let Some(robot) = f.robot_mut(r) {
                            robot.waypoints.draft.clone_from(points);
                            robot.waypoints.looped = *looped;
                        }
                    }
                });
                let l = if *looped { ", looped" } else { "" };
                let s = if points.len() == 1 { "" } else { "s" };
                Ok(Outcome::new(format!(
                    "{} waypoint{s} for {}{l}",
                    points.len(),
                    robots.join(", ")
                )))
            }
            Command::Send {
                target,
                channel: None,
            } if self.control.has_cluster_draft(&target.name) => {
                let n = self
                    .control
                    .send_cluster(&target.name)
                    .map_err(|e| LangError::new(target.span, e.to_string()))?;
                Ok(Outcome::new(format!(
                    "{}: {n} cluster waypoints started",
                    target.name
                )))
            }
            Command::Send { target, channel } => {
                let robots = self.resolve(target)?;
                let channel = channel
                    .clone()
                    .unwrap_or_else(|| self.gcs.config().fleet.mission_channel.clone());
                let mut ids = Vec::new();
                for r in &robots {
                    let draft = self.gcs.with_fleet(|f| {
                        f.robot(r)
                            .map(|x| (x.waypoints.draft.clone(), x.waypoints.looped))
                    });
                    let Some((waypoints, looped)) = draft.filter(|(w, _)| !w.is_empty()) else {
                        return Err(LangError::new(
                            target.span,
                            format!("{r} has no waypoints; set them with `waypoint {r} X,Y ...`"),
                        ));
                    };
                    let id = self
                        .gcs
                        .send_waypoints(SENDER, r, &channel, waypoints, looped)
                        .await
                        .map_err(|e| LangError::new(target.span, e.to_string()))?;
                    ids.push(format!("{r}: mission {id}"));
                }
                Ok(Outcome::new(format!(
                    "sent on {channel}: {}",
                    ids.join(", ")
                )))
            }
            Command::Cluster { name, members } => {
                let mut names = Vec::new();
                for m in members {
                    let known = self.gcs.with_fleet(|f| f.robot(&m.name).is_some());
                    if !known {
                        return Err(LangError::new(
                            m.span,
                            format!("no robot named {:?}", m.name),
                        ));
                    }
                    names.push(m.name.clone());
                }
                self.gcs
                    .update_fleet(|f| f.set_cluster(name, names.clone()));
                Ok(Outcome::new(format!(
                    "cluster {name}: {}",
                    names.join(", ")
                )))
            }
            Command::Stop { target } => {
                let robots = self.resolve(target)?;
                let mut stopped = Vec::new();
                for r in &robots {
                    let channel = self
                        .gcs
                        .with_fleet(|f| f.robot(r).and_then(|x| x.route.requested.clone()));
                    let Some(channel) = channel else { continue };
                    let delivery = self
                        .publishers
                        .on(&channel)
                        .send(r, Cmd::Stop(Stop {}))
                        .await
                        .map_err(|e| LangError::new(at, e.to_string()))?;
                    if delivery == Delivery::Forwarded(1) {
                        stopped.push(r.clone());
                    }
                }
                Ok(Outcome::new(format!(
                    "stop sent to {} of {} robots (robots routed to none already hold still)",
                    stopped.len(),
                    robots.len()
                )))
            }
            Command::EStop => {
                let id = self.gcs.router().estop().await;
                Ok(Outcome::new(format!("e-stop {id} engaged for every robot")))
            }
            Command::Release => {
                let id = self.gcs.router().release().await;
                Ok(Outcome::new(format!("e-stop released ({id})")))
            }
            Command::Wait { condition, timeout } => self.wait(condition, *timeout, at).await,
            Command::Expect(e) => {
                let f = self.gcs.snapshot();
                self.check(&f, e).map(Outcome::new)
            }
            Command::Sleep(d) => {
                tokio::time::sleep(*d).await;
                Ok(Outcome::new(format!("slept {:.3} s", d.as_secs_f64())))
            }
            Command::Log(text) => {
                tracing::info!(target: "script", "{text}");
                self.gcs
                    .update_fleet(|f| f.log(Severity::Info, text.clone()));
                Ok(Outcome::new(text.clone()))
            }
            Command::Spawn(n) => {
                let mut router = self.gcs.router().udp_addr();
                if router.ip().is_unspecified() {
                    router.set_ip(IpAddr::V4(Ipv4Addr::LOCALHOST));
                }
                let spawner = self.spawner.as_mut().ok_or_else(|| {
                    LangError::new(at, "simulated agents are not available in this build")
                })?;
                let names = spawner.spawn(*n, router).await.map_err(|e| {
                    LangError::new(at, format!("cannot spawn simulated agents: {e}"))
                })?;
                Ok(Outcome::new(format!("spawned {}", names.join(", "))))
            }
            Command::Channels => {
                let list = self.gcs.router().channels();
                let details = list
                    .iter()
                    .map(|c| {
                        format!(
                            "{} publisher {} {:.1} Hz robots [{}]",
                            c.name,
                            c.publisher,
                            c.rate_hz,
                            c.robots.join(", ")
                        )
                    })
                    .collect();
                Ok(Outcome {
                    summary: format!("{} live channels", list.len()),
                    details,
                })
            }
            Command::Status(target) => {
                let robots = match target {
                    Some(t) => self.resolve(t)?,
                    None => self.gcs.with_fleet(|f| f.robots.keys().cloned().collect()),
                };
                let details = self.gcs.with_fleet(|f| {
                    robots
                        .iter()
                        .filter_map(|r| f.robot(r))
                        .map(status_line)
                        .collect::<Vec<_>>()
                });
                Ok(Outcome {
                    summary: format!("{} robots", details.len()),
                    details,
                })
            }
            Command::Control(c) => self.control.execute(c, at).await,
            Command::Help => Ok(Outcome {
                summary: format!("{} commands", VERBS.len()),
                details: VERBS
                    .iter()
                    .map(|v| format!("{:<60} {}", v.usage, v.help))
                    .collect(),
            }),
        }
    }

    /// Robots named by `target`; an error at the target if it names nothing.
    fn resolve(&self, target: &Target) -> Result<Vec<String>, LangError> {
        self.gcs
            .with_fleet(|f| f.resolve(&target.name))
            .ok_or_else(|| {
                LangError::new(
                    target.span,
                    format!("no robot or cluster named {:?}", target.name),
                )
            })
    }

    async fn drive(&mut self, target: &Target, values: &[f64]) -> Result<Outcome, LangError> {
        let robots = self.resolve(target)?;
        let channel = self.gcs.config().fleet.command_channel.clone();
        let mut report = Vec::new();
        for r in &robots {
            let mode = self.gcs.with_fleet(|f| f.robot(r).and_then(|x| x.gcs_mode));
            let mode = mode.ok_or_else(|| {
                LangError::new(
                    target.span,
                    format!("{r} has no drive mode; set one with `mode {r} MODE`"),
                )
            })?;
            let cmd = command(mode, values).map_err(|m| LangError::new(target.span, m))?;
            let delivery = self
                .publishers
                .on(&channel)
                .send(r, cmd)
                .await
                .map_err(|e| LangError::new(target.span, e.to_string()))?;
            report.push(match delivery {
                Delivery::Forwarded(_) => format!("{r}: forwarded"),
                Delivery::Dropped(reason) => {
                    format!("{r}: dropped ({}; route it to {channel})", reason.as_str())
                }
                Delivery::Consumed => format!("{r}: consumed"),
            });
        }
        Ok(Outcome::new(format!(
            "{mode_channel}: {}",
            report.join(", "),
            mode_channel = channel
        )))
    }

    async fn wait(
        &mut self,
        condition: &WaitFor,
        timeout: Duration,
        at: Span,
    ) -> Result<Outcome, LangError> {
        let start = Instant::now();
        let deadline = start + timeout;
        loop {
            let why_not = self.gcs.with_fleet(|f| self.unmet(f, condition));
            match why_not {
                None => {
                    return Ok(Outcome::new(format!(
                        "after {:.3} s",
                        start.elapsed().as_secs_f64()
                    )));
                }
                Some(reason) if Instant::now() >= deadline => {
                    return Err(LangError::new(
                        at,
                        format!("timed out after {:.1} s: {reason}", timeout.as_secs_f64()),
                    ));
                }
                Some(_) => tokio::time::sleep(POLL).await,
            }
        }
    }

    /// `None` if the condition holds, else why not.
    fn unmet(&self, f: &Fleet, condition: &WaitFor) -> Option<String> {
        // Waiting for a robot that has not registered yet is allowed.
        let members = |t: &Target| f.resolve(&t.name).unwrap_or_else(|| vec![t.name.clone()]);
        let each = |t: &Target, ok: &dyn Fn(&Robot) -> Option<String>| {
            members(t).iter().find_map(|name| match f.robot(name) {
                None => Some(format!("{name} is not registered")),
                Some(r) => ok(r),
            })
        };
        match condition {
            WaitFor::Connected(t) => each(t, &|r| {
                (r.link != LinkState::Connected)
                    .then(|| format!("{} is {}", r.name, r.link.as_str()))
            }),
            WaitFor::Lost(t) => each(t, &|r| {
                (r.link != LinkState::Lost).then(|| format!("{} is {}", r.name, r.link.as_str()))
            }),
            WaitFor::Robots(n) => {
                let c = f
                    .robots
                    .values()
                    .filter(|r| r.link == LinkState::Connected)
                    .count();
                (c < *n).then(|| format!("{c} of {n} robots connected"))
            }
            WaitFor::Arrived(t) => each(t, &|r| {
                if r.arrived() {
                    return None;
                }
                Some(match (&r.waypoints.sent, &r.mission) {
                    (None, _) => format!("{} has no mission", r.name),
                    (Some(s), _) if s.delivery != MissionDelivery::Acked => {
                        format!("{} mission {} is {:?}", r.name, s.id, s.delivery)
                    }
                    (Some(s), Some(p)) if p.id == s.id => {
                        format!("{} at waypoint {} of {}", r.name, p.next, p.total)
                    }
                    (Some(_), _) => format!(
                        "{} is not running the mission (route it to its channel)",
                        r.name
                    ),
                })
            }),
            WaitFor::Route(t, channel) => each(t, &|r| {
                (r.route.is_pending() || r.route.acknowledged != *channel).then(|| {
                    format!(
                        "{} acknowledged {}, requested {}",
                        r.name,
                        show(&r.route.acknowledged),
                        show(&r.route.requested)
                    )
                })
            }),
            WaitFor::Near {
                target,
                x,
                y,
                tolerance,
            } => each(target, &|r| {
                let d = r.distance_to(*x, *y);
                (d > *tolerance).then(|| format!("{} is {d:.3} m from ({x}, {y})", r.name))
            }),
            WaitFor::EStopAcked => (!f.estop.pending.is_empty()).then(|| {
                format!(
                    "waiting for {}",
                    f.estop
                        .pending
                        .iter()
                        .cloned()
                        .collect::<Vec<_>>()
                        .join(", ")
                )
            }),
        }
    }

    fn check(&self, f: &Fleet, e: &Expectation) -> Result<String, LangError> {
        let robots = |t: &Target| {
            f.resolve(&t.name).ok_or_else(|| {
                LangError::new(t.span, format!("no robot or cluster named {:?}", t.name))
            })
        };
        let fail = |t: &Target, m: String| Err(LangError::new(t.span, m));
        match e {
            Expectation::Near {
                target,
                x,
                y,
                tolerance,
            } => {
                let mut worst = 0.0_f64;
                for name in robots(target)? {
                    let Some(r) = f.robot(&name) else { continue };
                    let d = r.distance_to(*x, *y);
                    if d > *tolerance {
                        return fail(
                            target,
                            format!(
                                "{name} is {d:.3} m from ({x}, {y}), more than {tolerance} m (at {:.3}, {:.3})",
                                r.pose.x, r.pose.y
                            ),
                        );
                    }
                    worst = worst.max(d);
                }
                Ok(format!("within {worst:.3} m"))
            }
            Expectation::Route(target, channel) => {
                for name in robots(target)? {
                    let Some(r) = f.robot(&name) else { continue };
                    if r.route.is_pending() || r.route.acknowledged != *channel {
                        return fail(
                            target,
                            format!(
                                "{name} acknowledged route {} (requested {}), expected {}",
                                show(&r.route.acknowledged),
                                show(&r.route.requested),
                                show(channel)
                            ),
                        );
                    }
                }
                Ok(format!("route {}", show(channel)))
            }
            Expectation::Link(target, state) => {
                for name in robots(target)? {
                    let Some(r) = f.robot(&name) else { continue };
                    if r.link != *state {
                        return fail(
                            target,
                            format!("{name} is {}, expected {}", r.link.as_str(), state.as_str()),
                        );
                    }
                }
                Ok(format!("link {}", state.as_str()))
            }
            Expectation::Failsafe(target, state) => {
                for name in robots(target)? {
                    let Some(r) = f.robot(&name) else { continue };
                    if r.failsafe != *state {
                        return fail(
                            target,
                            format!(
                                "{name} failsafe is {}, expected {}",
                                failsafe_name(r.failsafe),
                                failsafe_name(*state)
                            ),
                        );
                    }
                }
                Ok(format!("failsafe {}", failsafe_name(*state)))
            }
            Expectation::DroppedAtLeast { channel, min } => {
                let n = f
                    .counters
                    .channels
                    .get(channel)
                    .map_or(0, |t| t.dropped.not_routed);
                if n < *min {
                    return Err(LangError::new(
                        Span::default(),
                        format!(
                            "{n} messages on {channel} dropped as not routed, expected at least {min}"
                        ),
                    ));
                }
                Ok(format!("{n} dropped on {channel}"))
            }
        }
    }
}

fn show(c: &Option<String>) -> &str {
    c.as_deref().unwrap_or("none")
}

/// Builds a command of `mode` from the numbers written after `drive`.
pub fn command(mode: CommandKind, v: &[f64]) -> Result<Cmd, String> {
    let need = |n: usize| -> Result<(), String> {
        if v.len() == n {
            Ok(())
        } else {
            Err(format!("{mode} takes {n} numbers, got {}", v.len()))
        }
    };
    let cmd = match mode {
        CommandKind::Actuators => Cmd::Actuators(Actuators {
            outputs: v.to_vec(),
        }),
        CommandKind::SteeringThrottle => {
            need(2)?;
            Cmd::SteeringThrottle(SteeringThrottle {
                steering: v[0],
                throttle: v[1],
            })
        }
        CommandKind::VelocityHeading => {
            need(2)?;
            Cmd::VelocityHeading(VelocityHeading {
                speed: v[0],
                heading: v[1],
            })
        }
        CommandKind::Twist => match v {
            [vx, vy, wz] => Cmd::Twist(Twist {
                vx: *vx,
                vy: *vy,
                vz: 0.0,
                wz: *wz,
            }),
            [vx, vy, vz, wz] => Cmd::Twist(Twist {
                vx: *vx,
                vy: *vy,
                vz: *vz,
                wz: *wz,
            }),
            _ => {
                return Err(format!(
                    "twist takes vx vy wz or vx vy vz wz, got {} numbers",
                    v.len()
                ));
            }
        },
        CommandKind::Stop => {
            need(0)?;
            Cmd::Stop(Stop {})
        }
        CommandKind::Waypoints => {
            return Err("waypoints are sent with `waypoint` and `send`".into());
        }
    };
    cmd.validate().map_err(|e| e.to_string())?;
    Ok(cmd)
}

fn status_line(r: &Robot) -> String {
    format!(
        "{} #{} {} {} at ({:.2}, {:.2}) heading {:.2} speed {:.2} mode {:?} route {}{} failsafe {}",
        r.name,
        r.id,
        r.platform,
        r.link.as_str(),
        r.pose.x,
        r.pose.y,
        r.pose.heading,
        r.speed(),
        r.mode,
        show(&r.route.requested),
        if r.route.is_pending() {
            " (pending)"
        } else {
            ""
        },
        failsafe_name(r.failsafe),
    )
}

//! `mission save TARGET FILE [origin LAT,LON[,ALT]]` and `mission load
//! TARGET FILE [origin LAT,LON[,ALT]|home]`: a robot's waypoint list (or a
//! cluster's `cluster-waypoint` list), with its arrival times and loop,
//! to and from a file on the station's machine, in MECH's format (`.toml`)
//! or as `QGC WPL 110` (`.waypoints`, `.txt`: MAVProxy, QGroundControl).
//! Loading sets the draft, as `waypoint` / `cluster-waypoint` do: `send`
//! sends it. The formats are in [`crate::mission_file`]; which paths a
//! session may use, in [`crate::files`].

use std::path::Path;

use super::control_error;
use crate::lang::args::{Args, Target};
use crate::lang::context::Context;
use crate::lang::{LangError, Outcome, Span};
use crate::mission_file::qgc::{GeoOrigin, Origin};
use crate::mission_file::{self, Format, MissionPlan};

/// Mission files are small: a larger file is not one.
const MAX_FILE_BYTES: u64 = 1 << 20;

/// Save to or load from a mission file.
#[derive(Debug, Clone, PartialEq)]
pub struct MissionFile {
    pub action: Action,
    pub target: Target,
    /// The file as typed.
    pub file: String,
    pub file_span: Span,
    /// Where a QGC WPL file's global coordinates put the arena.
    pub origin: Option<Origin>,
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Action {
    Save,
    Load,
}

impl MissionFile {
    pub(super) fn parse(a: &mut Args<'_>) -> Result<MissionFile, LangError> {
        let action = if a.keyword("save") {
            Action::Save
        } else if a.keyword("load") {
            Action::Load
        } else {
            let w = a.next("save or load")?;
            return Err(LangError::new(
                w.span,
                format!("expected save or load, got {:?}", w.text),
            ));
        };
        let target = a.target()?;
        let file = a.next("file")?;
        let origin = if a.keyword("origin") {
            let w = a.next("origin LAT,LON[,ALT] or home")?;
            Some(parse_origin(&w.text, action).map_err(|e| LangError::new(w.span, e))?)
        } else {
            None
        };
        a.finish()?;
        Ok(MissionFile {
            action,
            target,
            file: file.text.clone(),
            file_span: file.span,
            origin,
        })
    }

    pub(super) async fn apply(&self, ctx: &mut Context, _at: Span) -> Result<Outcome, LangError> {
        let saving = self.action == Action::Save;
        let path = ctx
            .files
            .resolve(&self.file, saving)
            .map_err(|e| LangError::new(self.file_span, e))?;
        match self.action {
            Action::Save => self.save(ctx, &path).await,
            Action::Load => self.load(ctx, &path).await,
        }
    }

    fn file_error(&self, path: &Path, e: impl std::fmt::Display) -> LangError {
        LangError::new(self.file_span, format!("{}: {e}", path.display()))
    }

    fn is_cluster(&self, ctx: &Context) -> bool {
        ctx.gcs
            .with_fleet(|f| f.clusters.contains_key(&self.target.name))
    }

    async fn save(&self, ctx: &mut Context, path: &Path) -> Result<Outcome, LangError> {
        let format =
            Format::of_name(path).map_err(|e| LangError::new(self.file_span, e.to_string()))?;
        let plan = self.plan_of(ctx)?;
        let origin = match self.origin {
            Some(Origin::Geo(g)) if format == Format::QgcWpl => Some(g),
            Some(_) => {
                return Err(LangError::new(
                    self.file_span,
                    "an origin places a QGC WPL file (.waypoints, .txt) on the Earth; \
                     MECH's .toml is in arena metres",
                ));
            }
            None => None,
        };
        let (text, notes) =
            mission_file::write(&plan, format, origin).map_err(|e| self.file_error(path, e))?;
        tokio::fs::write(path, text)
            .await
            .map_err(|e| self.file_error(path, e))?;
        let frame = match (format, origin) {
            (Format::Mech, _) => "arena metres",
            (Format::QgcWpl, None) => "MAV_FRAME_LOCAL_ENU",
            (Format::QgcWpl, Some(_)) => "MAV_FRAME_GLOBAL_RELATIVE_ALT",
        };
        let mut out = Outcome::new(format!(
            "{}: {} saved to {} ({}, {frame})",
            self.target.name,
            describe(&plan),
            path.display(),
            format.name()
        ));
        out.details = notes;
        Ok(out)
    }

    /// What `mission save` writes for the target: a cluster's waypoint
    /// draft, or one robot's.
    fn plan_of(&self, ctx: &Context) -> Result<MissionPlan, LangError> {
        let name = &self.target.name;
        if self.is_cluster(ctx) {
            let (waypoints, looped) = ctx.control.cluster_draft(name).ok_or_else(|| {
                LangError::new(
                    self.target.span,
                    format!(
                        "{name} has no cluster waypoints (`cluster-waypoint {name} X,Y ...`); \
                         a member's own waypoints are saved with `mission save ROBOT FILE`"
                    ),
                )
            })?;
            return Ok(MissionPlan::Cluster { waypoints, looped });
        }
        let robots = ctx.resolve(&self.target)?;
        let [robot] = robots.as_slice() else {
            return Err(LangError::new(
                self.target.span,
                format!(
                    "{name} is {} robots: a mission file holds one robot's waypoints or a cluster's",
                    robots.len()
                ),
            ));
        };
        let draft = ctx.gcs.with_fleet(|f| {
            f.robot(robot)
                .map(|r| (r.waypoints.draft.clone(), r.waypoints.looped))
        });
        match draft {
            Some((waypoints, looped)) if !waypoints.is_empty() => {
                Ok(MissionPlan::Robot { waypoints, looped })
            }
            _ => Err(LangError::new(
                self.target.span,
                format!("{robot} has no waypoints; set them with `waypoint {robot} X,Y ...`"),
            )),
        }
    }

    async fn load(&self, ctx: &mut Context, path: &Path) -> Result<Outcome, LangError> {
        let text = crate::files::read_text(path, MAX_FILE_BYTES)
            .await
            .map_err(|e| self.file_error(path, e))?;
        let cluster = self.is_cluster(ctx);
        let (plan, notes) = mission_file::read(&text, self.origin, cluster)
            .map_err(|e| self.file_error(path, e))?;
        let name = &self.target.name;
        let summary = describe(&plan);
        match plan {
            MissionPlan::Cluster { waypoints, looped } => {
                if !cluster {
                    return Err(LangError::new(
                        self.target.span,
                        format!(
                            "{} holds a cluster's waypoints: load it into a cluster",
                            path.display()
                        ),
                    ));
                }
                ctx.control
                    .set_cluster_waypoints(name, waypoints, looped)
                    .map_err(|e| control_error(&self.target, e))?;
            }
            MissionPlan::Robot { waypoints, looped } => {
                let robots = ctx.resolve(&self.target)?;
                ctx.gcs.update_fleet(|f| {
                    for r in &robots {
                        if let Some(robot) = f.robot_mut(r) {
                            robot.waypoints.draft.clone_from(&waypoints);
                            robot.waypoints.looped = looped;
                        }
                    }
                });
            }
        }
        let mut out = Outcome::new(format!(
            "{name}: {summary} loaded from {} ({}); `send {name}` sends them",
            path.display(),
            Format::of_text(&text).name()
        ));
        out.details = notes;
        Ok(out)
    }
}

/// `3 waypoints, looped, 2 timed`.
fn describe(plan: &MissionPlan) -> String {
    let n = plan.len();
    let mut s = format!("{n} waypoint{}", if n == 1 { "" } else { "s" });
    if plan.looped() {
        s.push_str(", looped");
    }
    if let MissionPlan::Robot { waypoints, .. } = plan {
        let timed = waypoints.iter().filter(|w| w.time.is_some()).count();
        if timed > 0 {
            s.push_str(&format!(", {timed} timed"));
        }
    }
    s
}

/// `home` (loading only) or `LAT,LON[,ALT]` in degrees and metres.
fn parse_origin(text: &str, action: Action) -> Result<Origin, String> {
    if text == "home" {
        return match action {
            Action::Load => Ok(Origin::Home),
            Action::Save => {
                Err("`origin home` reads a file's home; to save, give LAT,LON[,ALT]".into())
            }
        };
    }
    let numbers: Option<Vec<f64>> = text
        .split(',')
        .map(|s| s.trim().parse::<f64>().ok().filter(|v| v.is_finite()))
        .collect();
    let bad = || {
        format!(
            "expected an origin like 52.0,4.37 or 52.0,4.37,3.5 (degrees, m) or home, found {text:?}"
        )
    };
    let numbers = numbers.ok_or_else(bad)?;
    let (lat, lon, alt) = match numbers.as_slice() {
        [lat, lon] => (*lat, *lon, 0.0),
        [lat, lon, alt] => (*lat, *lon, *alt),
        _ => return Err(bad()),
    };
    if !(-90.0..=90.0).contains(&lat) || !(-180.0..=180.0).contains(&lon) {
        return Err(format!(
            "latitude {lat} or longitude {lon} is off the Earth"
        ));
    }
    Ok(Origin::Geo(GeoOrigin { lat, lon, alt }))
}

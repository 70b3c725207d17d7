//! Runs [`Statement`]s against a running [`Gcs`]: the one executor behind
//! the TUI command line and `--script`. Each verb's work is in its own file
//! under [`verbs`](super::verbs); this is the front door.

use std::sync::Arc;

use super::context::Context;
use super::parse::{Statement, parse_line};
use super::{LangError, Outcome};
use crate::files::{FileAccess, default_dir};
use crate::hub::ControlHub;
use crate::spec::ClusterSpec;
use mech_core::Gcs;
use mech_core::fleet::Severity;
use mech_core::record::OperatorRecord;

pub use super::context::{RemoteRoutes, SENDER, SharedSpawner, SimSpawner};

/// Executes command-language statements. Holds the publishers it created
/// (one per channel, so sequence numbers continue), the controllers its
/// commands started and the simulator.
#[derive(Debug)]
pub struct Executor {
    ctx: Context,
    /// Where commands come from, as recordings name it (`tui`, `script`).
    source: String,
}

impl Executor {
    pub fn new(gcs: Gcs) -> Executor {
        Executor {
            ctx: Context::new(gcs),
            source: "tui".into(),
        }
    }

    /// Names where this executor's commands come from in recordings
    /// (`tui` unless told).
    pub fn with_source(mut self, source: &str) -> Executor {
        self.source = source.to_string();
        self
    }

    /// Where `record start` without a file records (rotating files, with
    /// the `[record]` size cap): `[record] dir`, else the log directory;
    /// and the only place an operator's `record start FILE` may write.
    pub fn with_record_dir(mut self, dir: std::path::PathBuf) -> Executor {
        self.ctx.record_dir = Some(dir);
        self
    }

    /// Defines the clusters of the configuration (`[[cluster]]`) and their
    /// formations; a bad one is reported in the event log.
    pub fn with_clusters(self, clusters: &[ClusterSpec]) -> Executor {
        if let Err(e) = self.ctx.control.apply_config(clusters) {
            self.ctx
                .gcs
                .update_fleet(|f| f.log(Severity::Error, e.to_string()));
        }
        self
    }

    /// Runs fleet and offboard controllers in `control` instead of a hub
    /// of its own: every executor of a station shares one, so a cluster
    /// started from one operator's command line is the same cluster for
    /// all.
    pub fn with_control(mut self, control: ControlHub) -> Executor {
        self.ctx.control = control;
        self
    }

    /// An operator's session: publishes and sends missions as `sender`
    /// (the operator's name) instead of [`SENDER`], so the router and the
    /// robots see who commanded them; and reads and writes mission and
    /// arena files only in the station's missions directory (`[fleet]
    /// mission_dir`, else [`default_dir`](crate::files::default_dir)), and
    /// recordings only in the recording directory
    /// ([`Executor::with_record_dir`]): an operator, maybe attached over
    /// TCP from elsewhere, has no account on the station's machine
    /// ([`crate::files`]).
    pub fn with_sender(mut self, sender: &str) -> Executor {
        self.ctx.publishers = self.ctx.gcs.router().publishers(sender);
        self.ctx.sender = sender.to_string();
        let dir = self.ctx.gcs.config().fleet.mission_dir.clone();
        self.ctx.files = FileAccess::Confined(dir.unwrap_or_else(default_dir));
        self
    }

    /// Mission and arena files only in `dir`, recordings only in the
    /// recording directory (what [`Executor::with_sender`] sets for an
    /// operator's session), or, with `None`, wherever the station process
    /// may read and write (a script the station runs itself).
    pub fn with_mission_dir(mut self, dir: Option<std::path::PathBuf>) -> Executor {
        self.ctx.files = match dir {
            Some(d) => FileAccess::Confined(d),
            None => FileAccess::Station,
        };
        self
    }

    /// Enables `spawn` (and `--demo`).
    pub fn with_spawner(mut self, spawner: Box<dyn SimSpawner>) -> Executor {
        self.ctx.spawner = Some(spawner);
        self
    }

    /// Lets `route` reach other stations' robots, as requests to them.
    pub fn with_remote_routes(mut self, routes: Arc<dyn RemoteRoutes>) -> Executor {
        self.ctx.remote_routes = Some(routes);
        self
    }

    pub fn gcs(&self) -> &Gcs {
        &self.ctx.gcs
    }

    /// The fleet and offboard controllers (cluster poses, slot targets,
    /// tracking errors, offboard progress for displays).
    pub fn control(&self) -> &ControlHub {
        &self.ctx.control
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
        if let Some(s) = self.ctx.spawner.as_mut() {
            s.shutdown().await;
        }
    }

    /// Runs one statement. Errors point at the statement or the argument at
    /// fault.
    /// Each command and its outcome goes into the recording, if one is
    /// being made: the summary, then each detail line (`status`'s robots),
    /// one per line, so a replay prints what the run printed.
    pub async fn execute(&mut self, stmt: &Statement) -> Result<Outcome, LangError> {
        let result = stmt.command.apply(&mut self.ctx, stmt.span).await;
        let summary = match &result {
            Ok(o) => std::iter::once(o.summary.as_str())
                .chain(o.details.iter().map(String::as_str))
                .collect::<Vec<_>>()
                .join("\n"),
            Err(e) => e.to_string(),
        };
        self.ctx.gcs.router().record_operator(OperatorRecord {
            at: std::time::Duration::ZERO,
            source: self.source.clone(),
            line: stmt.span.line,
            text: stmt.text.clone(),
            ok: result.is_ok(),
            summary,
        });
        result
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn assert_send<T: Send>(_: &T) {}

    /// Compiles only if `execute` can run on a spawned task, as the TUI runs
    /// it: a verb must not hold the (not `Sync`) context across an await.
    #[allow(dead_code)]
    fn execute_is_send(exec: &mut Executor, stmt: &Statement) {
        let run = exec.execute(stmt);
        assert_send(&run);
    }
}

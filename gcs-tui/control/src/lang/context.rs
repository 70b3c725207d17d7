//! What a verb runs against: the station, its controllers, the publishers
//! the language sends through and the simulator, with the name lookups
//! every verb needs.

use std::net::SocketAddr;

use futures::future::BoxFuture;

use super::LangError;
use super::args::Target;
use crate::hub::ControlHub;
use mech_core::Gcs;
use mech_core::router::{Publishers, RouterHandle};

/// Sender name of everything the command language publishes.
pub const SENDER: &str = "gcs";

/// Starts and stops simulated agents for `spawn` and `--demo`. The GCS core
/// does not depend on the simulator; the binary plugs one in.
pub trait SimSpawner: Send + std::fmt::Debug {
    /// Starts `count` simulated agents registering with `router` at
    /// `addr` (when the router authenticates, the spawner gives it a key
    /// for each agent); returns their names.
    fn spawn(
        &mut self,
        count: usize,
        addr: SocketAddr,
        router: RouterHandle,
    ) -> BoxFuture<'_, Result<Vec<String>, String>>;
    /// Stops every agent this spawner started.
    fn shutdown(&mut self) -> BoxFuture<'_, ()>;
}

/// The state behind an [`Executor`](super::Executor), handed to each verb's
/// `apply`.
#[derive(Debug)]
pub(super) struct Context {
    pub(super) gcs: Gcs,
    pub(super) spawner: Option<Box<dyn SimSpawner>>,
    /// One publisher per channel under [`SENDER`], so a channel's sequence
    /// numbers run on from one command to the next.
    pub(super) publishers: Publishers,
    /// Fleet and offboard controllers started by this executor's commands.
    pub(super) control: ControlHub,
    /// Where `record start` without a file records (rotating files).
    pub(super) record_dir: Option<std::path::PathBuf>,
}

impl Context {
    pub(super) fn new(gcs: Gcs) -> Context {
        Context {
            control: ControlHub::new(gcs.clone()),
            publishers: gcs.router().publishers(SENDER),
            gcs,
            spawner: None,
            record_dir: None,
        }
    }

    /// Robots named by `target`; an error at the target if it names nothing.
    pub(super) fn resolve(&self, target: &Target) -> Result<Vec<String>, LangError> {
        self.gcs
            .with_fleet(|f| f.resolve(&target.name))
            .ok_or_else(|| {
                LangError::new(
                    target.span,
                    format!("no robot or cluster named {:?}", target.name),
                )
            })
    }
}

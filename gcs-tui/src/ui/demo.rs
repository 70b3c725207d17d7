//! The demo fleet: simulated agents (the agent's own core, over real UDP
//! sockets) spread over the demo arena, started by the command language's
//! `spawn N` (and so by `mech-gcs --demo N`).

use std::net::SocketAddr;

use futures::FutureExt;
use futures::future::BoxFuture;
use mech_agent::sim::{Arena, SimFleet, SimFleetOptions};

use super::station::demo_arena;
use crate::lang::SimSpawner;

/// Spawns simulated fleets of mixed platforms (diff-drive, kiwi,
/// quadcopter) and stops them on shutdown.
#[derive(Debug, Default)]
pub struct DemoSpawner {
    fleets: Vec<SimFleet>,
}

impl DemoSpawner {
    pub fn boxed() -> Box<dyn SimSpawner> {
        Box::new(DemoSpawner::default())
    }
}

impl SimSpawner for DemoSpawner {
    fn spawn(
        &mut self,
        count: usize,
        router: SocketAddr,
    ) -> BoxFuture<'_, Result<Vec<String>, String>> {
        async move {
            let a = demo_arena();
            let arena = Arena {
                min_x: a.min_x,
                min_y: a.min_y,
                max_x: a.max_x,
                max_y: a.max_y,
            };
            let fleet = SimFleet::spawn(count, router, arena, SimFleetOptions::default())
                .await
                .map_err(|e| format!("cannot start simulated agents: {e}"))?;
            let names = fleet.names();
            self.fleets.push(fleet);
            Ok(names)
        }
        .boxed()
    }

    fn shutdown(&mut self) -> BoxFuture<'_, ()> {
        async move {
            for f in self.fleets.drain(..) {
                f.shutdown().await;
            }
        }
        .boxed()
    }
}

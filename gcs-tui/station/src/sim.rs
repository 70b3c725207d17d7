//! The simulator behind `spawn` and `--demo`: simulated agents from
//! `mech-agent`, plugged into the command language through its
//! [`SimSpawner`] trait, so the station's core and control crates never
//! depend on the simulator. Simulated robots live in the simulator's
//! arena: spawning them in a station without an arena gives it that one,
//! so they are kept inside it and apart (fleet safety).

use mech_control::lang::SimSpawner;
use mech_core::auth::{Identity, Role};
use mech_core::{ArenaShape, RouterHandle};
use mech_proto::auth::Key;

/// Simulated agents (`mech_agent::sim`) for `spawn` and `--demo`: the same
/// agent core as on a robot, with simulated platforms and UWB-like position
/// noise, over real loopback UDP. One fleet per run (its robots are named
/// `robot_1..robot_N`, so a second fleet would reuse the names).
#[derive(Debug)]
pub struct SimulatedFleet {
    pub arena: mech_agent::sim::Arena,
    pub options: mech_agent::sim::SimFleetOptions,
    fleet: Option<mech_agent::sim::SimFleet>,
}

impl SimulatedFleet {
    pub fn new(
        arena: mech_agent::sim::Arena,
        options: mech_agent::sim::SimFleetOptions,
    ) -> SimulatedFleet {
        SimulatedFleet {
            arena,
            options,
            fleet: None,
        }
    }
}

impl SimSpawner for SimulatedFleet {
    fn spawn(
        &mut self,
        count: usize,
        router: std::net::SocketAddr,
        station: RouterHandle,
    ) -> futures::future::BoxFuture<'_, Result<Vec<String>, String>> {
        Box::pin(async move {
            if let Some(f) = &self.fleet {
                return Err(format!(
                    "{} simulated agents are already running; spawn once per run",
                    f.names().len()
                ));
            }
            let mut options = self.options.clone();
            if station.authenticated() {
                // Each simulated robot gets a key of its own, known to this
                // station only, so it registers like a real robot.
                options.router_name = station.name().to_string();
                for i in 1..=count {
                    let name = format!("robot_{i}");
                    let secret: [u8; 32] = rand::random();
                    let key = Key::new(&secret);
                    station.add_key(Identity::new(Role::Robot, &name, key, Vec::new()));
                    options.secrets.insert(name, secret);
                }
            }
            if station.arena().is_none() {
                tracing::info!("no arena: the simulator's, where its robots live");
                station.set_arena(Some(shape(&self.arena))).await;
            }
            let fleet = mech_agent::sim::SimFleet::spawn(count, router, self.arena, options)
                .await
                .map_err(|e| e.to_string())?;
            let names = fleet.names();
            tracing::info!(count, %router, "simulated agents started");
            self.fleet = Some(fleet);
            Ok(names)
        })
    }

    fn shutdown(&mut self) -> futures::future::BoxFuture<'_, ()> {
        Box::pin(async move {
            if let Some(f) = self.fleet.take() {
                f.shutdown().await;
            }
        })
    }
}

/// The simulator `spawn` and `--demo` use: the default arena (the 2017
/// lab's 3.9 m x 2.8 m) with position noise.
pub fn simulator() -> Box<dyn SimSpawner> {
    Box::new(SimulatedFleet::new(
        mech_agent::sim::Arena::default(),
        mech_agent::sim::SimFleetOptions::default(),
    ))
}

/// The simulator's rectangle as an arena, with the default margin.
pub fn shape(a: &mech_agent::sim::Arena) -> ArenaShape {
    let p = |x, y| mech_proto::Point { x, y };
    ArenaShape {
        boundary: vec![
            p(a.min_x, a.min_y),
            p(a.max_x, a.min_y),
            p(a.max_x, a.max_y),
            p(a.min_x, a.max_y),
        ],
        keep_out: Vec::new(),
        slow_zones: Vec::new(),
        obstacles: Vec::new(),
        margin: mech_core::arena::DEFAULT_MARGIN,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_simulators_arena_is_the_demo_arena() {
        let demo = mech_core::ArenaConfig::demo().shape();
        assert_eq!(shape(&mech_agent::sim::Arena::default()), demo);
        let a = mech_agent::sim::Arena::default();
        let bounds = crate::demo_arena();
        assert_eq!(
            (bounds.min_x, bounds.min_y, bounds.max_x, bounds.max_y),
            (a.min_x, a.min_y, a.max_x, a.max_y)
        );
    }
}

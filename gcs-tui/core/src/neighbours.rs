//! Choosing each robot's neighbours: from the fleet's latest states, the
//! [`Neighbours`] message each robot is to receive, with the robots whose
//! discs lie within a horizon of its own, nearest first, at most a set
//! number, and the static obstacles. [`select`] is a pure function, so the
//! station's broadcaster ([`broadcast`], 10 Hz or more) only gathers
//! states and sends; the `[neighbours]` section ([`NeighbourConfig`]) says
//! how often and how far.
//!
//! Robots are bucketed in a grid of horizon-sized cells, so a fleet of
//! `n` robots costs about `n` times the robots near each, not `n²`.

pub mod broadcast;

use std::collections::HashMap;
use std::time::Duration;

use mech_proto::{MAX_NEIGHBOURS, Neighbour, Neighbours, Obstacle};
use serde::Deserialize;

use crate::config::ConfigError;

/// The `[neighbours]` section: how the station's broadcaster tells each
/// robot about the robots near it (`docs/safety.md`). It runs while the
/// station has an arena.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct NeighbourConfig {
    /// Neighbour lists per second to each robot: at least 10 (a robot whose
    /// newest list is older than its `stale_after`, 0.3 s by default,
    /// crawls); 20 leaves room for a lost datagram or two.
    pub rate_hz: f64,
    /// Largest gap between two robots' discs for them to be neighbours, m.
    pub horizon: f64,
    /// Most neighbours in one list, nearest first.
    pub max: usize,
    /// Radius of a robot that reports none (an agent without the layer,
    /// another station's robot), m.
    pub default_radius: f64,
    /// Deceleration assumed of a robot the station lost (its failsafe
    /// stops it), m/s²: its disc is grown by the way it could have gone.
    pub lost_deceleration: f64,
}

impl Default for NeighbourConfig {
    fn default() -> Self {
        NeighbourConfig {
            rate_hz: 20.0,
            horizon: NeighbourPolicy::default().horizon,
            max: NeighbourPolicy::default().max,
            default_radius: 0.3,
            lost_deceleration: 1.0,
        }
    }
}

impl NeighbourConfig {
    /// Checks every value.
    pub fn validate(&self) -> Result<(), ConfigError> {
        if !(self.rate_hz.is_finite() && (10.0..=200.0).contains(&self.rate_hz)) {
            return Err(ConfigError(format!(
                "neighbours.rate_hz {} must be 10 to 200: robots take lists older than 0.3 s as stale",
                self.rate_hz
            )));
        }
        for (name, v) in [
            ("horizon", self.horizon),
            ("default_radius", self.default_radius),
            ("lost_deceleration", self.lost_deceleration),
        ] {
            if !(v.is_finite() && v > 0.0 && v <= mech_proto::MAX_EXTENT) {
                return Err(ConfigError(format!(
                    "neighbours.{name} {v} must be a positive number"
                )));
            }
        }
        if self.max == 0 || self.max > MAX_NEIGHBOURS {
            return Err(ConfigError(format!(
                "neighbours.max {} must be 1 to {MAX_NEIGHBOURS}",
                self.max
            )));
        }
        Ok(())
    }

    /// Time between two lists to one robot.
    pub fn period(&self) -> Duration {
        Duration::from_secs_f64(1.0 / self.rate_hz)
    }

    /// Which robots count as neighbours.
    pub fn policy(&self) -> NeighbourPolicy {
        NeighbourPolicy {
            horizon: self.horizon,
            max: self.max,
        }
    }
}

/// A robot's state as the station last saw it.
#[derive(Debug, Clone, PartialEq)]
pub struct RobotState {
    pub name: String,
    /// The router's id for it ([`mech_proto::Welcome::robot_id`]).
    pub id: u16,
    /// Position, m, and velocity, m/s, map frame.
    pub position: [f64; 3],
    pub velocity: [f64; 3],
    /// Radius of its disc, m (its telemetry's safety report, or the
    /// station's default for a robot without one).
    pub radius: f64,
    /// How old the state is: time since its telemetry arrived.
    pub age: Duration,
    /// Whether its safety layer is on (it takes its share of avoidance).
    pub cooperative: bool,
}

/// Which robots count as neighbours.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct NeighbourPolicy {
    /// Largest gap between two robots' discs for them to be neighbours, m.
    pub horizon: f64,
    /// Most neighbours per robot (nearest first), at most
    /// [`MAX_NEIGHBOURS`].
    pub max: usize,
}

impl Default for NeighbourPolicy {
    /// 2 m: what two robots at 1 m/s close in a second, with room to
    /// brake; 32 robots.
    fn default() -> Self {
        NeighbourPolicy {
            horizon: 2.0,
            max: 32,
        }
    }
}

/// The message each robot of `fleet` is to receive now (station time
/// `stamp_us`), in fleet order.
pub fn select(
    fleet: &[RobotState],
    policy: &NeighbourPolicy,
    obstacles: &[Obstacle],
    stamp_us: u64,
) -> Vec<Neighbours> {
    let widest = fleet.iter().map(|r| r.radius).fold(0.0f64, f64::max);
    // Two robots whose discs are within the horizon have centres within
    // `reach`: one cell of that size around a robot's holds them all.
    let reach = (policy.horizon + 2.0 * widest).max(1e-3);
    let cell = |p: &[f64; 3]| ((p[0] / reach).floor() as i64, (p[1] / reach).floor() as i64);
    let mut grid: HashMap<(i64, i64), Vec<usize>> = HashMap::new();
    for (i, r) in fleet.iter().enumerate() {
        if r.position[0].is_finite() && r.position[1].is_finite() {
            grid.entry(cell(&r.position)).or_default().push(i);
        }
    }
    let max = policy.max.min(MAX_NEIGHBOURS);
    fleet
        .iter()
        .enumerate()
        .map(|(i, me)| {
            let mut near: Vec<(f64, usize)> = Vec::new();
            if me.position[0].is_finite() && me.position[1].is_finite() {
                let (cx, cy) = cell(&me.position);
                for dx in -1..=1 {
                    for dy in -1..=1 {
                        for &j in grid.get(&(cx + dx, cy + dy)).into_iter().flatten() {
                            if j == i {
                                continue;
                            }
                            let o = &fleet[j];
                            let centres = (o.position[0] - me.position[0])
                                .hypot(o.position[1] - me.position[1]);
                            let gap = centres - me.radius - o.radius;
                            if gap <= policy.horizon {
                                near.push((gap, j));
                            }
                        }
                    }
                }
            }
            near.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            near.truncate(max);
            Neighbours {
                robot: me.name.clone(),
                stamp_us,
                robots: near.iter().map(|&(_, j)| neighbour(&fleet[j])).collect(),
                obstacles: obstacles.to_vec(),
            }
        })
        .collect()
}

fn neighbour(r: &RobotState) -> Neighbour {
    Neighbour {
        id: r.id,
        x: r.position[0],
        y: r.position[1],
        z: r.position[2],
        vx: r.velocity[0],
        vy: r.velocity[1],
        vz: r.velocity[2],
        radius: r.radius,
        age_ms: r.age.as_millis().min(u128::from(u32::MAX)) as u32,
        cooperative: r.cooperative,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mech_proto::{Body, Disc};

    fn robot(i: u16, x: f64, y: f64) -> RobotState {
        RobotState {
            name: format!("robot_{i}"),
            id: i,
            position: [x, y, 0.0],
            velocity: [0.1, 0.0, 0.0],
            radius: 0.15,
            age: Duration::from_millis(40),
            cooperative: true,
        }
    }

    #[test]
    fn the_section_is_checked() {
        assert!(NeighbourConfig::default().validate().is_ok());
        let slow = NeighbourConfig {
            rate_hz: 5.0,
            ..NeighbourConfig::default()
        };
        assert!(slow.validate().unwrap_err().0.contains("rate_hz"));
        let none = NeighbourConfig {
            max: 0,
            ..NeighbourConfig::default()
        };
        assert!(none.validate().unwrap_err().0.contains("max"));
        assert_eq!(
            NeighbourConfig::default().period(),
            Duration::from_millis(50)
        );
    }

    #[test]
    fn neighbours_are_the_others_within_the_horizon_nearest_first() {
        let fleet = vec![
            robot(1, 0.0, 0.0),
            robot(2, 1.0, 0.0),
            robot(3, 0.5, 0.0),
            robot(4, 2.6, 0.0),
            robot(5, 10.0, 0.0),
        ];
        let policy = NeighbourPolicy {
            horizon: 2.0,
            max: 32,
        };
        let out = select(&fleet, &policy, &[], 99);
        assert_eq!(out.len(), 5);
        let ids = |n: &Neighbours| n.robots.iter().map(|r| r.id).collect::<Vec<_>>();
        assert_eq!(out[0].robot, "robot_1");
        // Gaps: 0.2, 0.7, 2.3 (beyond), 9.7 (beyond).
        assert_eq!(ids(&out[0]), vec![3, 2]);
        assert_eq!(
            ids(&out[3]),
            vec![2, 3],
            "robot 4 sees 2 (gap 1.3), 3 (1.8)"
        );
        assert!(ids(&out[4]).is_empty());
        assert_eq!(out[0].stamp_us, 99);
        assert_eq!(out[0].robots[0].age_ms, 40);
        for n in out {
            assert!(Body::Neighbours(n).validate().is_ok());
        }
    }

    #[test]
    fn the_count_is_capped_and_obstacles_go_to_everyone() {
        let fleet: Vec<RobotState> = (0..200)
            .map(|i| robot(i, (i % 20) as f64 * 0.4, (i / 20) as f64 * 0.4))
            .collect();
        let disc = Obstacle::Disc(Disc {
            x: 1.0,
            y: 1.0,
            radius: 0.2,
        });
        let policy = NeighbourPolicy {
            horizon: 100.0,
            max: 1000,
        };
        let out = select(&fleet, &policy, std::slice::from_ref(&disc), 1);
        assert!(out.iter().all(|n| n.robots.len() == MAX_NEIGHBOURS));
        assert!(out.iter().all(|n| n.obstacles == vec![disc.clone()]));
        // Nearest first, by the gap between discs.
        let me = &fleet[0];
        let gaps: Vec<f64> = out[0]
            .robots
            .iter()
            .map(|r| (r.x - me.position[0]).hypot(r.y - me.position[1]))
            .collect();
        assert!(gaps.windows(2).all(|w| w[0] <= w[1]));
    }

    /// The grid finds exactly what comparing every pair finds.
    #[test]
    fn the_grid_misses_no_one() {
        let mut seed = 7u64;
        let mut next = || {
            seed = seed
                .wrapping_mul(6364136223846793005)
                .wrapping_add(1442695040888963407);
            (seed >> 11) as f64 / (1u64 << 53) as f64
        };
        let fleet: Vec<RobotState> = (0..300)
            .map(|i| {
                let mut r = robot(i, next() * 30.0 - 15.0, next() * 30.0 - 15.0);
                r.radius = 0.05 + next() * 0.5;
                r
            })
            .collect();
        let policy = NeighbourPolicy {
            horizon: 1.5,
            max: MAX_NEIGHBOURS,
        };
        let out = select(&fleet, &policy, &[], 1);
        for (i, me) in fleet.iter().enumerate() {
            let mut want: Vec<u16> = fleet
                .iter()
                .enumerate()
                .filter(|(j, o)| {
                    *j != i
                        && (o.position[0] - me.position[0]).hypot(o.position[1] - me.position[1])
                            - me.radius
                            - o.radius
                            <= policy.horizon
                })
                .map(|(_, o)| o.id)
                .collect();
            let mut got: Vec<u16> = out[i].robots.iter().map(|r| r.id).collect();
            want.sort_unstable();
            got.sort_unstable();
            assert_eq!(got, want, "robot {i}");
        }
    }
}

//! Which member holds which slot of the formation: the slot offsets laid
//! out for the members present, the assignment that minimises the total
//! distance they travel, when it must be made again (the members present
//! or the formation changed), and where a slot is in the world at a
//! desired cluster pose.

use std::collections::BTreeMap;

use mech_proto::{ClusterPose, ClusterVelocity, Formation, FormationKind, Offset};

use crate::MemberState;
use crate::assignment::assign_slots;
use crate::formation::slot_offsets;
use crate::geometry::{norm, rotate};
use crate::tracking::Reference;

/// The slots of a cluster's formation and the member in each.
#[derive(Debug, Clone)]
pub(super) struct SlotAssignment {
    /// Members present at the last step, sorted: a change re-assigns.
    present: Vec<String>,
    /// Slot offsets in the cluster frame, for the members assigned.
    offsets: Vec<Offset>,
    /// Each assigned member's slot index.
    by_robot: BTreeMap<String, usize>,
    /// The assignment must be made again before it is used.
    stale: bool,
}

impl SlotAssignment {
    /// No slots yet: the first step with members assigns them.
    pub fn new() -> SlotAssignment {
        SlotAssignment {
            present: Vec::new(),
            offsets: Vec::new(),
            by_robot: BTreeMap::new(),
            stale: true,
        }
    }

    /// Asks for a new assignment (the formation or the members changed).
    pub fn invalidate(&mut self) {
        self.stale = true;
    }

    pub fn is_stale(&self) -> bool {
        self.stale
    }

    /// Asks for a new assignment when the set of present members changed.
    pub fn watch(&mut self, present: &[&MemberState]) {
        let names: Vec<String> = present.iter().map(|s| s.robot.clone()).collect();
        if names != self.present {
            self.present = names;
            self.stale = true;
        }
    }

    /// Lays out `formation`'s slots for `members` at `desired` and gives
    /// each member the slot that minimises the total distance.
    pub fn assign(
        &mut self,
        formation: &Formation,
        desired: &ClusterPose,
        members: &[&MemberState],
    ) {
        let offsets = match slot_offsets(formation, members.len()) {
            Ok(o) => o,
            // Only a custom formation with too few offsets can fail here, and
            // set_formation/set_members refuse that; fall back to a circle.
            Err(_) => match slot_offsets(
                &Formation {
                    kind: FormationKind::Circle,
                    spacing: 1.0,
                    offsets: vec![],
                },
                members.len(),
            ) {
                Ok(o) => o,
                Err(_) => return,
            },
        };
        let world: Vec<(f64, f64)> = offsets.iter().map(|o| slot_position(desired, o)).collect();
        let positions: Vec<(f64, f64)> = members.iter().map(|s| (s.pose.x, s.pose.y)).collect();
        let assignment = assign_slots(&positions, &world);
        self.by_robot = members
            .iter()
            .map(|s| s.robot.clone())
            .zip(assignment)
            .collect();
        self.offsets = offsets;
        self.stale = false;
    }

    /// The slot assigned to `robot`: its index and offset.
    pub fn slot_of(&self, robot: &str) -> Option<(usize, &Offset)> {
        let &slot = self.by_robot.get(robot)?;
        Some((slot, self.offsets.get(slot)?))
    }

    /// The largest slot offset from the centroid, m (before the scale).
    pub fn max_offset(&self) -> f64 {
        self.offsets
            .iter()
            .map(|o| norm(o.x, o.y))
            .fold(0.0, f64::max)
    }

    /// Largest distance between a commanded member and its slot at the
    /// desired pose, m.
    pub fn worst_lag(&self, desired: &ClusterPose, fresh: &[&MemberState]) -> f64 {
        fresh
            .iter()
            .filter_map(|s| {
                let (_, o) = self.slot_of(&s.robot)?;
                let (x, y) = slot_position(desired, o);
                Some(norm(x - s.pose.x, y - s.pose.y))
            })
            .fold(0.0, f64::max)
    }
}

/// Where the slot with offset `o` is in the world at the desired pose.
fn slot_position(desired: &ClusterPose, o: &Offset) -> (f64, f64) {
    let (x, y) = rotate(o.x, o.y, desired.heading);
    (desired.x + desired.scale * x, desired.y + desired.scale * y)
}

/// The slot with offset `o` as a tracking reference: its position, and its
/// velocity from the inverse cluster kinematics,
/// `v_slot = v_c + wz x r + scale_rate R o` with `r = scale R(heading) o`.
pub(super) fn slot_reference(desired: &ClusterPose, v: &ClusterVelocity, o: &Offset) -> Reference {
    let (vwx, vwy) = rotate(v.vx, v.vy, desired.heading);
    let (ox, oy) = rotate(o.x, o.y, desired.heading);
    let (rx, ry) = (desired.scale * ox, desired.scale * oy);
    Reference {
        x: desired.x + rx,
        y: desired.y + ry,
        heading: desired.heading,
        vx: vwx - v.wz * ry + v.scale_rate * ox,
        vy: vwy + v.wz * rx + v.scale_rate * oy,
        wz: v.wz,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::PlatformLimits;
    use mech_proto::{CommandKind, Pose, Velocity};

    fn member(robot: &str, x: f64, y: f64) -> MemberState {
        MemberState {
            robot: robot.into(),
            platform: PlatformLimits::new("kiwi", &[CommandKind::Twist], 1.0, 2.0),
            pose: Pose {
                x,
                y,
                ..Pose::default()
            },
            velocity: Velocity::default(),
            stamp: 0.0,
        }
    }

    const AT_ORIGIN: ClusterPose = ClusterPose {
        x: 0.0,
        y: 0.0,
        heading: 0.0,
        scale: 1.0,
    };

    #[test]
    fn members_take_the_nearest_slots_and_a_new_member_set_reassigns() {
        let column = Formation {
            kind: FormationKind::Column,
            spacing: 2.0,
            offsets: Vec::new(),
        };
        // The column runs back along x: slots at x = +1 and x = -1.
        let (front, back) = (member("a", 1.2, 0.0), member("b", -0.9, 0.0));
        let mut slots = SlotAssignment::new();
        assert!(slots.is_stale());
        slots.watch(&[&back, &front]);
        slots.assign(&column, &AT_ORIGIN, &[&back, &front]);
        assert!(!slots.is_stale());
        let x_of = |r: &str, s: &SlotAssignment| s.slot_of(r).map(|(_, o)| o.x);
        assert_eq!(x_of("a", &slots), Some(1.0));
        assert_eq!(x_of("b", &slots), Some(-1.0));
        assert_eq!(slots.max_offset(), 1.0);
        assert!((slots.worst_lag(&AT_ORIGIN, &[&front, &back]) - 0.2).abs() < 1e-9);
        slots.watch(&[&back, &front]);
        assert!(!slots.is_stale(), "the same members: kept");
        slots.watch(&[&front]);
        assert!(slots.is_stale(), "a member left: assigned again");
    }

    #[test]
    fn a_slot_reference_moves_with_the_cluster_turning_and_growing() {
        let o = Offset { x: 1.0, y: 0.0 };
        let v = ClusterVelocity {
            vx: 0.5,
            vy: 0.0,
            wz: 1.0,
            scale_rate: 0.1,
        };
        let r = slot_reference(&AT_ORIGIN, &v, &o);
        assert_eq!((r.x, r.y), (1.0, 0.0));
        // Translation, plus wz x r (r = (1, 0): +y), plus the growth along o.
        assert!(
            (r.vx - 0.6).abs() < 1e-12 && (r.vy - 1.0).abs() < 1e-12,
            "{r:?}"
        );
    }
}

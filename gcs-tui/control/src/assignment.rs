//! Slot assignment: which member takes which formation slot.
//!
//! The assignment minimises the total straight-line distance from members to
//! their slots, solved exactly for any number of members with the Hungarian
//! method (Kuhn-Munkres with potentials, O(n^3); 30 members take well under a
//! millisecond). Minimising the sum of Euclidean distances (not squared) has a
//! useful property in the plane: no two members' straight paths cross, because
//! two crossing segments can always be swapped for two shorter ones (triangle
//! inequality). So a formation change does not make members cross needlessly.

/// Slot index for each member: `result[m]` is the slot of `members[m]`.
/// `members` and `slots` are world positions and must have the same length
/// (the shorter length is used otherwise).
pub fn assign_slots(members: &[(f64, f64)], slots: &[(f64, f64)]) -> Vec<usize> {
    let n = members.len().min(slots.len());
    if n == 0 {
        return Vec::new();
    }
    let cost = |i: usize, j: usize| -> f64 {
        let d = (members[i].0 - slots[j].0).hypot(members[i].1 - slots[j].1);
        if d.is_finite() { d } else { 1e12 }
    };
    // Rows are members, columns slots; 1-based with a virtual column 0.
    let mut u = vec![0.0f64; n + 1];
    let mut v = vec![0.0f64; n + 1];
    let mut way = vec![0usize; n + 1];
    // slot_owner[j] = row assigned to column j (0 = none).
    let mut slot_owner = vec![0usize; n + 1];
    for i in 1..=n {
        slot_owner[0] = i;
        let mut j0 = 0usize;
        let mut minv = vec![f64::INFINITY; n + 1];
        let mut used = vec![false; n + 1];
        loop {
            used[j0] = true;
            let i0 = slot_owner[j0];
            let mut delta = f64::INFINITY;
            let mut j1 = 0usize;
            for j in 1..=n {
                if !used[j] {
                    let cur = cost(i0 - 1, j - 1) - u[i0] - v[j];
                    if cur < minv[j] {
                        minv[j] = cur;
                        way[j] = j0;
                    }
                    if minv[j] < delta {
                        delta = minv[j];
                        j1 = j;
                    }
                }
            }
            for j in 0..=n {
                if used[j] {
                    u[slot_owner[j]] += delta;
                    v[j] -= delta;
                } else {
                    minv[j] -= delta;
                }
            }
            j0 = j1;
            if slot_owner[j0] == 0 {
                break;
            }
        }
        loop {
            let j1 = way[j0];
            slot_owner[j0] = slot_owner[j1];
            j0 = j1;
            if j0 == 0 {
                break;
            }
        }
    }
    let mut result = vec![0usize; n];
    for j in 1..=n {
        if slot_owner[j] > 0 {
            result[slot_owner[j] - 1] = j - 1;
        }
    }
    result
}

/// Sum of member-to-slot distances of an assignment.
pub fn total_distance(members: &[(f64, f64)], slots: &[(f64, f64)], assignment: &[usize]) -> f64 {
    assignment
        .iter()
        .enumerate()
        .map(|(m, &s)| (members[m].0 - slots[s].0).hypot(members[m].1 - slots[s].1))
        .sum()
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn brute_force(members: &[(f64, f64)], slots: &[(f64, f64)]) -> f64 {
        fn permute(
            k: usize,
            perm: &mut Vec<usize>,
            best: &mut f64,
            m: &[(f64, f64)],
            s: &[(f64, f64)],
        ) {
            if k == perm.len() {
                *best = best.min(total_distance(m, s, perm));
                return;
            }
            for i in k..perm.len() {
                perm.swap(k, i);
                permute(k + 1, perm, best, m, s);
                perm.swap(k, i);
            }
        }
        let mut perm: Vec<usize> = (0..members.len()).collect();
        let mut best = f64::INFINITY;
        permute(0, &mut perm, &mut best, members, slots);
        best
    }

    fn segments_cross(a: (f64, f64), b: (f64, f64), c: (f64, f64), d: (f64, f64)) -> bool {
        let orient = |p: (f64, f64), q: (f64, f64), r: (f64, f64)| {
            (q.0 - p.0) * (r.1 - p.1) - (q.1 - p.1) * (r.0 - p.0)
        };
        let (o1, o2, o3, o4) = (
            orient(a, b, c),
            orient(a, b, d),
            orient(c, d, a),
            orient(c, d, b),
        );
        o1 * o2 < -1e-9 && o3 * o4 < -1e-9
    }

    fn points(n: usize) -> impl Strategy<Value = Vec<(f64, f64)>> {
        prop::collection::vec((-5.0f64..5.0, -5.0f64..5.0), n)
    }

    proptest! {
        #[test]
        fn hungarian_matches_brute_force(
            (m, s) in (1usize..7).prop_flat_map(|n| (points(n), points(n)))
        ) {
            let a = assign_slots(&m, &s);
            let mut seen = a.clone();
            seen.sort_unstable();
            prop_assert_eq!(seen, (0..m.len()).collect::<Vec<_>>());
            let best = brute_force(&m, &s);
            prop_assert!((total_distance(&m, &s, &a) - best).abs() < 1e-6);
        }

        #[test]
        fn optimal_paths_never_cross(
            (m, s) in (2usize..10).prop_flat_map(|n| (points(n), points(n)))
        ) {
            let a = assign_slots(&m, &s);
            for i in 0..m.len() {
                for j in i + 1..m.len() {
                    prop_assert!(!segments_cross(m[i], s[a[i]], m[j], s[a[j]]));
                }
            }
        }
    }

    #[test]
    fn swapped_members_keep_their_nearest_slots() {
        let members = [(0.0, 1.0), (0.0, -1.0), (5.0, 0.0)];
        let slots = [(5.0, 0.2), (0.0, -1.2), (0.0, 1.2)];
        assert_eq!(assign_slots(&members, &slots), vec![2, 1, 0]);
    }
}

//! Formation shapes: the slot offsets of `n` members in the cluster frame
//! (x forward, y left), centred on the cluster pose.
//!
//! Following Kitts & Mas (2009) the cluster pose is the members' centroid, so
//! every shape, custom ones included, is shifted to have its centroid at the
//! origin. `spacing` is the distance between neighbouring slots: side by side
//! for a line, nose to tail for a column, along each arm for a wedge (arms 45
//! degrees behind the apex), and the chord between neighbours for a circle.

use std::f64::consts::{FRAC_1_SQRT_2, PI};

use mech_proto::{Formation, FormationKind, Offset};
use thiserror::Error;

/// Why a formation cannot be laid out.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum FormationError {
    #[error("formation spacing {0} is not a positive finite distance")]
    Spacing(f64),
    #[error("custom formation has {offsets} offsets for {members} members")]
    TooFewOffsets { offsets: usize, members: usize },
    #[error("custom formation offset {0} is not finite")]
    Offset(usize),
}

/// Slot offsets for `n` members, centroid at the origin, before the cluster's
/// scale is applied. A custom formation with more offsets than members uses
/// the first `n`.
pub fn slot_offsets(formation: &Formation, n: usize) -> Result<Vec<Offset>, FormationError> {
    let s = formation.spacing;
    if formation.kind != FormationKind::Custom && !(s.is_finite() && s > 0.0) {
        return Err(FormationError::Spacing(s));
    }
    let mut slots: Vec<Offset> = match formation.kind {
        FormationKind::Line => (0..n)
            .map(|i| Offset {
                x: 0.0,
                y: -(i as f64) * s,
            })
            .collect(),
        FormationKind::Column => (0..n)
            .map(|i| Offset {
                x: -(i as f64) * s,
                y: 0.0,
            })
            .collect(),
        FormationKind::Wedge => (0..n)
            .map(|i| {
                let arm = i.div_ceil(2) as f64 * s * FRAC_1_SQRT_2;
                let side = if i % 2 == 1 { 1.0 } else { -1.0 };
                Offset {
                    x: -arm,
                    y: side * arm,
                }
            })
            .collect(),
        FormationKind::Circle => {
            let radius = if n < 2 {
                0.0
            } else {
                s / (2.0 * (PI / n as f64).sin())
            };
            (0..n)
                .map(|i| {
                    let a = 2.0 * PI * i as f64 / n as f64;
                    Offset {
                        x: radius * a.cos(),
                        y: radius * a.sin(),
                    }
                })
                .collect()
        }
        FormationKind::Custom => {
            if formation.offsets.len() < n {
                return Err(FormationError::TooFewOffsets {
                    offsets: formation.offsets.len(),
                    members: n,
                });
            }
            for (i, o) in formation.offsets.iter().enumerate().take(n) {
                if !(o.x.is_finite() && o.y.is_finite()) {
                    return Err(FormationError::Offset(i));
                }
            }
            formation.offsets[..n].to_vec()
        }
    };
    if n > 0 {
        let cx = slots.iter().map(|o| o.x).sum::<f64>() / n as f64;
        let cy = slots.iter().map(|o| o.y).sum::<f64>() / n as f64;
        for o in &mut slots {
            o.x -= cx;
            o.y -= cy;
        }
    }
    Ok(slots)
}

#[cfg(test)]
#[allow(clippy::unwrap_used)]
mod tests {
    use super::*;

    fn formation(kind: FormationKind, spacing: f64) -> Formation {
        Formation {
            kind,
            spacing,
            offsets: vec![],
        }
    }

    fn dist(a: &Offset, b: &Offset) -> f64 {
        (a.x - b.x).hypot(a.y - b.y)
    }

    #[test]
    fn every_shape_is_centred() {
        for kind in [
            FormationKind::Line,
            FormationKind::Column,
            FormationKind::Wedge,
            FormationKind::Circle,
        ] {
            for n in 1..9 {
                let slots = slot_offsets(&formation(kind, 1.3), n).unwrap();
                assert_eq!(slots.len(), n);
                let cx: f64 = slots.iter().map(|o| o.x).sum();
                let cy: f64 = slots.iter().map(|o| o.y).sum();
                assert!(cx.abs() < 1e-9 && cy.abs() < 1e-9, "{kind:?} n={n}");
            }
        }
    }

    #[test]
    fn neighbours_are_spacing_apart() {
        let line = slot_offsets(&formation(FormationKind::Line, 0.8), 4).unwrap();
        assert!(
            line.windows(2)
                .all(|w| (dist(&w[0], &w[1]) - 0.8).abs() < 1e-9)
        );
        assert!(line.iter().all(|o| o.x.abs() < 1e-12), "line is abreast");
        let column = slot_offsets(&formation(FormationKind::Column, 0.8), 4).unwrap();
        assert!(
            column.iter().all(|o| o.y.abs() < 1e-12),
            "column is nose to tail"
        );
        let circle = slot_offsets(&formation(FormationKind::Circle, 0.8), 5).unwrap();
        for i in 0..5 {
            assert!((dist(&circle[i], &circle[(i + 1) % 5]) - 0.8).abs() < 1e-9);
        }
        let wedge = slot_offsets(&formation(FormationKind::Wedge, 0.8), 5).unwrap();
        assert!((dist(&wedge[0], &wedge[1]) - 0.8).abs() < 1e-9);
        assert!((dist(&wedge[1], &wedge[3]) - 0.8).abs() < 1e-9);
        assert!(wedge[0].x > wedge[1].x && wedge[1].y > 0.0 && wedge[2].y < 0.0);
    }

    #[test]
    fn custom_offsets_are_centred_and_checked() {
        let f = Formation {
            kind: FormationKind::Custom,
            spacing: 0.0,
            offsets: vec![Offset { x: 2.0, y: 0.0 }, Offset { x: 0.0, y: 0.0 }],
        };
        let slots = slot_offsets(&f, 2).unwrap();
        assert_eq!(
            slots,
            vec![Offset { x: 1.0, y: 0.0 }, Offset { x: -1.0, y: 0.0 }]
        );
        assert_eq!(
            slot_offsets(&f, 3),
            Err(FormationError::TooFewOffsets {
                offsets: 2,
                members: 3
            })
        );
        assert_eq!(
            slot_offsets(&formation(FormationKind::Line, -1.0), 3),
            Err(FormationError::Spacing(-1.0))
        );
    }
}

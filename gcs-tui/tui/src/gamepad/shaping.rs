//! Stick shaping: deadzone (so a worn stick resting off-centre commands
//! nothing) and expo (fine control near centre, full range at the edge).

/// Deadzone and expo applied to every analogue axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shaping {
    /// Fraction of travel around centre that reads as zero, `[0, 1)`.
    pub deadzone: f64,
    /// Blend between linear (0) and cubic (1) response.
    pub expo: f64,
}

impl Default for Shaping {
    fn default() -> Self {
        Self {
            deadzone: 0.1,
            expo: 0.3,
        }
    }
}

impl Shaping {
    /// Shapes a raw axis value in `[-1, 1]`. Inside the deadzone the result
    /// is exactly zero; outside, the remaining travel is rescaled to `[0, 1]`
    /// so the output is continuous at the deadzone edge and still reaches 1.
    pub fn apply(&self, raw: f64) -> f64 {
        if !raw.is_finite() {
            return 0.0;
        }
        let v = raw.clamp(-1.0, 1.0);
        let dz = self.deadzone.clamp(0.0, 0.99);
        let mag = v.abs();
        if mag <= dz {
            return 0.0;
        }
        let scaled = (mag - dz) / (1.0 - dz);
        let e = self.expo.clamp(0.0, 1.0);
        let shaped = (1.0 - e) * scaled + e * scaled.powi(3);
        shaped.copysign(v)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn inside_deadzone_is_zero() {
        let s = Shaping {
            deadzone: 0.15,
            expo: 0.0,
        };
        assert_eq!(s.apply(0.1), 0.0);
        assert_eq!(s.apply(-0.15), 0.0);
        assert!(s.apply(0.2) > 0.0);
    }

    #[test]
    fn full_deflection_reaches_one_and_sign_is_kept() {
        let s = Shaping {
            deadzone: 0.2,
            expo: 0.5,
        };
        assert!((s.apply(1.0) - 1.0).abs() < 1e-12);
        assert!((s.apply(-1.0) + 1.0).abs() < 1e-12);
        assert!((s.apply(1.7) - 1.0).abs() < 1e-12, "clamped");
    }

    #[test]
    fn rescaled_linear_outside_deadzone() {
        let s = Shaping {
            deadzone: 0.2,
            expo: 0.0,
        };
        assert!((s.apply(0.6) - 0.5).abs() < 1e-12);
    }

    #[test]
    fn expo_softens_centre() {
        let lin = Shaping {
            deadzone: 0.0,
            expo: 0.0,
        };
        let expo = Shaping {
            deadzone: 0.0,
            expo: 1.0,
        };
        assert!((expo.apply(0.5) - 0.125).abs() < 1e-12);
        assert!(expo.apply(0.5) < lin.apply(0.5));
    }

    #[test]
    fn nan_is_zero() {
        assert_eq!(Shaping::default().apply(f64::NAN), 0.0);
    }
}

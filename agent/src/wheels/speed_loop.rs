//! Closed-loop wheel speed: one PI controller per wheel, on top of the open
//! loop output as a feed-forward, so that an output of `u` means a rim speed
//! of `u * max_wheel_speed` whatever the battery voltage or the load.
//!
//! - The feed-forward is the open loop output itself: with a full battery
//!   the integrator has almost nothing to add, so the loop is quick.
//! - Anti-windup by conditional integration: the integrator does not grow
//!   while the output is saturated in the direction the error pushes, so a
//!   wheel held back (a weak battery at full output, a stall) does not leave
//!   a charge that overshoots once it is free.
//! - A zero command is a zero output and an empty integrator: a stopped
//!   robot holds no torque and never creeps on measurement noise; and the
//!   output never reverses against the command (an H-bridge reversing to
//!   brake on noise would chatter).

use serde::Deserialize;

/// Gains of the wheel speed loop. The error is the speed shortfall as a
/// fraction of `max_wheel_speed`, so gains do not depend on the robot's
/// size.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PiGains {
    /// Output per unit of error.
    pub kp: f64,
    /// Output per unit of error per second.
    pub ki: f64,
}

impl Default for PiGains {
    /// Settles a wheel with a 50 ms motor lag to within 5% in well under a
    /// second at half battery (`wheels::speed_loop` tests and the
    /// simulator's battery test).
    fn default() -> Self {
        PiGains { kp: 0.6, ki: 6.0 }
    }
}

/// One wheel's PI state.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct SpeedLoop {
    integral: f64,
}

impl SpeedLoop {
    /// The output for this period: `feedforward` is the open loop output,
    /// `error` the speed shortfall (fraction of full speed), `dt` seconds
    /// since the previous period.
    pub fn update(&mut self, feedforward: f64, error: f64, dt: f64, gains: &PiGains) -> f64 {
        if feedforward == 0.0 || !error.is_finite() {
            self.integral = 0.0;
            return 0.0;
        }
        let p = gains.kp * error;
        let grown = self.integral + gains.ki * error * dt.max(0.0);
        let unclamped = feedforward + p + grown;
        let saturated = unclamped.abs() > 1.0 && unclamped.signum() == error.signum();
        if !saturated {
            self.integral = grown.clamp(-1.0, 1.0);
        }
        let u = (feedforward + p + self.integral).clamp(-1.0, 1.0);
        // Never reverse against the command.
        if feedforward > 0.0 {
            u.max(0.0)
        } else {
            u.min(0.0)
        }
    }

    pub fn reset(&mut self) {
        self.integral = 0.0;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A wheel reaching `gain * u` of full speed through a first-order lag
    /// of 50 ms (the simulator's motor), stepped at 50 Hz; returns the
    /// speeds (fraction of full) after each period.
    fn drive(gain: f64, command: f64, periods: usize) -> (Vec<f64>, Vec<f64>) {
        let (dt, tau): (f64, f64) = (0.02, 0.05);
        let mut pi = SpeedLoop::default();
        let mut speed: f64 = 0.0;
        let (mut speeds, mut outputs) = (vec![], vec![]);
        for _ in 0..periods {
            let u = pi.update(command, command - speed, dt, &PiGains::default());
            speed += (gain * u - speed) * (1.0 - (-dt / tau).exp());
            speeds.push(speed);
            outputs.push(u);
        }
        (speeds, outputs)
    }

    #[test]
    fn reaches_the_commanded_speed_on_a_weak_battery() {
        for gain in [1.0, 0.5] {
            let (speeds, _) = drive(gain, 0.4, 50);
            let last = *speeds.last().unwrap();
            assert!((last - 0.4).abs() < 0.4 * 0.05, "gain {gain}: {last}");
        }
    }

    #[test]
    fn integrator_does_not_wind_up_while_saturated() {
        // Half battery, full speed asked: the wheel can only make 0.5.
        let mut pi = SpeedLoop::default();
        for _ in 0..500 {
            assert_eq!(pi.update(1.0, 0.5, 0.02, &PiGains::default()), 1.0);
        }
        // The moment the error turns (a lower command), the output follows
        // at once instead of unwinding ten seconds of integral.
        let u = pi.update(0.3, -0.2, 0.02, &PiGains::default());
        assert!(u < 0.5, "{u}");
    }

    #[test]
    fn zero_command_is_zero_output_and_no_reversal() {
        let mut pi = SpeedLoop::default();
        pi.update(0.5, 0.3, 0.02, &PiGains::default());
        assert_eq!(pi.update(0.0, -0.2, 0.02, &PiGains::default()), 0.0);
        // Faster than asked (downhill): the output drops to zero, never
        // reverses.
        let u = pi.update(0.1, -0.9, 0.02, &PiGains::default());
        assert_eq!(u, 0.0);
    }
}

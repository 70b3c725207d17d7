//! L298 dual H-bridge, one [`L298Channel`] per motor: two direction inputs
//! (IN1/IN2) and a PWM enable (ENA).
//!
//! As in the 2017 L298Driver/MotorController, a non-zero output maps to a
//! duty cycle between `min_duty` (below which the motor stalls and only
//! heats) and `max_duty`; outputs inside the `deadband` stop the motor
//! (enable off, both inputs low: the motor coasts). Direction changes
//! disable the bridge first so the motor never sees both polarities at once.

use serde::Deserialize;

use crate::hal::{self, ErrorKind, ErrorType, HalError, Motor, OutputPin, PwmPin};

/// Duty-cycle shaping of one channel.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct DutyRange {
    /// Smallest duty that turns the motor (the 2017 driver's minDC = 20%).
    pub min_duty: f64,
    /// Largest duty used (the 2017 driver's maxDC = 100%).
    pub max_duty: f64,
    /// Outputs with magnitude below this stop the motor.
    pub deadband: f64,
}

impl Default for DutyRange {
    fn default() -> Self {
        DutyRange {
            min_duty: 0.2,
            max_duty: 1.0,
            deadband: 0.02,
        }
    }
}

impl DutyRange {
    /// Duty cycle for an output magnitude in `[0, 1]`.
    pub fn duty(&self, magnitude: f64) -> f64 {
        if magnitude < self.deadband {
            0.0
        } else {
            (self.min_duty + magnitude.min(1.0) * (self.max_duty - self.min_duty)).clamp(0.0, 1.0)
        }
    }
}

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Direction {
    Stopped,
    Forward,
    Reverse,
}

/// One motor on an L298.
#[derive(Debug)]
pub struct L298Channel<A, B, E> {
    in1: A,
    in2: B,
    enable: E,
    range: DutyRange,
    direction: Option<Direction>,
}

impl<A: OutputPin, B: OutputPin, E: PwmPin> L298Channel<A, B, E> {
    /// A channel from its pins; the motor is left stopped.
    pub fn new(in1: A, in2: B, enable: E, range: DutyRange) -> Result<Self, HalError> {
        let mut ch = L298Channel {
            in1,
            in2,
            enable,
            range,
            direction: None,
        };
        ch.set_output(0.0)?;
        Ok(ch)
    }

    pub fn pins(&self) -> (&A, &B, &E) {
        (&self.in1, &self.in2, &self.enable)
    }
}

fn fault<T: hal::Error>(what: &str) -> impl Fn(T) -> HalError + '_ {
    move |e| HalError::new(e.kind(), format!("L298 {what}: {e:?}"))
}

impl<A, B, E> ErrorType for L298Channel<A, B, E> {
    type Error = HalError;
}

impl<A: OutputPin, B: OutputPin, E: PwmPin> Motor for L298Channel<A, B, E> {
    fn set_output(&mut self, output: f64) -> Result<(), HalError> {
        if !output.is_finite() {
            return Err(HalError::new(
                ErrorKind::InvalidInput,
                "non-finite motor output",
            ));
        }
        let u = output.clamp(-1.0, 1.0);
        let duty = self.range.duty(u.abs());
        let direction = if duty == 0.0 {
            Direction::Stopped
        } else if u > 0.0 {
            Direction::Forward
        } else {
            Direction::Reverse
        };
        if self.direction != Some(direction) {
            self.enable.set_duty_cycle(0.0).map_err(fault("enable"))?;
            let (a, b) = match direction {
                Direction::Stopped => (false, false),
                Direction::Forward => (true, false),
                Direction::Reverse => (false, true),
            };
            self.in1.set_state(a).map_err(fault("IN1"))?;
            self.in2.set_state(b).map_err(fault("IN2"))?;
            self.direction = Some(direction);
        }
        if direction != Direction::Stopped {
            self.enable.set_duty_cycle(duty).map_err(fault("enable"))?;
        }
        Ok(())
    }
}

/// Pin numbers of one channel, as in the config (`[[actuators.channels]]`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct L298Pins {
    /// BCM GPIO number of IN1 (IN3 for the second channel).
    pub in1: u8,
    /// BCM GPIO number of IN2 (IN4).
    pub in2: u8,
    /// BCM GPIO number of ENA (ENB), driven with PWM.
    pub enable: u8,
}

#[cfg(test)]
pub(crate) mod fake {
    //! Pins that record every write into one shared log.
    use std::cell::RefCell;
    use std::rc::Rc;

    use crate::hal::{ErrorType, HalError, OutputPin, PwmPin};

    pub type Log = Rc<RefCell<Vec<(&'static str, f64)>>>;

    #[derive(Debug)]
    pub struct Pin(pub &'static str, pub Log);

    impl ErrorType for Pin {
        type Error = HalError;
    }
    impl OutputPin for Pin {
        fn set_state(&mut self, high: bool) -> Result<(), HalError> {
            self.1
                .borrow_mut()
                .push((self.0, if high { 1.0 } else { 0.0 }));
            Ok(())
        }
    }
    impl PwmPin for Pin {
        fn set_duty_cycle(&mut self, duty: f64) -> Result<(), HalError> {
            self.1.borrow_mut().push((self.0, duty));
            Ok(())
        }
    }
}

#[cfg(test)]
mod tests {
    use super::fake::{Log, Pin};
    use super::*;
    use crate::hal::{Actuators, MotorSet};
    use crate::platform::PlatformSpec;
    use mech_proto::{SteeringThrottle, Twist};

    fn drive(log: &Log) -> MotorSet<L298Channel<Pin, Pin, Pin>> {
        let ch = |a, b, e| {
            L298Channel::new(
                Pin(a, log.clone()),
                Pin(b, log.clone()),
                Pin(e, log.clone()),
                DutyRange::default(),
            )
            .unwrap()
        };
        MotorSet::new(vec![
            ch("L.in1", "L.in2", "L.en"),
            ch("R.in3", "R.in4", "R.en"),
        ])
    }

    /// The writes since the last call, duties rounded to 1e-9.
    fn take(log: &Log) -> Vec<(&'static str, f64)> {
        let writes = std::mem::take(&mut *log.borrow_mut());
        writes
            .into_iter()
            .map(|(pin, v)| (pin, (v * 1e9).round() / 1e9))
            .collect()
    }

    #[test]
    fn pin_sequence_forward_back_turn_stop() {
        let log = Log::default();
        let mut m = drive(&log);
        let init = take(&log);
        assert_eq!(
            init,
            vec![
                ("L.en", 0.0),
                ("L.in1", 0.0),
                ("L.in2", 0.0),
                ("R.en", 0.0),
                ("R.in3", 0.0),
                ("R.in4", 0.0)
            ],
            "starts stopped"
        );
        let dd = PlatformSpec::diff_drive().build();

        // Forward at full speed: IN1 high, IN2 low, full duty.
        m.set_outputs(&dd.mix(&Twist {
            vx: 0.5,
            ..Twist::default()
        }))
        .unwrap();
        assert_eq!(
            take(&log),
            vec![
                ("L.en", 0.0),
                ("L.in1", 1.0),
                ("L.in2", 0.0),
                ("L.en", 1.0),
                ("R.en", 0.0),
                ("R.in3", 1.0),
                ("R.in4", 0.0),
                ("R.en", 1.0),
            ]
        );
        // Same direction, half output: only the duty changes (20% + 0.5 * 80%).
        m.set_outputs(&[0.5, 0.5]).unwrap();
        assert_eq!(take(&log), vec![("L.en", 0.6), ("R.en", 0.6)]);

        // Back: bridge disabled, inputs swapped, duty restored.
        m.set_outputs(&[-0.5, -0.5]).unwrap();
        assert_eq!(
            take(&log),
            vec![
                ("L.en", 0.0),
                ("L.in1", 0.0),
                ("L.in2", 1.0),
                ("L.en", 0.6),
                ("R.en", 0.0),
                ("R.in3", 0.0),
                ("R.in4", 1.0),
                ("R.en", 0.6),
            ]
        );

        // Turn left on the spot: left wheel back, right wheel forward.
        let turn = dd.steering_throttle(&SteeringThrottle {
            steering: 1.0,
            throttle: 0.0,
        });
        assert_eq!(turn, vec![-1.0, 1.0]);
        m.set_outputs(&turn).unwrap();
        assert_eq!(
            take(&log),
            vec![
                ("L.en", 1.0),
                ("R.en", 0.0),
                ("R.in3", 1.0),
                ("R.in4", 0.0),
                ("R.en", 1.0)
            ]
        );

        // Stop: enable off, both inputs low.
        m.set_outputs(&[0.0, 0.0]).unwrap();
        assert_eq!(
            take(&log),
            vec![
                ("L.en", 0.0),
                ("L.in1", 0.0),
                ("L.in2", 0.0),
                ("R.en", 0.0),
                ("R.in3", 0.0),
                ("R.in4", 0.0)
            ]
        );
    }

    #[test]
    fn deadband_and_minimum_duty() {
        let r = DutyRange::default();
        assert_eq!(r.duty(0.01), 0.0);
        assert!((r.duty(0.02) - 0.216).abs() < 1e-12);
        assert_eq!(r.duty(1.0), 1.0);
        let log = Log::default();
        let mut m = drive(&log);
        take(&log);
        m.set_outputs(&[0.01, -0.01]).unwrap();
        assert!(take(&log).is_empty(), "already stopped: nothing to write");
        assert!(
            m.set_outputs(&[f64::NAN, 0.0]).is_ok(),
            "MotorSet clamps NaN to a stop"
        );
    }
}

//! Hardware abstraction: one trait per capability a robot's hardware offers,
//! in the style of `embedded-hal`. Every method is fallible and every error
//! has a coarse [`ErrorKind`], so the agent can count and report driver
//! faults without knowing the driver.
//!
//! - [`Motor`]: one actuator output in `[-1, 1]`; [`Actuators`]: a robot's
//!   whole set of outputs, in motor order.
//! - [`OutputPin`] and [`PwmPin`]: what an H-bridge needs.
//! - [`PositionSource`]: pose + timestamp + quality.
//! - [`Encoder`]: one wheel's edge count with the time of its newest edge;
//!   [`WheelEncoders`]: every wheel's, in motor order.
//! - [`DatagramLink`]: a message-per-datagram link (UDP). A byte-stream link
//!   (a serial port) is plain [`std::io::Read`] + [`std::io::Write`], framed by
//!   [`crate::drivers::serial_link::SerialLink`].

use std::fmt::Debug;
use std::time::Duration;

use mech_proto::Pose;

/// Coarse class of a hardware error, used as a counter key and in
/// `Notice{code: DriverFault}` texts.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum ErrorKind {
    /// The device is absent or was unplugged.
    NotConnected,
    /// The device did not answer in time.
    Timeout,
    /// The device answered something that does not follow its protocol.
    Protocol,
    /// The value asked for is outside what the device accepts.
    InvalidInput,
    /// An operating-system I/O error.
    Io,
    /// Anything else.
    Other,
}

/// A driver error that can say what class of failure it is.
pub trait Error: Debug {
    fn kind(&self) -> ErrorKind;
}

impl Error for std::io::Error {
    fn kind(&self) -> ErrorKind {
        match std::io::Error::kind(self) {
            std::io::ErrorKind::TimedOut | std::io::ErrorKind::WouldBlock => ErrorKind::Timeout,
            std::io::ErrorKind::NotFound
            | std::io::ErrorKind::NotConnected
            | std::io::ErrorKind::BrokenPipe
            | std::io::ErrorKind::ConnectionReset
            | std::io::ErrorKind::UnexpectedEof => ErrorKind::NotConnected,
            std::io::ErrorKind::InvalidInput | std::io::ErrorKind::InvalidData => {
                ErrorKind::InvalidInput
            }
            _ => ErrorKind::Io,
        }
    }
}

/// The error type shared by a driver's methods.
pub trait ErrorType {
    type Error: Error;
}

/// A generic hardware error for drivers that have nothing more specific.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("{kind:?}: {message}")]
pub struct HalError {
    pub kind: ErrorKind,
    pub message: String,
}

impl HalError {
    pub fn new(kind: ErrorKind, message: impl Into<String>) -> HalError {
        HalError {
            kind,
            message: message.into(),
        }
    }
}

impl Error for HalError {
    fn kind(&self) -> ErrorKind {
        self.kind
    }
}

/// One actuator: a motor through its driver, an ESC, or a velocity channel
/// of a flight controller.
pub trait Motor: ErrorType {
    /// Sets the output, a fraction of full forward (`1`) or reverse (`-1`).
    /// Values outside `[-1, 1]` are clamped by the caller
    /// ([`clamp_output`]); drivers may reject them.
    fn set_output(&mut self, output: f64) -> Result<(), Self::Error>;

    /// Stops the actuator (output zero).
    fn stop(&mut self) -> Result<(), Self::Error> {
        self.set_output(0.0)
    }
}

/// Every actuator of a robot, in the platform's motor order. This is what the
/// agent drives each control period.
pub trait Actuators {
    /// Writes all outputs (one per motor, each in `[-1, 1]`).
    fn set_outputs(&mut self, outputs: &[f64]) -> Result<(), HalError>;

    /// Zeroes every output.
    fn stop_all(&mut self, motors: usize) -> Result<(), HalError> {
        self.set_outputs(&vec![0.0; motors])
    }
}

/// Drives a list of [`Motor`]s as one robot's [`Actuators`].
#[derive(Debug)]
pub struct MotorSet<M> {
    motors: Vec<M>,
}

impl<M: Motor> MotorSet<M> {
    pub fn new(motors: Vec<M>) -> MotorSet<M> {
        MotorSet { motors }
    }

    pub fn motors(&self) -> &[M] {
        &self.motors
    }
}

impl<M: Motor> Actuators for MotorSet<M> {
    fn set_outputs(&mut self, outputs: &[f64]) -> Result<(), HalError> {
        if outputs.len() != self.motors.len() {
            return Err(HalError::new(
                ErrorKind::InvalidInput,
                format!("{} outputs for {} motors", outputs.len(), self.motors.len()),
            ));
        }
        // Every motor is written even if one fails, so a single bad channel
        // never leaves the others running on stale outputs.
        let mut first_error = None;
        for (motor, &u) in self.motors.iter_mut().zip(outputs) {
            if let Err(e) = motor.set_output(clamp_output(u)) {
                first_error.get_or_insert(HalError::new(e.kind(), format!("{e:?}")));
            }
        }
        first_error.map_or(Ok(()), Err)
    }
}

/// Actuators that go nowhere: a simulated robot's (its motion comes from the
/// simulator) or a robot with no drive configured.
#[derive(Debug, Default, Clone)]
pub struct NoActuators {
    /// Last outputs written, for inspection.
    pub last: Vec<f64>,
}

impl Actuators for NoActuators {
    fn set_outputs(&mut self, outputs: &[f64]) -> Result<(), HalError> {
        self.last.clear();
        self.last.extend_from_slice(outputs);
        Ok(())
    }
}

/// Clamps an actuator output to `[-1, 1]`, mapping NaN to zero so a bad
/// computation can never reach a motor as full power.
pub fn clamp_output(u: f64) -> f64 {
    if u.is_nan() { 0.0 } else { u.clamp(-1.0, 1.0) }
}

/// A digital output pin (an H-bridge direction input, an enable line).
pub trait OutputPin: ErrorType {
    /// Drives the pin high (`true`) or low (`false`).
    fn set_state(&mut self, high: bool) -> Result<(), Self::Error>;

    fn set_high(&mut self) -> Result<(), Self::Error> {
        self.set_state(true)
    }

    fn set_low(&mut self) -> Result<(), Self::Error> {
        self.set_state(false)
    }
}

/// A PWM output (an H-bridge enable input).
pub trait PwmPin: ErrorType {
    /// Sets the duty cycle, a fraction in `[0, 1]`.
    fn set_duty_cycle(&mut self, duty: f64) -> Result<(), Self::Error>;

    fn set_off(&mut self) -> Result<(), Self::Error> {
        self.set_duty_cycle(0.0)
    }
}

/// One position measurement.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PositionSample {
    /// Position (m) and heading (rad, CCW from +x) in the arena frame.
    pub pose: Pose,
    /// Agent clock time of the measurement.
    pub stamp: Duration,
    /// Confidence in `[0, 1]` (1 = the source's best).
    pub quality: f64,
    /// Whether `pose.heading` was measured; GPS positions without a compass
    /// leave it unmeasured and the estimator keeps its previous heading.
    pub has_heading: bool,
}

/// Something that measures where the robot is (UWB tag, GPS, motion capture
/// relayed by the GCS, the simulator).
pub trait PositionSource: ErrorType {
    /// Takes the next measurement. Blocking sources (serial devices) block
    /// for at most one measurement period; `Ok(None)` means no new fix yet.
    fn read(&mut self, now: Duration) -> Result<Option<PositionSample>, Self::Error>;
}

/// How an encoder's edges are counted, which decides who knows the
/// direction of rotation.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, serde::Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Counting {
    /// Two channels 90 degrees apart (A and B): every edge of either is
    /// counted, up or down, so the count is signed (forward positive).
    Quadrature,
    /// One channel: every edge of it is counted, always up. The direction is
    /// not measured; the agent takes it from the output it commanded (the
    /// 2017 robots' optical encoders were of this kind).
    SingleChannel,
}

/// One wheel's encoder reading.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct EdgeCount {
    /// Edges counted since the encoder was opened: signed (forward
    /// positive) for [`Counting::Quadrature`], never decreasing for
    /// [`Counting::SingleChannel`]. Wrapping is the reader's concern only
    /// after 2^63 edges.
    pub edges: i64,
    /// Agent clock time of the newest edge (`None` before the first). Speed
    /// is edges over the time between edges, not over the control period, so
    /// a wheel giving one edge every few periods is still measured smoothly.
    pub last_edge: Option<Duration>,
}

/// One wheel's rotation sensor: an optical or magnetic encoder whose edges
/// are counted (by GPIO interrupts on a Pi, by a counter chip, by the
/// simulator).
pub trait Encoder: ErrorType {
    /// The count now. Never blocks: edges are counted as they happen.
    fn read(&mut self, now: Duration) -> Result<EdgeCount, Self::Error>;
}

/// Every wheel encoder of a robot, in the platform's motor order: what the
/// agent reads each control period.
pub trait WheelEncoders {
    /// One reading per wheel.
    fn read_all(&mut self, now: Duration) -> Result<Vec<EdgeCount>, HalError>;
}

/// Reads a list of [`Encoder`]s as one robot's [`WheelEncoders`].
#[derive(Debug)]
pub struct EncoderSet<E> {
    encoders: Vec<E>,
}

impl<E: Encoder> EncoderSet<E> {
    pub fn new(encoders: Vec<E>) -> EncoderSet<E> {
        EncoderSet { encoders }
    }
}

impl<E: Encoder> WheelEncoders for EncoderSet<E> {
    fn read_all(&mut self, now: Duration) -> Result<Vec<EdgeCount>, HalError> {
        self.encoders
            .iter_mut()
            .enumerate()
            .map(|(i, e)| {
                e.read(now)
                    .map_err(|err| HalError::new(err.kind(), format!("encoder {}: {err:?}", i + 1)))
            })
            .collect()
    }
}

/// A datagram link: one message per datagram (UDP to the router).
pub trait DatagramLink: ErrorType {
    /// Sends one whole message.
    fn send(&mut self, datagram: &[u8]) -> Result<(), Self::Error>;

    /// Receives one whole message into `buf`, returning its length, or
    /// `Ok(None)` when nothing is waiting.
    fn try_recv(&mut self, buf: &mut [u8]) -> Result<Option<usize>, Self::Error>;
}

#[cfg(test)]
mod tests {
    use super::*;

    #[derive(Debug)]
    struct Recorder {
        out: Vec<f64>,
        fail: bool,
    }
    impl ErrorType for Recorder {
        type Error = HalError;
    }
    impl Motor for Recorder {
        fn set_output(&mut self, u: f64) -> Result<(), HalError> {
            self.out.push(u);
            if self.fail {
                Err(HalError::new(ErrorKind::NotConnected, "unplugged"))
            } else {
                Ok(())
            }
        }
    }

    #[test]
    fn motor_set_writes_every_motor_even_after_a_fault() {
        let mut set = MotorSet::new(vec![
            Recorder {
                out: vec![],
                fail: true,
            },
            Recorder {
                out: vec![],
                fail: false,
            },
        ]);
        let err = set.set_outputs(&[2.0, f64::NAN]).unwrap_err();
        assert_eq!(err.kind, ErrorKind::NotConnected);
        assert_eq!(set.motors()[0].out, vec![1.0]);
        assert_eq!(set.motors()[1].out, vec![0.0]);
        assert!(set.set_outputs(&[0.0]).is_err());
    }
}

//! Raspberry Pi GPIO through rppal: digital outputs and software PWM for
//! the L298 driver, and wheel encoder inputs counted by interrupt
//! ([`encoders`]). Pin numbers are BCM GPIO numbers (the 2017 config used
//! physical board pins: board 38/37 = BCM 20/26, 31/32 = BCM 6/12, 33/35 =
//! BCM 13/19).

pub mod encoders;

use rppal::gpio::Gpio;

use crate::drivers::l298::{DutyRange, L298Channel, L298Pins};
use crate::hal::{self, ErrorKind, ErrorType, HalError, MotorSet, OutputPin, PwmPin};

/// An rppal error with its kind.
#[derive(Debug, thiserror::Error)]
#[error(transparent)]
pub struct RpiError(#[from] rppal::gpio::Error);

impl hal::Error for RpiError {
    fn kind(&self) -> ErrorKind {
        match &self.0 {
            rppal::gpio::Error::PinNotAvailable(_) | rppal::gpio::Error::PinUsed(_) => {
                ErrorKind::InvalidInput
            }
            rppal::gpio::Error::UnknownModel | rppal::gpio::Error::PermissionDenied(_) => {
                ErrorKind::NotConnected
            }
            rppal::gpio::Error::Io(_) => ErrorKind::Io,
            _ => ErrorKind::Other,
        }
    }
}

/// A GPIO output.
#[derive(Debug)]
pub struct RpiPin(pub rppal::gpio::OutputPin);

impl ErrorType for RpiPin {
    type Error = RpiError;
}

impl OutputPin for RpiPin {
    fn set_state(&mut self, high: bool) -> Result<(), RpiError> {
        if high {
            self.0.set_high();
        } else {
            self.0.set_low();
        }
        Ok(())
    }
}

/// Software PWM on any GPIO output (enough for an L298 at 100 Hz-1 kHz).
#[derive(Debug)]
pub struct RpiSoftPwm {
    pin: rppal::gpio::OutputPin,
    frequency: f64,
}

impl ErrorType for RpiSoftPwm {
    type Error = RpiError;
}

impl PwmPin for RpiSoftPwm {
    fn set_duty_cycle(&mut self, duty: f64) -> Result<(), RpiError> {
        if duty <= 0.0 {
            self.pin.clear_pwm()?;
            self.pin.set_low();
            Ok(())
        } else {
            Ok(self.pin.set_pwm_frequency(self.frequency, duty.min(1.0))?)
        }
    }
}

/// The robot's L298 channels on this Pi, in motor order.
pub type RpiL298 = MotorSet<L298Channel<RpiPin, RpiPin, RpiSoftPwm>>;

/// Opens the GPIO pins of every channel. Fails off a Pi (rppal cannot
/// identify the board) or when a pin is taken.
pub fn open_l298(
    channels: &[L298Pins],
    range: DutyRange,
    pwm_frequency: f64,
) -> Result<RpiL298, HalError> {
    let gpio = Gpio::new().map_err(|e| to_hal(RpiError(e)))?;
    let output = |pin: u8| -> Result<rppal::gpio::OutputPin, HalError> {
        Ok(gpio
            .get(pin)
            .map_err(|e| to_hal(RpiError(e)))?
            .into_output_low())
    };
    let mut motors = Vec::with_capacity(channels.len());
    for ch in channels {
        let enable = RpiSoftPwm {
            pin: output(ch.enable)?,
            frequency: pwm_frequency,
        };
        motors.push(L298Channel::new(
            RpiPin(output(ch.in1)?),
            RpiPin(output(ch.in2)?),
            enable,
            range,
        )?);
    }
    Ok(MotorSet::new(motors))
}

fn to_hal(e: RpiError) -> HalError {
    HalError::new(hal::Error::kind(&e), e.to_string())
}

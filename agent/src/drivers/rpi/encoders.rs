//! Wheel encoders on Raspberry Pi GPIO: every edge of every channel raises
//! an interrupt (rppal's asynchronous interrupts, one thread per pin); the
//! callback feeds the wheel's [`EdgeCounter`], stamped with the agent's
//! clock. The agent reads the counts each control period without blocking.
//!
//! Compiled under the `rpi` feature on any machine; it only runs on a Pi
//! (`Gpio::new` fails elsewhere).

use std::sync::{Arc, Mutex, PoisonError};
use std::time::{Duration, Instant};

use rppal::gpio::{Event, Gpio, InputPin, Trigger};

use super::{RpiError, to_hal};
use crate::drivers::edge_counter::{Channel, EdgeCounter, EncoderPins};
use crate::hal::{Counting, EdgeCount, Encoder, EncoderSet, ErrorKind, ErrorType, HalError};

/// One wheel's encoder: its input pins (kept open: dropping one ends its
/// interrupts) and the count its interrupts keep.
#[derive(Debug)]
pub struct RpiEncoder {
    counter: Arc<Mutex<EdgeCounter>>,
    _pins: Vec<InputPin>,
}

impl ErrorType for RpiEncoder {
    type Error = HalError;
}

impl Encoder for RpiEncoder {
    fn read(&mut self, _now: Duration) -> Result<EdgeCount, HalError> {
        self.counter
            .lock()
            .map(|c| c.count())
            .map_err(|e: PoisonError<_>| HalError::new(ErrorKind::Other, e.to_string()))
    }
}

/// The robot's wheel encoders on this Pi, in motor order.
pub type RpiEncoders = EncoderSet<RpiEncoder>;

/// Opens every wheel's pins as inputs (with the pull-up on when `pull_up`,
/// for open-collector optical sensors) and starts counting. `origin` is
/// agent time zero, so edge times are on the agent's clock. Fails off a Pi
/// or when a pin is taken.
pub fn open_encoders(
    wheels: &[EncoderPins],
    counting: Counting,
    pull_up: bool,
    origin: Instant,
) -> Result<RpiEncoders, HalError> {
    let gpio = Gpio::new().map_err(|e| to_hal(RpiError(e)))?;
    let input = |pin: u8| -> Result<InputPin, HalError> {
        let pin = gpio.get(pin).map_err(|e| to_hal(RpiError(e)))?;
        Ok(if pull_up {
            pin.into_input_pullup()
        } else {
            pin.into_input()
        })
    };
    let mut encoders = Vec::with_capacity(wheels.len());
    for w in wheels {
        let mut a = input(w.a)?;
        let mut b = match (counting, w.b) {
            (Counting::Quadrature, Some(b)) => Some(input(b)?),
            (Counting::Quadrature, None) => {
                return Err(HalError::new(
                    ErrorKind::InvalidInput,
                    format!("quadrature encoder on GPIO {} has no channel B", w.a),
                ));
            }
            (Counting::SingleChannel, _) => None,
        };
        let counter = Arc::new(Mutex::new(EdgeCounter::new(
            counting,
            a.is_high(),
            b.as_ref().is_some_and(InputPin::is_high),
        )));
        watch(&mut a, Channel::A, &counter, origin)?;
        let mut pins = vec![a];
        if let Some(mut b) = b.take() {
            watch(&mut b, Channel::B, &counter, origin)?;
            pins.push(b);
        }
        encoders.push(RpiEncoder {
            counter,
            _pins: pins,
        });
    }
    Ok(EncoderSet::new(encoders))
}

/// Feeds `pin`'s edges, both ways, into `counter`.
fn watch(
    pin: &mut InputPin,
    channel: Channel,
    counter: &Arc<Mutex<EdgeCounter>>,
    origin: Instant,
) -> Result<(), HalError> {
    let counter = Arc::clone(counter);
    pin.set_async_interrupt(Trigger::Both, None, move |event: Event| {
        let level = event.trigger == Trigger::RisingEdge;
        // A poisoned lock means another callback panicked; the count is
        // still the best there is.
        let mut c = counter.lock().unwrap_or_else(PoisonError::into_inner);
        c.edge(channel, level, origin.elapsed());
    })
    .map_err(|e| to_hal(RpiError(e)))
}

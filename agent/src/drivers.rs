//! Drivers: implementations of the [`crate::hal`] traits for real hardware,
//! each tested through fakes of the traits or byte streams it sits on.
//!
//! - [`l298`]: L298 dual H-bridge (direction pins + PWM duty with a minimum
//!   duty dead-band), over any [`crate::hal::OutputPin`]/[`crate::hal::PwmPin`];
//!   `rpi` provides those pins on a Raspberry Pi (feature `rpi`).
//! - [`udp`]: the default link to the router.
//! - [`serial_link`]: serial radios (XBee transparent mode or any UART) with
//!   the protocol's COBS + CRC framing.
//! - [`pozyx`]: Pozyx UWB tag over its serial text protocol.
//! - [`nmea_gps`]: NMEA GPS receivers, converted to a local metric frame
//!   (feature `serial`).
//! - [`edge_counter`]: a wheel encoder's count from its pin changes
//!   (quadrature or single-channel); `rpi` feeds it from GPIO interrupts.
//!
//! Positions sent by the GCS (`PositionFix`, the "external" source) need no
//! driver: the agent core takes them when configured to.

pub mod edge_counter;
pub mod l298;
#[cfg(feature = "serial")]
pub mod nmea_gps;
pub mod pozyx;
#[cfg(feature = "rpi")]
pub mod rpi;
pub mod serial_link;
pub mod udp;

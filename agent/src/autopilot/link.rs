//! The MAVLink link to the autopilot: a [`MavlinkPort`] the vehicle
//! polls, and the real one over the `mavlink` crate (UDP, TCP, serial),
//! whose blocking receive runs on its own thread.

use std::sync::Arc;
use std::sync::mpsc::{Receiver, TryRecvError};

use mavlink::dialects::common::MavMessage;
use mavlink::{MavConnection, MavHeader, MavlinkVersion};

use crate::hal::{ErrorKind, HalError};

/// A message-at-a-time link to an autopilot.
pub trait MavlinkPort: Send {
    /// Sends one message with `header` (its sequence number is the link's).
    fn send(&mut self, header: &MavHeader, msg: &MavMessage) -> Result<(), HalError>;
    /// The next message received, if any (never blocks).
    fn try_recv(&mut self) -> Option<Result<(MavHeader, MavMessage), HalError>>;
}

/// A MAVLink 2 connection opened from an address (`udpin:0.0.0.0:14540`,
/// `serial:/dev/ttyACM0:921600`...). Receiving runs on a thread; messages
/// and errors wait in a channel for [`MavlinkPort::try_recv`].
pub struct MavlinkLink {
    connection: Arc<mavlink::Connection<MavMessage>>,
    incoming: Receiver<Result<(MavHeader, MavMessage), HalError>>,
}

impl std::fmt::Debug for MavlinkLink {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("MavlinkLink").finish_non_exhaustive()
    }
}

impl MavlinkLink {
    /// Opens the link and starts its receiving thread.
    pub fn open(address: &str) -> Result<MavlinkLink, HalError> {
        let mut connection = mavlink::connect::<MavMessage>(address)
            .map_err(|e| HalError::new(crate::hal::Error::kind(&e), format!("{address}: {e}")))?;
        connection.set_protocol_version(MavlinkVersion::V2);
        // Autopilots answer in the version they were spoken to, but some
        // radios and older firmware send MAVLink 1 first.
        connection.set_allow_recv_any_version(true);
        let connection = Arc::new(connection);
        let (tx, incoming) = std::sync::mpsc::channel();
        let reader = connection.clone();
        std::thread::Builder::new()
            .name("mavlink-rx".into())
            .spawn(move || {
                loop {
                    let got = reader.recv().map_err(|e| {
                        HalError::new(ErrorKind::Protocol, format!("MAVLink receive: {e}"))
                    });
                    let failed = got.is_err();
                    if tx.send(got).is_err() {
                        break; // the vehicle is gone
                    }
                    if failed {
                        // Do not spin on a dead device.
                        std::thread::sleep(std::time::Duration::from_millis(200));
                    }
                }
            })
            .map_err(|e| HalError::new(ErrorKind::Io, format!("MAVLink thread: {e}")))?;
        Ok(MavlinkLink {
            connection,
            incoming,
        })
    }
}

impl MavlinkPort for MavlinkLink {
    fn send(&mut self, header: &MavHeader, msg: &MavMessage) -> Result<(), HalError> {
        self.connection
            .send(header, msg)
            .map(|_| ())
            .map_err(|e| HalError::new(ErrorKind::Io, format!("MAVLink send: {e}")))
    }

    fn try_recv(&mut self) -> Option<Result<(MavHeader, MavMessage), HalError>> {
        match self.incoming.try_recv() {
            Ok(item) => Some(item),
            Err(TryRecvError::Empty) => None,
            Err(TryRecvError::Disconnected) => Some(Err(HalError::new(
                ErrorKind::NotConnected,
                "the MAVLink receive thread ended",
            ))),
        }
    }
}

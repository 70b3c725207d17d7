//! Pozyx UWB tag over its serial/USB text protocol.
//!
//! The tag answers ASCII commands terminated by `\r`:
//! - `R,<reg hex>,<n>` reads `n` bytes from a register: reply `D,<hex bytes>`.
//! - `F,<reg hex>,<param hex>,<n>` calls a register function: reply
//!   `D,<status byte><result bytes>` (status 1 = success).
//!
//! Each measurement triggers positioning (`DO_POSITIONING`, 0xB6), waits
//! for the position interrupt flag (`INT_STATUS` 0x05, bit `POS`), then reads
//! x, y, z (0x30, three little-endian i32 in mm) and the Euler heading (0x66,
//! little-endian i16, 1/16 degree, clockwise as a compass). Anchors are
//! configured once with the Pozyx tools, as in the 2017 PozyxPositioner.

use std::io::{Read, Write};
use std::time::Duration;

use mech_proto::Pose;

use crate::hal::{self, ErrorKind, ErrorType, PositionSample, PositionSource};
use mech_proto::wrap_angle;

const REG_INT_STATUS: u8 = 0x05;
const REG_POS_X: u8 = 0x30;
const REG_EUL_HEADING: u8 = 0x66;
const FN_DO_POSITIONING: u8 = 0xB6;
const INT_STATUS_ERR: u8 = 0x01;
const INT_STATUS_POS: u8 = 0x02;

/// Why a Pozyx measurement failed.
#[derive(Debug, thiserror::Error)]
pub enum PozyxError {
    #[error("serial I/O: {0}")]
    Io(#[from] std::io::Error),
    #[error("unexpected reply {0:?}")]
    Reply(String),
    #[error("function 0x{function:02x} failed with status {status}")]
    Status { function: u8, status: u8 },
    #[error("the tag reported a positioning error")]
    Positioning,
    #[error("no position after {0} polls")]
    Timeout(u32),
}

impl hal::Error for PozyxError {
    fn kind(&self) -> ErrorKind {
        match self {
            PozyxError::Io(e) => hal::Error::kind(e),
            PozyxError::Reply(_) | PozyxError::Status { .. } => ErrorKind::Protocol,
            PozyxError::Positioning => ErrorKind::Other,
            PozyxError::Timeout(_) => ErrorKind::Timeout,
        }
    }
}

/// Mounting and frame of the tag.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PozyxSettings {
    /// Added to the (counter-clockwise) heading so that 0 = arena +x.
    pub heading_offset: f64,
    /// Interrupt-status polls before giving up on one measurement.
    pub max_polls: u32,
}

impl Default for PozyxSettings {
    fn default() -> Self {
        PozyxSettings {
            heading_offset: 0.0,
            max_polls: 50,
        }
    }
}

/// A Pozyx tag on a byte stream.
#[derive(Debug)]
pub struct Pozyx<S> {
    stream: S,
    settings: PozyxSettings,
    line: Vec<u8>,
}

impl<S: Read + Write> Pozyx<S> {
    pub fn new(stream: S, settings: PozyxSettings) -> Pozyx<S> {
        Pozyx {
            stream,
            settings,
            line: Vec::with_capacity(64),
        }
    }

    /// Sends one command, returns the bytes of its `D,` reply.
    fn exchange(&mut self, command: &str) -> Result<Vec<u8>, PozyxError> {
        self.stream.write_all(command.as_bytes())?;
        self.stream.flush()?;
        self.line.clear();
        let mut byte = [0u8; 1];
        loop {
            match self.stream.read(&mut byte)? {
                0 => return Err(PozyxError::Io(std::io::ErrorKind::UnexpectedEof.into())),
                _ if byte[0] == b'\n' => break,
                _ if self.line.len() > 256 => {
                    return Err(PozyxError::Reply(
                        String::from_utf8_lossy(&self.line).into_owned(),
                    ));
                }
                _ => self.line.push(byte[0]),
            }
        }
        let text = String::from_utf8_lossy(&self.line).trim().to_string();
        let hex = text
            .strip_prefix("D,")
            .ok_or_else(|| PozyxError::Reply(text.clone()))?;
        decode_hex(hex).ok_or(PozyxError::Reply(text))
    }

    /// Reads `len` bytes from register `reg`.
    pub fn read_register(&mut self, reg: u8, len: usize) -> Result<Vec<u8>, PozyxError> {
        let data = self.exchange(&format!("R,{reg:02x},{len}\r"))?;
        if data.len() != len {
            return Err(PozyxError::Reply(format!(
                "{} bytes from register 0x{reg:02x}, wanted {len}",
                data.len()
            )));
        }
        Ok(data)
    }

    /// Calls register function `function`; returns its result bytes.
    pub fn call(
        &mut self,
        function: u8,
        params: &[u8],
        result_len: usize,
    ) -> Result<Vec<u8>, PozyxError> {
        let hex: String = params.iter().map(|b| format!("{b:02x}")).collect();
        let data = self.exchange(&format!("F,{function:02x},{hex},{}\r", result_len + 1))?;
        match data.split_first() {
            Some((1, rest)) => Ok(rest.to_vec()),
            Some((&status, _)) => Err(PozyxError::Status { function, status }),
            None => Err(PozyxError::Reply(format!(
                "empty reply to function 0x{function:02x}"
            ))),
        }
    }

    /// One positioning cycle.
    pub fn measure(&mut self, now: Duration) -> Result<PositionSample, PozyxError> {
        self.call(FN_DO_POSITIONING, &[], 0)?;
        let mut polls = 0;
        loop {
            let status = self.read_register(REG_INT_STATUS, 1)?[0];
            if status & INT_STATUS_ERR != 0 {
                return Err(PozyxError::Positioning);
            }
            if status & INT_STATUS_POS != 0 {
                break;
            }
            polls += 1;
            if polls >= self.settings.max_polls {
                return Err(PozyxError::Timeout(polls));
            }
        }
        let p = self.read_register(REG_POS_X, 12)?;
        let mm =
            |i: usize| f64::from(i32::from_le_bytes([p[i], p[i + 1], p[i + 2], p[i + 3]])) / 1000.0;
        let h = self.read_register(REG_EUL_HEADING, 2)?;
        let compass_deg = f64::from(i16::from_le_bytes([h[0], h[1]])) / 16.0;
        Ok(PositionSample {
            pose: Pose {
                x: mm(0),
                y: mm(4),
                z: mm(8),
                heading: wrap_angle(self.settings.heading_offset - compass_deg.to_radians()),
            },
            stamp: now,
            quality: 1.0,
            has_heading: true,
        })
    }
}

impl<S> ErrorType for Pozyx<S> {
    type Error = PozyxError;
}

impl<S: Read + Write> PositionSource for Pozyx<S> {
    fn read(&mut self, now: Duration) -> Result<Option<PositionSample>, PozyxError> {
        self.measure(now).map(Some)
    }
}

fn decode_hex(hex: &str) -> Option<Vec<u8>> {
    let hex = hex.trim();
    if !hex.len().is_multiple_of(2) {
        return None;
    }
    (0..hex.len())
        .step_by(2)
        .map(|i| u8::from_str_radix(hex.get(i..i + 2)?, 16).ok())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::VecDeque;

    /// A tag that answers each `\r`-terminated command with the next
    /// recorded reply.
    #[derive(Debug, Default)]
    struct FakeTag {
        replies: VecDeque<&'static str>,
        commands: Vec<String>,
        pending: Vec<u8>,
        readable: VecDeque<u8>,
    }

    impl Write for FakeTag {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            for &b in buf {
                if b == b'\r' {
                    self.commands
                        .push(String::from_utf8_lossy(&self.pending).into_owned());
                    self.pending.clear();
                    let reply = self.replies.pop_front().unwrap_or("");
                    self.readable.extend(reply.bytes());
                } else {
                    self.pending.push(b);
                }
            }
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    impl Read for FakeTag {
        fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
            let n = buf.len().min(self.readable.len());
            for (slot, b) in buf.iter_mut().zip(self.readable.drain(..n)) {
                *slot = b;
            }
            Ok(n)
        }
    }

    #[test]
    fn reads_position_and_heading_from_recorded_replies() {
        let tag = FakeTag {
            replies: [
                "D,01\r\n", // DO_POSITIONING ok
                "D,00\r\n", // not ready yet
                "D,02\r\n", // POS flag
                // x = 1234 mm, y = -500 mm, z = 0
                "D,d20400000cfeffff00000000\r\n",
                "D,a005\r\n", // 0x05a0 = 1440 = 90 degrees
            ]
            .into(),
            ..FakeTag::default()
        };
        let mut p = Pozyx::new(tag, PozyxSettings::default());
        let s = p.read(Duration::from_millis(7)).unwrap().unwrap();
        assert_eq!(s.pose.x, 1.234);
        assert_eq!(s.pose.y, -0.5);
        assert!(
            (s.pose.heading + std::f64::consts::FRAC_PI_2).abs() < 1e-12,
            "compass east = -90 deg CCW"
        );
        assert_eq!(s.stamp, Duration::from_millis(7));
        assert_eq!(
            p.stream.commands,
            vec!["F,b6,,1", "R,05,1", "R,05,1", "R,30,12", "R,66,2"]
        );
    }

    #[test]
    fn protocol_errors_are_typed() {
        let mut p = Pozyx::new(
            FakeTag {
                replies: ["D,00\r\n"].into(),
                ..FakeTag::default()
            },
            PozyxSettings::default(),
        );
        let e = p.read(Duration::ZERO).unwrap_err();
        assert!(matches!(
            e,
            PozyxError::Status {
                function: 0xb6,
                status: 0
            }
        ));
        assert_eq!(hal::Error::kind(&e), ErrorKind::Protocol);
        let mut p = Pozyx::new(
            FakeTag {
                replies: ["D,01\r\n", "D,01\r\n"].into(),
                ..FakeTag::default()
            },
            PozyxSettings::default(),
        );
        assert!(matches!(
            p.read(Duration::ZERO),
            Err(PozyxError::Positioning)
        ));
        let mut p = Pozyx::new(
            FakeTag {
                replies: ["garbage\r\n"].into(),
                ..FakeTag::default()
            },
            PozyxSettings::default(),
        );
        assert!(matches!(p.read(Duration::ZERO), Err(PozyxError::Reply(_))));
        let mut p = Pozyx::new(FakeTag::default(), PozyxSettings::default());
        assert_eq!(
            hal::Error::kind(&p.read(Duration::ZERO).unwrap_err()),
            ErrorKind::NotConnected
        );
    }
}

//! NMEA 0183 GPS receiver on a serial line, parsed here ([`sentence`]: the
//! two sentences it needs, checksum first) and converted to a local metric frame (ENU: x east, y north, z up) around
//! a configured origin with the equirectangular approximation, which is
//! accurate to millimetres over a few kilometres.
//!
//! `GGA` gives the position, fix type and HDOP; `HDT` (a dual-antenna or
//! compass heading), when present, gives the heading.

use std::io::BufRead;
use std::time::Duration;

use mech_proto::Pose;

use crate::hal::{self, ErrorKind, ErrorType, PositionSample, PositionSource};
use mech_proto::wrap_angle;
use sentence::Sentence;

mod sentence;

/// Mean Earth radius (IUGG), m.
const EARTH_RADIUS: f64 = 6_371_008.8;

/// The geodetic point that becomes (0, 0, 0) of the arena frame.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GeoOrigin {
    /// Degrees north.
    pub latitude: f64,
    /// Degrees east.
    pub longitude: f64,
    /// Metres above mean sea level.
    pub altitude: f64,
}

impl GeoOrigin {
    /// Local ENU coordinates of a geodetic point.
    pub fn to_local(&self, latitude: f64, longitude: f64, altitude: f64) -> (f64, f64, f64) {
        let lat0 = self.latitude.to_radians();
        let east = EARTH_RADIUS * (longitude - self.longitude).to_radians() * lat0.cos();
        let north = EARTH_RADIUS * (latitude - self.latitude).to_radians();
        (east, north, altitude - self.altitude)
    }
}

#[derive(Debug, thiserror::Error)]
pub enum GpsError {
    #[error("serial I/O: {0}")]
    Io(#[from] std::io::Error),
    #[error("GPS serial line closed")]
    Closed,
}

impl hal::Error for GpsError {
    fn kind(&self) -> ErrorKind {
        match self {
            GpsError::Io(e) => hal::Error::kind(e),
            GpsError::Closed => ErrorKind::NotConnected,
        }
    }
}

/// A GPS receiver on a line-oriented byte stream.
#[derive(Debug)]
pub struct NmeaGps<R> {
    reader: R,
    origin: GeoOrigin,
    line: String,
    /// Last `HDT` heading (rad, CCW from east).
    heading: Option<f64>,
    /// Sentences that did not parse (bad checksum, unsupported type).
    pub skipped: u64,
}

impl<R: BufRead> NmeaGps<R> {
    pub fn new(reader: R, origin: GeoOrigin) -> NmeaGps<R> {
        NmeaGps {
            reader,
            origin,
            line: String::new(),
            heading: None,
            skipped: 0,
        }
    }

    /// Handles one sentence; returns a sample for a valid `GGA` fix.
    pub fn parse_line(&mut self, line: &str, now: Duration) -> Option<PositionSample> {
        match sentence::parse(line.trim()) {
            Ok(Sentence::Gga(gga)) => {
                let fix = gga.fix?;
                let (x, y, z) = self.origin.to_local(
                    fix.latitude,
                    fix.longitude,
                    gga.altitude.unwrap_or(self.origin.altitude),
                );
                let hdop = gga.hdop.unwrap_or(5.0);
                Some(PositionSample {
                    pose: Pose {
                        x,
                        y,
                        z,
                        heading: self.heading.unwrap_or(0.0),
                    },
                    stamp: now,
                    quality: (1.0 / hdop.max(1.0)).clamp(0.0, 1.0),
                    has_heading: self.heading.is_some(),
                })
            }
            Ok(Sentence::Hdt(heading)) => {
                // True heading is clockwise from north; ENU is CCW from east.
                self.heading =
                    heading.map(|h| wrap_angle(std::f64::consts::FRAC_PI_2 - h.to_radians()));
                None
            }
            Ok(Sentence::Other) => None,
            Err(_) => {
                self.skipped += 1;
                None
            }
        }
    }
}

impl<R> ErrorType for NmeaGps<R> {
    type Error = GpsError;
}

impl<R: BufRead> PositionSource for NmeaGps<R> {
    /// Reads sentences until a fix (or the port's read timeout).
    fn read(&mut self, now: Duration) -> Result<Option<PositionSample>, GpsError> {
        loop {
            self.line.clear();
            match self.reader.read_line(&mut self.line) {
                Ok(0) => return Err(GpsError::Closed),
                Ok(_) => {
                    let line = std::mem::take(&mut self.line);
                    let sample = self.parse_line(&line, now);
                    self.line = line;
                    if sample.is_some() {
                        return Ok(sample);
                    }
                }
                Err(e) if e.kind() == std::io::ErrorKind::TimedOut => return Ok(None),
                Err(e) => return Err(e.into()),
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Appends the NMEA checksum.
    fn sentence(body: &str) -> String {
        let sum = body.bytes().fold(0u8, |a, b| a ^ b);
        format!("${body}*{sum:02X}\r\n")
    }

    #[test]
    fn gga_becomes_local_metres_and_hdt_the_heading() {
        let origin = GeoOrigin {
            latitude: 48.0,
            longitude: 11.0,
            altitude: 500.0,
        };
        // 0.001' of latitude north and east of the origin.
        let stream = [
            sentence("GPGGA,123519,4800.000,N,01100.000,E,1,08,0.9,500.0,M,46.9,M,,"),
            "$GPGGA,garbage*00\r\n".to_string(),
            sentence("GPHDT,90.0,T"),
            sentence("GPGGA,123520,4800.060,N,01100.090,E,1,08,2.0,501.0,M,46.9,M,,"),
            sentence("GPGGA,123521,4800.060,N,01100.090,E,0,00,,,M,,M,,"),
        ]
        .concat();
        let mut gps = NmeaGps::new(std::io::Cursor::new(stream.into_bytes()), origin);
        let a = gps.read(Duration::ZERO).unwrap().unwrap();
        assert!(a.pose.x.abs() < 1e-6 && a.pose.y.abs() < 1e-6 && a.pose.z.abs() < 1e-6);
        assert!(!a.has_heading);
        let b = gps.read(Duration::ZERO).unwrap().unwrap();
        assert_eq!(gps.skipped, 1);
        // 0.06' = 0.001 degree north = 111.2 m; 0.09' = 0.0015 degree east
        // at 48 degrees = 111.2 * 1.5 * cos 48 = 111.6 m.
        assert!((b.pose.y - 111.195).abs() < 0.01, "{:?}", b.pose);
        assert!((b.pose.x - 111.604).abs() < 0.01, "{:?}", b.pose);
        assert!((b.pose.z - 1.0).abs() < 1e-6);
        assert!(
            b.has_heading && b.pose.heading.abs() < 1e-9,
            "heading 90 T = east = 0 rad"
        );
        assert_eq!(b.quality, 0.5);
        // An invalid fix is not a sample; the stream then ends.
        assert!(matches!(gps.read(Duration::ZERO), Err(GpsError::Closed)));
    }
}

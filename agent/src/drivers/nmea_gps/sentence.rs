//! The NMEA 0183 sentences the GPS driver reads: `$--GGA` (position, fix,
//! HDOP, altitude) and `$--HDT` (true heading), from any talker. A sentence
//! is checked whole first (`$`, ASCII, the `*hh` checksum) and then its
//! fields; `RMC` is recognised and not used; anything else is unsupported.

/// Why a sentence was not used.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum SentenceError {
    #[error("not an NMEA sentence (no leading `$` or `*hh` checksum)")]
    Framing,
    #[error("checksum {found:02X} does not match the sentence ({computed:02X})")]
    Checksum { found: u8, computed: u8 },
    #[error("unsupported sentence {0:?}")]
    Unsupported(String),
    #[error("field {field} {value:?} is not valid")]
    Field { field: &'static str, value: String },
}

/// A position fix: degrees north and east.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Fix {
    pub latitude: f64,
    pub longitude: f64,
}

/// A `GGA` sentence: the fix, if the receiver has a valid one.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gga {
    /// `None` when the fix quality says invalid, estimated, manual or
    /// simulated, or the position is empty.
    pub fix: Option<Fix>,
    pub hdop: Option<f64>,
    /// Metres above mean sea level.
    pub altitude: Option<f64>,
}

/// One recognised sentence.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Sentence {
    Gga(Gga),
    /// True heading, degrees clockwise from north, if the receiver has one.
    Hdt(Option<f64>),
    /// Well-formed, and not needed here.
    Other,
}

/// Parses one sentence (without its line ending).
pub fn parse(line: &str) -> Result<Sentence, SentenceError> {
    let body = checked_body(line)?;
    let fields: Vec<&str> = body.split(',').collect();
    let kind = fields[0].get(2..).unwrap_or_default();
    match kind {
        "GGA" => gga(&fields).map(Sentence::Gga),
        "HDT" => optional(fields.get(1), "heading").map(Sentence::Hdt),
        "RMC" => Ok(Sentence::Other),
        _ => Err(SentenceError::Unsupported(fields[0].to_string())),
    }
}

/// The text between `$` and `*`, once its checksum (XOR of its bytes) matches.
fn checked_body(line: &str) -> Result<&str, SentenceError> {
    if !line.is_ascii() {
        return Err(SentenceError::Framing);
    }
    let inner = line.strip_prefix('$').ok_or(SentenceError::Framing)?;
    let (body, sum) = inner.rsplit_once('*').ok_or(SentenceError::Framing)?;
    let found = (sum.len() == 2)
        .then(|| u8::from_str_radix(sum, 16).ok())
        .flatten()
        .ok_or(SentenceError::Framing)?;
    let computed = body.bytes().fold(0u8, |a, b| a ^ b);
    if found != computed {
        return Err(SentenceError::Checksum { found, computed });
    }
    Ok(body)
}

/// `$--GGA,time,lat,N|S,lon,E|W,quality,sats,hdop,alt,M,...`
fn gga(fields: &[&str]) -> Result<Gga, SentenceError> {
    let field = |i: usize| fields.get(i).copied().unwrap_or_default();
    // 1 GPS, 2 DGPS, 3 PPS, 4 RTK, 5 float RTK; 0 invalid, 6 estimated,
    // 7 manual, 8 simulated are not measurements.
    let measured = matches!(field(6), "1" | "2" | "3" | "4" | "5");
    let latitude = angle(field(2), field(3), 2, ("N", "S"), "latitude")?;
    let longitude = angle(field(4), field(5), 3, ("E", "W"), "longitude")?;
    let fix = match (measured, latitude, longitude) {
        (true, Some(latitude), Some(longitude)) => Some(Fix {
            latitude,
            longitude,
        }),
        _ => None,
    };
    Ok(Gga {
        fix,
        hdop: optional(fields.get(8), "hdop")?,
        altitude: optional(fields.get(9), "altitude")?,
    })
}

/// `ddmm.mmmm` (or `dddmm.mmmm`, `degree_digits` = 3) and its hemisphere
/// as signed degrees; `None` when empty.
fn angle(
    value: &str,
    hemisphere: &str,
    degree_digits: usize,
    (plus, minus): (&str, &str),
    field: &'static str,
) -> Result<Option<f64>, SentenceError> {
    if value.is_empty() {
        return Ok(None);
    }
    let bad = || SentenceError::Field {
        field,
        value: format!("{value},{hemisphere}"),
    };
    let (degrees, minutes) = (value.get(..degree_digits), value.get(degree_digits..));
    let degrees: f64 = degrees.and_then(|d| d.parse().ok()).ok_or_else(bad)?;
    let minutes: f64 = minutes.and_then(|m| m.parse().ok()).ok_or_else(bad)?;
    if !(0.0..60.0).contains(&minutes) {
        return Err(bad());
    }
    let magnitude = degrees + minutes / 60.0;
    match hemisphere {
        h if h == plus => Ok(Some(magnitude)),
        h if h == minus => Ok(Some(-magnitude)),
        _ => Err(bad()),
    }
}

/// A decimal field that may be empty.
fn optional(value: Option<&&str>, field: &'static str) -> Result<Option<f64>, SentenceError> {
    match value.copied().unwrap_or_default() {
        "" => Ok(None),
        v => v
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .map(Some)
            .ok_or_else(|| SentenceError::Field {
                field,
                value: v.to_string(),
            }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sentence(body: &str) -> String {
        let sum = body.bytes().fold(0u8, |a, b| a ^ b);
        format!("${body}*{sum:02X}")
    }

    #[test]
    fn gga_gives_signed_degrees_hdop_and_altitude() {
        let s = sentence("GNGGA,123519,4807.038,S,01131.000,W,4,08,0.9,545.4,M,46.9,M,,");
        let Sentence::Gga(g) = parse(&s).unwrap() else {
            panic!()
        };
        let fix = g.fix.unwrap();
        assert!((fix.latitude + (48.0 + 7.038 / 60.0)).abs() < 1e-12);
        assert!((fix.longitude + (11.0 + 31.0 / 60.0)).abs() < 1e-12);
        assert_eq!((g.hdop, g.altitude), (Some(0.9), Some(545.4)));
    }

    #[test]
    fn estimated_or_empty_positions_are_no_fix() {
        for body in [
            "GPGGA,123519,4807.038,N,01131.000,E,6,08,0.9,545.4,M,46.9,M,,",
            "GPGGA,123519,,,,,0,00,,,M,,M,,",
        ] {
            let Sentence::Gga(g) = parse(&sentence(body)).unwrap() else {
                panic!()
            };
            assert_eq!(g.fix, None, "{body}");
        }
    }

    #[test]
    fn heading_rmc_and_unsupported_sentences() {
        assert_eq!(
            parse(&sentence("GPHDT,274.07,T")).unwrap(),
            Sentence::Hdt(Some(274.07))
        );
        assert_eq!(parse(&sentence("GPHDT,,T")).unwrap(), Sentence::Hdt(None));
        assert_eq!(
            parse(&sentence(
                "GPRMC,123519,A,4807.038,N,01131.000,E,022.4,084.4,230394,003.1,W"
            ))
            .unwrap(),
            Sentence::Other
        );
        assert!(matches!(
            parse(&sentence("GPGSV,1,1,00")),
            Err(SentenceError::Unsupported(_))
        ));
    }

    #[test]
    fn corrupt_sentences_are_errors() {
        let good = sentence("GPHDT,90.0,T");
        let flipped = good.replace("90.0", "91.0");
        assert!(matches!(
            parse(&flipped),
            Err(SentenceError::Checksum { .. })
        ));
        for bad in [
            "",
            "$",
            "GPHDT,90.0,T*00",
            "$GPHDT,90.0,T",
            "$GPHDT*zz",
            "$é*00",
        ] {
            assert!(parse(bad).is_err(), "{bad:?}");
        }
        for body in [
            "GPGGA,1,48x7.038,N,01131.000,E,1,08,0.9,5,M,,M,,",
            "GPGGA,1,4807.038,Q,01131.000,E,1,08,0.9,5,M,,M,,",
            "GPGGA,1,4867.038,N,01131.000,E,1,08,0.9,5,M,,M,,",
            "GPGGA,1,4807.038,N,01131.000,E,1,08,inf,5,M,,M,,",
            "GPHDT,north,T",
        ] {
            assert!(
                matches!(parse(&sentence(body)), Err(SentenceError::Field { .. })),
                "{body}"
            );
        }
    }
}

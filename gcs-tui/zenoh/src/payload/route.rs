//! `mech/<station>/<robot>/route/request`, a query: another station's
//! operator asks this station to route one of its robots, and the reply
//! says what it did. The request is signed with that operator's key
//! (`mech-gcs keygen`), which this station must list as an operator in its
//! `[auth]` section: the tag is the protocol's (`docs/security.md`), over
//! the text
//!
//! ```text
//! mech-route-request/1\n<station>\n<robot>\n<channel or empty>\n<operator>
//! ```
//!
//! with link number [`ROUTE_LINK`], so a tag made for one station, robot
//! and channel is worth nothing for another, and each is accepted once.

use mech_proto::auth::{Signer, TAG_LEN, Tag};
use serde::{Deserialize, Serialize};

use super::{PayloadError, VERSION};

/// The link number of route-request tags: their own stream per operator
/// key, apart from anything the same key signs on the message protocol.
pub const ROUTE_LINK: u8 = 0x40;

/// A route request.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RouteRequest {
    pub v: u32,
    /// The station asked.
    pub station: String,
    pub robot: String,
    /// `null` = route to none.
    pub channel: Option<String>,
    /// The operator key's name.
    pub operator: String,
    /// The tag, hexadecimal (58 digits); absent when unsigned.
    pub tag: Option<String>,
}

impl RouteRequest {
    pub fn new(station: &str, robot: &str, channel: Option<&str>, operator: &str) -> RouteRequest {
        RouteRequest {
            v: VERSION,
            station: station.to_string(),
            robot: robot.to_string(),
            channel: channel.map(str::to_string),
            operator: operator.to_string(),
            tag: None,
        }
    }

    /// The bytes the tag covers.
    pub fn region(&self) -> Vec<u8> {
        format!(
            "mech-route-request/{}\n{}\n{}\n{}\n{}",
            self.v,
            self.station,
            self.robot,
            self.channel.as_deref().unwrap_or(""),
            self.operator
        )
        .into_bytes()
    }

    /// Signs the request with `signer`'s key and its next stamp, taken at
    /// `local_us` on the station's clock; unsigned without a key.
    pub fn sign(&mut self, signer: &mut Signer, local_us: u64) {
        if let Some(tag) = signer.sign(&self.region(), ROUTE_LINK, local_us) {
            self.tag = Some(tag.iter().map(|b| format!("{b:02x}")).collect());
        }
    }

    /// The tag, if the request carries one.
    pub fn parsed_tag(&self) -> Result<Option<Tag>, PayloadError> {
        let Some(hex) = &self.tag else {
            return Ok(None);
        };
        let bad = || PayloadError::Invalid {
            what: "route request",
            detail: format!("tag is not {} hexadecimal digits", 2 * TAG_LEN),
        };
        if hex.len() != 2 * TAG_LEN || !hex.is_ascii() {
            return Err(bad());
        }
        let bytes = (0..TAG_LEN)
            .map(|i| u8::from_str_radix(&hex[2 * i..2 * i + 2], 16))
            .collect::<Result<Vec<u8>, _>>()
            .map_err(|_| bad())?;
        let tag = Tag::parse(&bytes).map_err(|_| bad())?;
        if tag.link != ROUTE_LINK {
            return Err(PayloadError::Invalid {
                what: "route request",
                detail: format!("tag of link {:#x}, not a route request's", tag.link),
            });
        }
        Ok(Some(tag))
    }
}

/// The answer to a route request.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RouteReply {
    pub v: u32,
    /// Whether the station routed the robot.
    pub ok: bool,
    /// What it did, or why not.
    pub message: String,
    /// The route epoch it made, when it did.
    pub epoch: Option<u32>,
}

impl RouteReply {
    pub fn done(message: String, epoch: u32) -> RouteReply {
        RouteReply {
            v: VERSION,
            ok: true,
            message,
            epoch: Some(epoch),
        }
    }

    pub fn refused(message: String) -> RouteReply {
        RouteReply {
            v: VERSION,
            ok: false,
            message,
            epoch: None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use mech_proto::auth::Key;

    #[test]
    fn a_signed_request_checks_only_for_what_it_names() {
        let key = Key::new(&[7; 32]);
        let mut r = RouteRequest::new("site-a", "robot_1", Some("ext/x"), "op-b");
        r.sign(&mut Signer::new(Some(key.clone())), 1_000);
        let json = serde_json::to_vec(&r).unwrap();
        let back: RouteRequest = serde_json::from_slice(&json).unwrap();
        let tag = back.parsed_tag().unwrap().unwrap();
        assert_eq!((tag.key_id, tag.stamp_us), (key.id(), 1_000));
        assert!(key.verify(&back.region(), &tag));
        for other in [
            RouteRequest {
                channel: None,
                ..back.clone()
            },
            RouteRequest {
                robot: "robot_2".into(),
                ..back.clone()
            },
            RouteRequest {
                station: "site-c".into(),
                ..back.clone()
            },
        ] {
            assert!(!key.verify(&other.region(), &tag), "{other:?}");
        }
    }

    #[test]
    fn malformed_tags_are_errors_and_no_tag_is_none() {
        let r = RouteRequest::new("s", "r", None, "op");
        assert_eq!(r.parsed_tag().unwrap(), None);
        for bad in ["zz", "00", &"g".repeat(58)] {
            let r = RouteRequest {
                tag: Some(bad.to_string()),
                ..r.clone()
            };
            assert!(r.parsed_tag().is_err(), "{bad}");
        }
        let mut on_link_0 = [0u8; TAG_LEN];
        on_link_0[4] = 0;
        let r = RouteRequest {
            tag: Some(on_link_0.iter().map(|b| format!("{b:02x}")).collect()),
            ..r
        };
        assert!(r.parsed_tag().is_err(), "a message tag is not a request's");
    }
}

//! Validation of a received `Command` on the forwarding hot path, without
//! building the envelope: the header names are checked in place (borrowed
//! from the datagram, as [`mech_proto::peek`] returns them) and only the
//! command itself is deserialised. It accepts exactly what
//! [`mech_proto::decode`] accepts for a `Command` message (the unit tests
//! compare the two on mutated input), so a truncated, corrupt or out-of-range
//! command is still never forwarded, but the names cost no allocation.

use mech_proto::{AuthTag, Command, Error, MAX_AUTH_LEN, MAX_NAME_LEN, Peek};
use serde::Deserialize;

/// Checks the rest of a message whose header `head` was peeked from `bytes`
/// and whose kind is `Command`: names, the command's fields and ranges, the
/// authentication tag and that nothing follows the message.
pub(crate) fn command(bytes: &[u8], head: &Peek<'_>) -> Result<(), Error> {
    name(head.sender, "sender")?;
    name(head.destination, "destination")?;
    name(head.channel, "channel")?;
    // The channel is the last header element; the body starts right after it.
    let body_at = (head.channel.as_ptr() as usize)
        .checked_sub(bytes.as_ptr() as usize)
        .map(|at| at + head.channel.len())
        .and_then(|at| bytes.get(at..))
        .ok_or_else(|| Error::Malformed("header outside the message".into()))?;
    let mut rest = body_at;
    let (command, auth) = {
        let mut de = rmp_serde::Deserializer::new(&mut rest);
        let malformed = |e: rmp_serde::decode::Error| Error::Malformed(e.to_string());
        let command = Command::deserialize(&mut de).map_err(malformed)?;
        let auth = Option::<AuthTag>::deserialize(&mut de).map_err(malformed)?;
        (command, auth)
    };
    if !rest.is_empty() {
        return Err(Error::Malformed(format!(
            "{} bytes after the message",
            rest.len()
        )));
    }
    if let Some(tag) = auth {
        if tag.len() > MAX_AUTH_LEN {
            return Err(Error::Invalid(format!(
                "authentication tag of {} bytes, at most {MAX_AUTH_LEN} allowed",
                tag.len()
            )));
        }
    }
    command.validate()
}

/// The protocol's rule for a name (as `mech_proto` checks it on decode).
fn name(v: &str, what: &str) -> Result<(), Error> {
    if v.len() > MAX_NAME_LEN {
        return Err(Error::Invalid(format!(
            "{what} is {} bytes long, at most {MAX_NAME_LEN} allowed",
            v.len()
        )));
    }
    if v.chars().any(|c| c.is_control() || c.is_whitespace()) {
        return Err(Error::Invalid(format!(
            "{what} {v:?} contains whitespace or control characters"
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use mech_proto::{
        Actuators, Body, Envelope, Header, SteeringThrottle, Stop, Twist, VelocityHeading,
    };
    use proptest::prelude::*;

    const COMMAND: u8 = 5;

    /// What the router's fast check says about `bytes`.
    fn fast(bytes: &[u8]) -> bool {
        match mech_proto::peek(bytes) {
            Ok(head) if head.kind == COMMAND => command(bytes, &head).is_ok(),
            _ => false,
        }
    }

    /// What a full decode says: a valid message with a `Command` body.
    fn full(bytes: &[u8]) -> bool {
        matches!(
            mech_proto::decode(bytes),
            Ok(Envelope {
                body: Body::Command(_),
                ..
            })
        )
    }

    fn encoded(command: Command, sender: &str, auth: Option<Vec<u8>>) -> Vec<u8> {
        let mut env = Envelope::new(
            Header {
                seq: 7,
                stamp_us: 1_700_000_000_000_000,
                sender: sender.into(),
                destination: "robot_1".into(),
                channel: "joy/0".into(),
            },
            Body::Command(command),
        );
        env.auth = auth.map(AuthTag::from);
        mech_proto::encode(&env).unwrap()
    }

    fn commands() -> Vec<Command> {
        vec![
            Command::Twist(Twist {
                vx: 0.5,
                vy: 0.0,
                vz: 0.0,
                wz: 0.1,
            }),
            Command::Actuators(Actuators {
                outputs: vec![0.1, -0.2, 0.3],
            }),
            Command::SteeringThrottle(SteeringThrottle {
                steering: 0.2,
                throttle: 0.4,
            }),
            Command::VelocityHeading(VelocityHeading {
                speed: 0.3,
                heading: 1.0,
            }),
            Command::Stop(Stop {}),
        ]
    }

    #[test]
    fn valid_commands_pass() {
        for c in commands() {
            let bytes = encoded(c, "pad", None);
            assert!(fast(&bytes) && full(&bytes));
            let signed = encoded(Command::Stop(Stop {}), "pad", Some(vec![1; 32]));
            assert!(fast(&signed) && full(&signed));
        }
    }

    #[test]
    fn a_nan_a_truncation_and_trailing_bytes_fail() {
        let bytes = encoded(commands()[0].clone(), "pad", None);
        // vx = 0.5 is the f64 0x3fe0000000000000; make it NaN.
        let at = bytes
            .windows(9)
            .position(|w| w == [0xcb, 0x3f, 0xe0, 0, 0, 0, 0, 0, 0])
            .unwrap();
        let mut nan = bytes.clone();
        nan[at + 1..at + 9].copy_from_slice(&f64::NAN.to_be_bytes());
        assert!(!fast(&nan) && !full(&nan));
        for cut in 1..bytes.len() {
            assert!(!fast(&bytes[..cut]), "truncated at {cut}");
        }
        let mut longer = bytes.clone();
        longer.push(0xc0);
        assert!(!fast(&longer) && !full(&longer));
    }

    #[test]
    fn a_bad_sender_name_fails() {
        // Encoding refuses a bad name, so patch one in: "pad" -> "p d".
        let bytes = encoded(commands()[0].clone(), "pad", None);
        let at = bytes.windows(3).position(|w| w == b"pad").unwrap();
        let mut spaced = bytes.clone();
        spaced[at + 1] = b' ';
        assert!(!fast(&spaced) && !full(&spaced));
    }

    proptest! {
        /// Mutated commands: the fast check and a full decode agree.
        #[test]
        fn agrees_with_a_full_decode(
            which in 0usize..5,
            edits in proptest::collection::vec((any::<usize>(), any::<u8>(), 0u8..3), 1..4),
        ) {
            let mut bytes = encoded(commands()[which].clone(), "pad", None);
            for (at, byte, op) in edits {
                let at = at % (bytes.len() + 1);
                match op {
                    0 if at < bytes.len() => bytes[at] = byte,
                    1 => bytes.insert(at, byte),
                    _ => bytes.truncate(at),
                }
            }
            prop_assert_eq!(fast(&bytes), full(&bytes));
        }
    }
}

//! What the robot sends and receives as bytes: the sequence numbers and
//! stamps of its messages (numbered as they are sent, so a message a link
//! skips leaves no gap), signing them when it has a key, and the checks
//! received bytes pass before any other part of the core sees them
//! (addressed to this robot, decodable, signed by the router for it).

use std::time::Duration;

use mech_proto::{Body, Envelope, Header, Level, Notice, NoticeCode};

use crate::auth::{Checked, RobotAuth, RobotRejections};

/// Numbering, stamping and signing of what this robot sends; checking of
/// what it receives.
#[derive(Debug)]
pub(crate) struct Wire {
    /// The sender of everything this robot sends, and the destination it
    /// accepts.
    name: String,
    /// The number of the last message sent.
    seq: u32,
    /// Unix time (µs) at agent time zero, for message stamps.
    stamp_origin_us: u64,
    /// Signing and checking, when the robot has a key.
    auth: Option<RobotAuth>,
}

/// Why received bytes are not a message for the rest of the core.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Unread {
    /// Addressed to another robot (a radio is a broadcast medium).
    NotForMe,
    /// Not a message.
    Undecodable,
    /// The router's answer to this robot's time request: station time is
    /// known, so the robot may register now.
    Synced,
    /// Refused by authentication (counted in [`Wire::rejections`]).
    Refused,
}

impl Wire {
    pub(crate) fn new(name: &str, stamp_origin_us: u64) -> Wire {
        Wire {
            name: name.to_string(),
            seq: 0,
            stamp_origin_us,
            auth: None,
        }
    }

    /// Signs everything with `key` and accepts only what the router (named
    /// `router`) signed for this robot.
    pub(crate) fn with_key(&mut self, key: mech_proto::auth::Key, router: &str) {
        self.auth = Some(RobotAuth::new(key, router));
    }

    pub(crate) fn name(&self) -> &str {
        &self.name
    }

    /// Messages refused by authentication, by reason (zero without a key).
    pub(crate) fn rejections(&self) -> RobotRejections {
        self.auth.as_ref().map(|a| a.rejected).unwrap_or_default()
    }

    /// The robot's clock at agent time `now`: µs since the Unix epoch.
    pub(crate) fn stamp_us(&self, now: Duration) -> u64 {
        self.stamp_origin_us + now.as_micros() as u64
    }

    /// A message from this robot, stamped; it is numbered when sent
    /// ([`Wire::number`]).
    pub(crate) fn envelope(&mut self, destination: &str, body: Body, now: Duration) -> Envelope {
        Envelope::new(
            Header {
                seq: 0,
                stamp_us: self.stamp_us(now),
                sender: self.name.clone(),
                destination: destination.to_string(),
                channel: String::new(),
            },
            body,
        )
    }

    /// A notice from this robot (free text cut to the protocol's limit).
    pub(crate) fn notice(
        &mut self,
        destination: &str,
        level: Level,
        code: NoticeCode,
        text: &str,
        now: Duration,
    ) -> Envelope {
        let body = Body::Notice(Notice {
            level,
            code,
            text: truncate(text),
        });
        self.envelope(destination, body, now)
    }

    /// Numbers a message that is about to be sent: +1 for each message
    /// that goes out, on one link or several (the copies share the
    /// number), and none for one that is not sent at all (a telemetry
    /// sample over a radio's rate cap). The router reads a gap in the
    /// numbers as messages lost on the way (`docs/protocol.md`, *Link
    /// quality*), so only a message that left may take a number.
    pub(crate) fn number(&mut self, env: &mut Envelope) {
        self.seq = self.seq.wrapping_add(1);
        env.header.seq = self.seq;
    }

    /// Encodes a message to send on link number `link`, signed when the
    /// robot has a key: each link is its own signed stream.
    pub(crate) fn encode_on(
        &mut self,
        env: &Envelope,
        link: u8,
        out: &mut Vec<u8>,
    ) -> Result<(), mech_proto::Error> {
        mech_proto::encode_into(env, out)?;
        if let Some(auth) = self.auth.as_mut()
            && let Err(e) = auth.seal(out, env.header.stamp_us, link)
        {
            return Err(mech_proto::Error::Encode(e.to_string()));
        }
        Ok(())
    }

    /// Whether a message addressed to `destination` is for this robot.
    pub(crate) fn for_me(&self, destination: &str) -> bool {
        destination.is_empty() || destination == mech_proto::BROADCAST || destination == self.name
    }

    /// Checks and decodes one received datagram or frame: a message for
    /// this robot, authentic when the robot has a key, or why not.
    pub(crate) fn receive(&mut self, bytes: &[u8], now: Duration) -> Result<Envelope, Unread> {
        // A radio is a broadcast medium: frames for other robots are
        // skipped before they are checked (they are signed for those
        // robots, not refused forgeries).
        if let Ok(head) = mech_proto::peek(bytes)
            && !self.for_me(head.destination)
        {
            return Err(Unread::NotForMe);
        }
        let Ok(env) = mech_proto::decode(bytes) else {
            return Err(Unread::Undecodable);
        };
        let local_us = self.stamp_us(now);
        let Some(auth) = self.auth.as_mut() else {
            return Ok(env);
        };
        match auth.check(bytes, &env.header.sender, &env.body, local_us) {
            Checked::Accept => Ok(env),
            Checked::Synced => Err(Unread::Synced),
            Checked::Reject => {
                if auth.rejected.total().is_power_of_two() {
                    tracing::warn!(robot = %self.name, rejected = ?auth.rejected, "refused a message not signed by the router for this robot");
                }
                Err(Unread::Refused)
            }
        }
    }

    /// A time request to send before registering, while a robot with a key
    /// does not know station time (signed stamps need it); `None` when it
    /// may say Hello.
    pub(crate) fn time_request(&mut self) -> Option<mech_proto::TimeRequest> {
        match self.auth.as_mut() {
            Some(auth) if !auth.synced() => Some(auth.time_request()),
            _ => None,
        }
    }

    /// The router was lost: with a key, ask its time again before trusting
    /// it.
    pub(crate) fn forget_router(&mut self) {
        if let Some(auth) = self.auth.as_mut() {
            auth.forget_router();
        }
    }
}

/// Cuts free text to the protocol's limit on a character boundary.
pub(crate) fn truncate(text: &str) -> String {
    let mut end = text.len().min(mech_proto::MAX_TEXT_LEN);
    while !text.is_char_boundary(end) {
        end -= 1;
    }
    text[..end].to_string()
}

#[cfg(test)]
mod tests {
    use super::super::testing::*;

    #[test]
    fn frames_for_other_robots_on_a_shared_radio_are_skipped() {
        let mut a = routed("joy/0");
        let other = Envelope::new(
            Header {
                destination: "r2".into(),
                channel: "joy/0".into(),
                ..Header::default()
            },
            twist(0.5),
        );
        a.handle_bytes(&mech_proto::encode(&other).unwrap(), ms(10));
        assert!(!moving(&a.tick(ms(20)).outputs));
        assert_eq!(a.counters().not_for_me, 1);
        assert_eq!(a.counters().commands, 0);
        a.handle_bytes(
            &mech_proto::encode(&msg("joy/0", twist(0.5))).unwrap(),
            ms(30),
        );
        assert_eq!(a.counters().commands, 1);
    }

    #[test]
    fn undecodable_bytes_and_unsupported_commands_are_counted() {
        let mut a = routed("joy/0");
        assert!(a.handle_bytes(&[0x93, 0x01, 0xff], ms(5)).is_empty());
        assert_eq!(a.counters().bad_messages, 1);
        let out = a.handle(
            msg(
                "joy/0",
                Body::Command(Command::Actuators(mech_proto::Actuators {
                    outputs: vec![0.5],
                })),
            ),
            ms(10),
        );
        assert!(matches!(&out[0].body, Body::Notice(n) if n.code == NoticeCode::Unsupported));
        assert_eq!(a.counters().refused, 1);
        let mut other = msg("joy/0", twist(0.2));
        other.header.destination = "r2".into();
        a.handle(other, ms(20));
        assert_eq!(a.counters().not_for_me, 1);
        assert!(!moving(&a.tick(ms(30)).outputs));
    }
}

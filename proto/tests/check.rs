//! `check_command`, the router's allocation-free check of a received
//! command, accepts exactly what a full `decode` accepts for a `Command`
//! message, on valid, corrupt and mutated input.

use mech_proto::{
    Actuators, AuthTag, Body, Command, Envelope, Header, SteeringThrottle, Stop, Twist,
    VelocityHeading, check_command,
};
use proptest::prelude::*;

/// What the router's fast check says about `bytes`.
fn fast(bytes: &[u8]) -> bool {
    match mech_proto::peek(bytes) {
        Ok(head) => check_command(bytes, &head).is_ok(),
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
fn command_kind_constant_matches_the_body() {
    assert_eq!(
        mech_proto::COMMAND_KIND,
        Body::Command(Command::Stop(Stop {})).kind()
    );
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

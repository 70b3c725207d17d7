//! Hostile input: truncated, oversized, corrupt, wrong-version, unknown-kind
//! and random bytes all return a typed error and never panic.

use mech_proto::framing::{SerialDecoder, StreamDecoder, write_serial_frame, write_stream_frame};
use mech_proto::*;

/// SplitMix64: a tiny deterministic generator so failures reproduce.
struct Rng(u64);

impl Rng {
    fn next(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    fn below(&mut self, n: usize) -> usize {
        (self.next() % n as u64) as usize
    }
    fn bytes(&mut self, n: usize) -> Vec<u8> {
        (0..n).map(|_| self.next() as u8).collect()
    }
}

fn samples() -> Vec<Envelope> {
    let h = |channel: &str| Header {
        seq: 42,
        stamp_us: 1_795_000_000_000_000,
        sender: "gcs".into(),
        destination: "robot_1".into(),
        channel: channel.into(),
    };
    vec![
        Envelope::new(
            h("joy/0"),
            Body::Command(Command::Twist(Twist {
                vx: 0.4,
                vy: 0.1,
                vz: 0.0,
                wz: 0.3,
            })),
        ),
        Envelope::new(
            h("wp/gcs"),
            Body::Mission(Mission {
                id: 9,
                waypoints: vec![
                    Waypoint {
                        x: 1.0,
                        y: 2.0,
                        z: 0.0,
                        time: None,
                    },
                    Waypoint {
                        x: 3.0,
                        y: 2.0,
                        z: 0.0,
                        time: Some(15.0),
                    },
                ],
                looped: true,
                arrival_radius: 0.05,
                start_index: 1,
            }),
        ),
        Envelope::new(
            h(""),
            Body::Telemetry(Telemetry {
                pose: Pose {
                    x: 1.0,
                    y: -2.0,
                    z: 0.0,
                    heading: 0.5,
                },
                velocity: Velocity::default(),
                mode: ControlMode::Twist,
                channel: "joy/0".into(),
                computation: Computation::Onboard,
                failsafe: FailsafeState::Ok,
                health: Health::Ok,
                battery: Some(0.5),
                position_quality: 1.0,
                actuators: vec![0.1, -0.1],
                mission: None,
                stale: 0,
                velocity_source: mech_proto::VelocitySource::Measured,
                safety: None,
            }),
        ),
        Envelope::new(
            h("fleet/c1"),
            Body::FleetCommand(FleetCommand {
                parts: vec![
                    RobotCommand {
                        robot: "robot_1".into(),
                        command: Command::Stop(Stop {}),
                    },
                    RobotCommand {
                        robot: "robot_2".into(),
                        command: Command::Actuators(Actuators {
                            outputs: vec![0.5, -0.5, 0.25],
                        }),
                    },
                ],
            }),
        ),
    ]
}

#[test]
fn every_truncation_is_an_error() {
    for env in samples() {
        let bytes = encode(&env).unwrap();
        for n in 0..bytes.len() {
            assert!(
                decode(&bytes[..n]).is_err(),
                "{} truncated to {n} bytes decoded",
                env.body.name()
            );
        }
    }
}

#[test]
fn trailing_bytes_are_an_error() {
    let mut bytes = encode(&samples()[0]).unwrap();
    bytes.push(0xc0);
    assert!(matches!(decode(&bytes), Err(Error::Malformed(_))));
}

#[test]
fn typed_errors_for_empty_oversized_version_and_kind() {
    assert_eq!(decode(&[]), Err(Error::Empty));
    let huge = vec![0x99; MAX_MESSAGE_LEN + 1];
    assert!(matches!(decode(&huge), Err(Error::Oversized { .. })));

    let mut bytes = encode(&samples()[0]).unwrap();
    bytes[1] = 2; // version 2
    assert_eq!(
        decode(&bytes),
        Err(Error::Version {
            found: 2,
            supported: 1
        })
    );
    bytes[1] = 1;
    bytes[2] = 0x7f; // kind 127
    assert_eq!(decode(&bytes), Err(Error::UnknownKind(127)));
    assert_eq!(peek(&bytes).err(), Some(Error::UnknownKind(127)));
}

#[test]
fn non_finite_and_out_of_range_values_are_rejected_both_ways() {
    let mut env = samples()[0].clone();
    env.body = Body::Command(Command::Twist(Twist {
        vx: f64::NAN,
        vy: 0.0,
        vz: 0.0,
        wz: 0.0,
    }));
    assert!(matches!(encode(&env), Err(Error::Invalid(_))));

    // A peer that sends NaN anyway: patch the float bytes of vx.
    let mut bytes = encode(&samples()[0]).unwrap();
    let at = bytes.iter().position(|&b| b == 0xcb).unwrap();
    bytes[at + 1..at + 9].copy_from_slice(&f64::NAN.to_be_bytes());
    assert!(matches!(decode(&bytes), Err(Error::Invalid(_))));

    env.body = Body::Command(Command::SteeringThrottle(SteeringThrottle {
        steering: 1.5,
        throttle: 0.0,
    }));
    assert!(matches!(encode(&env), Err(Error::Invalid(_))));

    env.body = Body::Command(Command::Twist(Twist::default()));
    env.header.channel = "joy 0".into();
    assert!(
        matches!(encode(&env), Err(Error::Invalid(_))),
        "names hold no whitespace"
    );
}

/// A waypoint may be due a day after its mission starts at most: a later
/// (finite) arrival time is refused, sent or received, so no robot counts
/// time it cannot hold.
#[test]
fn a_waypoint_due_more_than_a_day_later_is_rejected_both_ways() {
    let mission = |time| {
        let mut env = samples()[1].clone();
        let Body::Mission(m) = &mut env.body else {
            panic!("sample 1 is a mission");
        };
        m.waypoints[1].time = Some(time);
        env
    };
    assert!(encode(&mission(mech_proto::MAX_WAYPOINT_TIME)).is_ok());
    let late = mission(1e20);
    let e = encode(&late).unwrap_err();
    assert!(e.to_string().contains("more than"), "{e}");
    // A peer that sends it anyway: the 15 s of the sample patched to 1e20.
    let mut bytes = encode(&mission(15.0)).unwrap();
    let at = bytes
        .windows(8)
        .position(|w| w == 15.0f64.to_be_bytes())
        .unwrap();
    bytes[at..at + 8].copy_from_slice(&1e20f64.to_be_bytes());
    assert!(matches!(decode(&bytes), Err(Error::Invalid(_))));
}

#[test]
fn unknown_command_kind_is_malformed_not_a_panic() {
    let mut bytes = encode(&samples()[0]).unwrap();
    // The command kind follows the body's 0x92 array marker.
    let at = bytes.iter().position(|&b| b == 0x92).unwrap();
    bytes[at + 1] = 0x55;
    assert!(matches!(decode(&bytes), Err(Error::Malformed(_))));
}

#[test]
fn hundred_thousand_random_byte_strings_never_panic() {
    let mut rng = Rng(1);
    let mut stream = StreamDecoder::new();
    let mut serial = SerialDecoder::new();
    let mut ok = 0;
    for i in 0..100_000 {
        let len = rng.below(96);
        let mut bytes = rng.bytes(len);
        // Half of them start like an envelope, to get past the first checks.
        if i % 2 == 0 && len >= 3 {
            bytes[0] = 0x99;
            bytes[1] = 0x01;
            bytes[2] = (rng.below(21)) as u8;
        }
        ok += usize::from(decode(&bytes).is_ok());
        let _ = peek(&bytes);
        stream.push(&bytes);
        while stream.next_frame().is_some() {}
        if stream.is_broken() {
            stream = StreamDecoder::new();
        }
        serial.push(&bytes);
        while serial.next_message().is_some() {}
    }
    assert_eq!(ok, 0, "random bytes are not valid messages");
}

#[test]
fn hundred_thousand_mutated_frames_never_panic_and_serial_crc_catches_them() {
    let mut rng = Rng(2);
    let envs = samples();
    let mut undetected_serial = 0;
    for i in 0..100_000 {
        let env = &envs[i % envs.len()];
        let mut bytes = encode(env).unwrap();
        mutate(&mut rng, &mut bytes);
        if let Ok(decoded) = decode(&bytes) {
            // A mutation may produce another valid message; it must still be valid.
            decoded.validate().unwrap();
        }

        let mut framed = Vec::new();
        write_stream_frame(env, &mut framed).unwrap();
        mutate(&mut rng, &mut framed);
        let mut sd = StreamDecoder::new();
        sd.push(&framed);
        while sd.next_message().is_some() {}

        let mut serial = Vec::new();
        write_serial_frame(env, &mut serial).unwrap();
        let original = serial.clone();
        mutate(&mut rng, &mut serial);
        let mut rd = SerialDecoder::new();
        rd.push(&serial);
        // Resynchronisation: an intact frame after the damaged one decodes.
        rd.push(&original);
        let mut results = Vec::new();
        while let Some(r) = rd.next_message() {
            results.push(r);
        }
        assert_eq!(
            results.last(),
            Some(&Ok(env.clone())),
            "decoder resynchronises"
        );
        // Mutating only a delimiter leaves the message intact; anything
        // else must be caught.
        undetected_serial += results[..results.len() - 1]
            .iter()
            .filter(|r| matches!(r, Ok(m) if m != env))
            .count();
    }
    assert_eq!(
        undetected_serial, 0,
        "CRC-32 lets no mutated serial frame through"
    );
}

fn mutate(rng: &mut Rng, bytes: &mut Vec<u8>) {
    match rng.below(5) {
        0 => {
            let at = rng.below(bytes.len());
            bytes[at] ^= 1 << rng.below(8);
        }
        1 => {
            let at = rng.below(bytes.len());
            bytes[at] = rng.next() as u8;
        }
        2 => {
            let keep = rng.below(bytes.len());
            bytes.truncate(keep);
        }
        3 => {
            let at = rng.below(bytes.len() + 1);
            bytes.insert(at, rng.next() as u8);
        }
        _ => {
            let at = rng.below(bytes.len());
            bytes.remove(at);
        }
    }
}

#[test]
fn stream_decoder_stops_on_a_bad_length_and_keeps_earlier_frames() {
    let env = &samples()[0];
    let mut bytes = Vec::new();
    write_stream_frame(env, &mut bytes).unwrap();
    bytes.extend_from_slice(&u32::MAX.to_be_bytes());
    let mut dec = StreamDecoder::new();
    dec.push(&bytes);
    assert_eq!(
        dec.next_message(),
        Some(Ok(env.clone())),
        "what arrived first is kept"
    );
    assert!(matches!(
        dec.next_message(),
        Some(Err(Error::Oversized { .. }))
    ));
    assert!(dec.is_broken());
    assert_eq!(dec.next_message(), None);
}

#[test]
fn serial_decoder_survives_an_endless_frame() {
    let mut dec = SerialDecoder::new();
    dec.push(&vec![0x55; framing::MAX_SERIAL_FRAME_LEN + 10]);
    assert!(matches!(
        dec.next_message(),
        Some(Err(Error::Oversized { .. }))
    ));
    let env = &samples()[0];
    let mut frame = Vec::new();
    write_serial_frame(env, &mut frame).unwrap();
    dec.push(&frame);
    assert_eq!(dec.next_message(), Some(Ok(env.clone())));
}

#[test]
fn signed_region_covers_everything_but_the_tag() {
    let mut env = samples()[0].clone();
    env.auth = Some(AuthTag::from(vec![0xab; 32]));
    let bytes = encode(&env).unwrap();
    let region = signed_region(&bytes, &env).unwrap();
    assert_eq!(region.len(), bytes.len() - 34);
    assert_eq!(&bytes[region.len()..region.len() + 2], &[0xc4, 32]);
    env.auth = Some(AuthTag::from(vec![0; MAX_AUTH_LEN + 1]));
    assert!(matches!(encode(&env), Err(Error::Invalid(_))));
}

//! Golden bytes: decode(golden) == fixture and encode(fixture) == golden, with
//! every byte explained. A change here is a change of the wire protocol.

use mech_proto::framing::{SerialDecoder, StreamDecoder, write_serial_frame, write_stream_frame};
use mech_proto::{Body, Command, Echo, Envelope, Header, Heartbeat, Route, Twist, decode, encode};

fn header(sender: &str, destination: &str, channel: &str) -> Header {
    Header {
        seq: 7,
        stamp_us: 1_000_000,
        sender: sender.into(),
        destination: destination.into(),
        channel: channel.into(),
    }
}

fn heartbeat() -> Envelope {
    Envelope::new(
        header("robot_1", "router", ""),
        Body::Heartbeat(Heartbeat::new(1500)),
    )
}

#[rustfmt::skip]
const HEARTBEAT: &[u8] = &[
    0x99,                                     // fixarray, 9 elements: the envelope
    0x01,                                     // version 1
    0x03,                                     // kind 3 = Heartbeat
    0x07,                                     // seq 7
    0xce, 0x00, 0x0f, 0x42, 0x40,             // stamp_us: uint32 1_000_000
    0xa7, b'r', b'o', b'b', b'o', b't', b'_', b'1', // sender "robot_1"
    0xa6, b'r', b'o', b'u', b't', b'e', b'r', // destination "router"
    0xa0,                                     // channel "" (not a command)
    0x91,                                     // body: fixarray, 1 field
    0xcd, 0x05, 0xdc,                         //   uptime_ms: uint16 1500
    0xc0,                                     // auth: nil (unsigned)
];

/// A robot's heartbeat echoing router heartbeat 300, held 20 ms.
fn heartbeat_with_echo() -> Envelope {
    Envelope::new(
        header("robot_1", "router", ""),
        Body::Heartbeat(Heartbeat {
            uptime_ms: 1500,
            echo: Some(Echo {
                seq: 300,
                held_us: 20_000,
            }),
        }),
    )
}

#[rustfmt::skip]
const HEARTBEAT_WITH_ECHO: &[u8] = &[
    0x99,                                     // envelope, 9 elements
    0x01,                                     // version 1
    0x03,                                     // kind 3 = Heartbeat
    0x07,                                     // seq 7
    0xce, 0x00, 0x0f, 0x42, 0x40,             // stamp_us 1_000_000
    0xa7, b'r', b'o', b'b', b'o', b't', b'_', b'1', // sender "robot_1"
    0xa6, b'r', b'o', b'u', b't', b'e', b'r', // destination "router"
    0xa0,                                     // channel ""
    0x92,                                     // body: fixarray, 2 fields
    0xcd, 0x05, 0xdc,                         //   uptime_ms 1500
    0x92,                                     //   echo: fixarray, 2 fields
    0xcd, 0x01, 0x2c,                         //     seq: uint16 300
    0xcd, 0x4e, 0x20,                         //     held_us: uint16 20_000
    0xc0,                                     // auth: nil
];

fn twist() -> Envelope {
    Envelope::new(
        header("gcs", "robot_1", "joy/0"),
        Body::Command(Command::Twist(Twist {
            vx: 0.5,
            vy: 0.0,
            vz: 0.0,
            wz: -0.25,
        })),
    )
}

#[rustfmt::skip]
const TWIST: &[u8] = &[
    0x99,                                     // envelope, 9 elements
    0x01,                                     // version 1
    0x05,                                     // kind 5 = Command
    0x07,                                     // seq 7
    0xce, 0x00, 0x0f, 0x42, 0x40,             // stamp_us 1_000_000
    0xa3, b'g', b'c', b's',                   // sender "gcs"
    0xa7, b'r', b'o', b'b', b'o', b't', b'_', b'1', // destination "robot_1"
    0xa5, b'j', b'o', b'y', b'/', b'0',       // channel "joy/0"
    0x92,                                     // body: [command kind, payload]
    0x04,                                     //   command kind 4 = Twist
    0x94,                                     //   payload: fixarray, 4 fields
    0xcb, 0x3f, 0xe0, 0, 0, 0, 0, 0, 0,       //     vx  float64  0.5 m/s
    0xcb, 0, 0, 0, 0, 0, 0, 0, 0,             //     vy  float64  0.0 m/s
    0xcb, 0, 0, 0, 0, 0, 0, 0, 0,             //     vz  float64  0.0 m/s
    0xcb, 0xbf, 0xd0, 0, 0, 0, 0, 0, 0,       //     wz  float64 -0.25 rad/s
    0xc0,                                     // auth: nil
];

fn route() -> Envelope {
    Envelope::new(
        header("gcs", "robot_1", ""),
        Body::Route(Route {
            robot: "robot_1".into(),
            channel: "joy/0".into(),
            epoch: 3,
        }),
    )
}

#[rustfmt::skip]
const ROUTE: &[u8] = &[
    0x99,                                     // envelope, 9 elements
    0x01,                                     // version 1
    0x09,                                     // kind 9 = Route
    0x07,                                     // seq 7
    0xce, 0x00, 0x0f, 0x42, 0x40,             // stamp_us 1_000_000
    0xa3, b'g', b'c', b's',                   // sender "gcs"
    0xa7, b'r', b'o', b'b', b'o', b't', b'_', b'1', // destination "robot_1"
    0xa0,                                     // channel ""
    0x93,                                     // body: fixarray, 3 fields
    0xa7, b'r', b'o', b'b', b'o', b't', b'_', b'1', //   robot "robot_1"
    0xa5, b'j', b'o', b'y', b'/', b'0',       //   channel "joy/0"
    0x03,                                     //   epoch 3
    0xc0,                                     // auth: nil
];

#[test]
fn golden_messages_decode_to_fixtures() {
    assert_eq!(decode(HEARTBEAT), Ok(heartbeat()));
    assert_eq!(decode(TWIST), Ok(twist()));
    assert_eq!(decode(ROUTE), Ok(route()));
    assert_eq!(decode(HEARTBEAT_WITH_ECHO), Ok(heartbeat_with_echo()));
}

#[test]
fn fixtures_encode_to_golden_messages() {
    assert_eq!(encode(&heartbeat()).as_deref(), Ok(HEARTBEAT));
    assert_eq!(encode(&twist()).as_deref(), Ok(TWIST));
    assert_eq!(encode(&route()).as_deref(), Ok(ROUTE));
    assert_eq!(
        encode(&heartbeat_with_echo()).as_deref(),
        Ok(HEARTBEAT_WITH_ECHO)
    );
}

/// The echo was added at the end of the heartbeat: a heartbeat without one
/// is byte for byte what it was before (so a robot that does not know the
/// echo still reads the router's), and the old one-element heartbeat reads
/// as having no echo.
#[test]
fn a_heartbeat_without_an_echo_keeps_its_old_bytes() {
    let Body::Heartbeat(hb) = heartbeat().body else {
        unreachable!("the fixture is a heartbeat")
    };
    assert_eq!(hb.echo, None);
    assert_eq!(HEARTBEAT[HEARTBEAT.len() - 5], 0x91, "one field");
}

#[test]
fn golden_stream_frame_is_length_prefixed() {
    let mut frame = Vec::new();
    write_stream_frame(&heartbeat(), &mut frame).unwrap();
    // u32 big-endian length 30, then the message itself.
    assert_eq!(&frame[..4], &[0x00, 0x00, 0x00, HEARTBEAT.len() as u8]);
    assert_eq!(&frame[4..], HEARTBEAT);
    let mut dec = StreamDecoder::new();
    dec.push(&frame);
    assert_eq!(dec.next_message(), Some(Ok(heartbeat())));
    assert_eq!(dec.next_message(), None);
}

#[rustfmt::skip]
const HEARTBEAT_SERIAL: &[u8] = &[
    0x00,                                     // leading delimiter: flushes receiver garbage
    0x06,                                     // COBS code: 5 data bytes, then a zero
    0x99, 0x01, 0x03, 0x07, 0xce,             // envelope, version, kind, seq, uint32 marker
    0x1d,                                     // COBS code: 28 data bytes, no zero, end
    0x0f, 0x42, 0x40,                         // rest of stamp_us (its 0x00 became the code above)
    0xa7, b'r', b'o', b'b', b'o', b't', b'_', b'1', // sender
    0xa6, b'r', b'o', b'u', b't', b'e', b'r', // destination
    0xa0, 0x91, 0xcd, 0x05, 0xdc, 0xc0,       // channel, body, auth
    0x66, 0x4f, 0xfa, 0xbd,                   // CRC-32 (IEEE) of the message, little-endian
    0x00,                                     // frame delimiter
];

#[test]
fn golden_serial_frame_is_cobs_with_crc32() {
    let mut frame = Vec::new();
    write_serial_frame(&heartbeat(), &mut frame).unwrap();
    assert_eq!(frame, HEARTBEAT_SERIAL);
    assert_eq!(
        crc32_ieee(HEARTBEAT).to_le_bytes(),
        HEARTBEAT_SERIAL[HEARTBEAT_SERIAL.len() - 5..HEARTBEAT_SERIAL.len() - 1]
    );
    let mut dec = SerialDecoder::new();
    dec.push(HEARTBEAT_SERIAL);
    assert_eq!(dec.next_message(), Some(Ok(heartbeat())));
    assert_eq!(dec.next_message(), None);
}

/// Bitwise CRC-32/ISO-HDLC, written out so the test does not trust the
/// crate under test's own dependency.
fn crc32_ieee(data: &[u8]) -> u32 {
    let mut crc = 0xffff_ffffu32;
    for &b in data {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xedb8_8320
            } else {
                crc >> 1
            };
        }
    }
    !crc
}

#[test]
fn crc_reference_matches_known_check_value() {
    // The standard check value of CRC-32/ISO-HDLC for "123456789".
    assert_eq!(crc32_ieee(b"123456789"), 0xcbf4_3926);
}

#[test]
fn floats_may_arrive_as_float32_or_integers() {
    // Clients in other languages often shrink numbers: 0.5 as float32,
    // 0 as a positive fixint, -1 as a negative fixint.
    let mut bytes = TWIST[..TWIST.len() - 38].to_vec();
    #[rustfmt::skip]
    bytes.extend_from_slice(&[
        0x94,                               // payload, 4 fields
        0xca, 0x3f, 0x00, 0x00, 0x00,       // vx float32 0.5
        0x00,                               // vy 0
        0x00,                               // vz 0
        0xff,                               // wz -1
        0xc0,                               // auth nil
    ]);
    let env = decode(&bytes).unwrap();
    assert_eq!(
        env.body,
        Body::Command(Command::Twist(Twist {
            vx: 0.5,
            vy: 0.0,
            vz: 0.0,
            wz: -1.0
        }))
    );
}

/// The published test key of docs/protocol.md: secret bytes 0x00..0x1f.
/// Never use it for a real robot.
const TEST_SECRET: [u8; 32] = [
    0x00, 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, 0x07, 0x08, 0x09, 0x0a, 0x0b, 0x0c, 0x0d, 0x0e, 0x0f,
    0x10, 0x11, 0x12, 0x13, 0x14, 0x15, 0x16, 0x17, 0x18, 0x19, 0x1a, 0x1b, 0x1c, 0x1d, 0x1e, 0x1f,
];

/// The tag that replaces TWIST's final nil when `gcs` signs it with the
/// test key on link 0 at station time 1_700_000_000_000_000 µs (the MAC was
/// computed independently with Python's hmac and hashlib).
#[rustfmt::skip]
const TWIST_TAG: &[u8] = &[
    0xc4, 0x1d,                               // auth: bin 8, 29 bytes
    0x63, 0x0d, 0xcd, 0x29,                   //   key id: SHA-256(key)[0..4]
    0x00,                                     //   link 0, from a peer (bit 7 clear)
    0x00, 0x06, 0x0a, 0x24, 0x18, 0x1e, 0x40, 0x00, // stamp_us 1_700_000_000_000_000
    0x6b, 0x31, 0x24, 0xbf, 0xaf, 0x0d, 0x4c, 0x91, // MAC: HMAC-SHA-256(key,
    0x43, 0x2e, 0x88, 0xac, 0xb7, 0xe5, 0x43, 0x86, //   region || id || link || stamp)[0..16]
];

#[test]
fn the_signed_twist_matches_the_documented_bytes() {
    use mech_proto::auth::{Key, split};
    let key = Key::new(&TEST_SECRET);
    assert_eq!(key.id(), 0x630d_cd29);
    let mut signed = TWIST.to_vec();
    key.seal(&mut signed, 0, 1_700_000_000_000_000).unwrap();
    let mut expected = TWIST[..TWIST.len() - 1].to_vec();
    expected.extend_from_slice(TWIST_TAG);
    assert_eq!(signed, expected);
    let (region, tag) = split(&signed).unwrap();
    assert!(key.verify(region, &tag.unwrap()));
    // A signed message still decodes to the same envelope, with its tag.
    let env = decode(&signed).unwrap();
    assert_eq!((env.header, env.body), (twist().header, twist().body));
    assert_eq!(
        env.auth.map(|a| a.into_vec()),
        Some(TWIST_TAG[2..].to_vec())
    );
}

#[rustfmt::skip]
const AUTOPILOT_TAKEOFF: &[u8] = &[
    0x99,                                     // envelope, 9 elements
    0x01,                                     // version 1
    0x16,                                     // kind 22 = Autopilot
    0x07,                                     // seq 7
    0xce, 0x00, 0x0f, 0x42, 0x40,             // stamp_us 1_000_000
    0xa3, b'g', b'c', b's',                   // sender "gcs" (an operator)
    0xa6, b'r', b'o', b'u', b't', b'e', b'r', // destination "router"
    0xa0,                                     // channel "" (not a command)
    0x93,                                     // body: fixarray, 3 fields
    0xa7, b'r', b'o', b'b', b'o', b't', b'_', b'1', //   robot "robot_1"
    0x05,                                     //   action 5 = takeoff
    0xcb, 0x40, 0x04, 0, 0, 0, 0, 0, 0,       //   altitude float64 2.5 m
    0xc0,                                     // auth: nil
];

#[test]
fn an_autopilot_request_has_the_documented_bytes() {
    use mech_proto::{AutopilotAction, AutopilotRequest};
    let takeoff = Envelope::new(
        header("gcs", "router", ""),
        Body::Autopilot(AutopilotRequest {
            robot: "robot_1".into(),
            action: AutopilotAction::Takeoff,
            altitude: 2.5,
        }),
    );
    assert_eq!(encode(&takeoff).as_deref(), Ok(AUTOPILOT_TAKEOFF));
    assert_eq!(decode(AUTOPILOT_TAKEOFF), Ok(takeoff));
    // A takeoff to no height, and an unknown action, are refused.
    let mut flat = AUTOPILOT_TAKEOFF.to_vec();
    flat[31..39].copy_from_slice(&0.0f64.to_be_bytes());
    assert!(decode(&flat).is_err());
    let mut unknown = AUTOPILOT_TAKEOFF.to_vec();
    unknown[29] = 0x06;
    assert!(decode(&unknown).is_err());
}

#[rustfmt::skip]
const ARENA_ACK: &[u8] = &[
    0x99,                                     // envelope, 9 elements
    0x01,                                     // version 1
    0x18,                                     // kind 24 = ArenaAck
    0x07,                                     // seq 7
    0xce, 0x00, 0x0f, 0x42, 0x40,             // stamp_us 1_000_000
    0xa7, b'r', b'o', b'b', b'o', b't', b'_', b'1', // sender "robot_1"
    0xa6, b'r', b'o', b'u', b't', b'e', b'r', // destination "router"
    0xa0,                                     // channel ""
    0x92,                                     // body: fixarray, 2 fields
    0xa7, b'r', b'o', b'b', b'o', b't', b'_', b'1', //   robot "robot_1"
    0xcd, 0x01, 0x2c,                         //   id: uint16 300
    0xc0,                                     // auth: nil
];

#[rustfmt::skip]
const ARENA_TRIANGLE: &[u8] = &[
    0x99,                                     // envelope, 9 elements
    0x01,                                     // version 1
    0x17,                                     // kind 23 = Arena
    0x07,                                     // seq 7
    0xce, 0x00, 0x0f, 0x42, 0x40,             // stamp_us 1_000_000
    0xa6, b'r', b'o', b'u', b't', b'e', b'r', // sender "router"
    0xa7, b'r', b'o', b'b', b'o', b't', b'_', b'1', // destination "robot_1"
    0xa0,                                     // channel ""
    0x97,                                     // body: fixarray, 7 fields
    0xa7, b'r', b'o', b'b', b'o', b't', b'_', b'1', //   robot "robot_1"
    0x02,                                     //   id 2
    0xc3,                                     //   enabled: true
    0x93,                                     //   boundary: 3 points
    0x92, 0xcb, 0, 0, 0, 0, 0, 0, 0, 0,       //     [x 0.0,
          0xcb, 0, 0, 0, 0, 0, 0, 0, 0,       //      y 0.0]
    0x92, 0xcb, 0x40, 0x10, 0, 0, 0, 0, 0, 0, //     [x 4.0,
          0xcb, 0, 0, 0, 0, 0, 0, 0, 0,       //      y 0.0]
    0x92, 0xcb, 0, 0, 0, 0, 0, 0, 0, 0,       //     [x 0.0,
          0xcb, 0x40, 0x08, 0, 0, 0, 0, 0, 0, //      y 3.0]
    0x90,                                     //   keep_out: none
    0x90,                                     //   slow_zones: none
    0xcb, 0x3f, 0xb9, 0x99, 0x99, 0x99, 0x99, 0x99, 0x9a, // margin 0.1 m
    0xc0,                                     // auth: nil
];

#[test]
fn arena_messages_have_the_documented_bytes() {
    use mech_proto::{Arena, ArenaAck, Point};
    let ack = Envelope::new(
        header("robot_1", "router", ""),
        Body::ArenaAck(ArenaAck {
            robot: "robot_1".into(),
            id: 300,
        }),
    );
    assert_eq!(encode(&ack).as_deref(), Ok(ARENA_ACK));
    assert_eq!(decode(ARENA_ACK), Ok(ack));
    let p = |x, y| Point { x, y };
    let arena = Envelope::new(
        header("router", "robot_1", ""),
        Body::Arena(Arena {
            robot: "robot_1".into(),
            id: 2,
            enabled: true,
            boundary: vec![p(0.0, 0.0), p(4.0, 0.0), p(0.0, 3.0)],
            keep_out: vec![],
            slow_zones: vec![],
            margin: 0.1,
        }),
    );
    assert_eq!(encode(&arena).as_deref(), Ok(ARENA_TRIANGLE));
    assert_eq!(decode(ARENA_TRIANGLE), Ok(arena));
    // Two points make no boundary: refused on decode.
    let mut short = ARENA_TRIANGLE.to_vec();
    let at = short.iter().position(|b| *b == 0x93).unwrap();
    short[at] = 0x92;
    short.drain(at + 1 + 2 * 19..at + 1 + 3 * 19);
    assert!(decode(&short).is_err());
}

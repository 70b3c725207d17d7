//! Encode/decode cost of a command and a telemetry message, and of the
//! header-only peek the router uses.

use criterion::{Criterion, criterion_group, criterion_main};
use mech_proto::{
    Body, Command, Computation, ControlMode, Envelope, FailsafeState, Header, Health,
    MissionProgress, Pose, Telemetry, Twist, Velocity, decode, encode, peek,
};
use std::hint::black_box;

fn header(channel: &str) -> Header {
    Header {
        seq: 123_456,
        stamp_us: 1_795_000_000_000_000,
        sender: "robot_1".into(),
        destination: "router".into(),
        channel: channel.into(),
    }
}

fn bench(c: &mut Criterion) {
    let command = Envelope::new(
        header("joy/0"),
        Body::Command(Command::Twist(Twist {
            vx: 0.5,
            vy: 0.0,
            vz: 0.0,
            wz: -0.25,
        })),
    );
    let telemetry = Envelope::new(
        header(""),
        Body::Telemetry(Telemetry {
            pose: Pose {
                x: 1.25,
                y: -3.5,
                z: 0.0,
                heading: 1.2,
            },
            velocity: Velocity {
                vx: 0.3,
                vy: 0.1,
                vz: 0.0,
                wz: 0.05,
            },
            mode: ControlMode::Waypoints,
            channel: "wp/gcs".into(),
            computation: Computation::Onboard,
            failsafe: FailsafeState::Ok,
            health: Health::Ok,
            battery: Some(0.82),
            position_quality: 0.9,
            actuators: vec![0.4, 0.45],
            mission: Some(MissionProgress {
                id: 7,
                next: 2,
                total: 5,
            }),
            stale: 0,
            velocity_source: mech_proto::VelocitySource::Measured,
            safety: None,
        }),
    );
    for (name, env) in [("command", &command), ("telemetry", &telemetry)] {
        let bytes = encode(env).expect("encodes");
        println!("{name}: {} bytes", bytes.len());
        let mut buf = Vec::with_capacity(256);
        c.bench_function(&format!("encode {name}"), |b| {
            b.iter(|| {
                buf.clear();
                mech_proto::encode_into(black_box(env), &mut buf).expect("encodes");
            })
        });
        c.bench_function(&format!("decode {name}"), |b| {
            b.iter(|| decode(black_box(&bytes)).expect("decodes"))
        });
        c.bench_function(&format!("peek {name}"), |b| {
            b.iter(|| peek(black_box(&bytes)).expect("peeks").seq)
        });
    }
}

criterion_group!(benches, bench);
criterion_main!(benches);

//! What a signed command costs the router, and what other MACs would.
//!
//! The router checks the controller's tag on every signed command and signs
//! the robot's copy under the robot's key: two MACs per command forwarded,
//! each over the command (75-80 bytes) and the tag's 13-byte header. This
//! measures them as `mech_proto::auth::Key` does them (HMAC-SHA-256, the
//! keyed state made once per key and cloned per message; the `sha2` crate
//! uses the CPU's SHA instructions when it has them), and, over the same
//! bytes, keyed BLAKE3 (with the CPU's vector instructions) and AES-CMAC
//! with a 256-bit and a 128-bit key (the keyed state likewise made once,
//! the CPU's AES instructions used), the usual candidates for a cheaper MAC.

use criterion::{Criterion, criterion_group, criterion_main};
use mech_proto::auth::{Key, Tag, split};
use mech_proto::{Body, Command, Envelope, Header, Twist, encode};
use std::hint::black_box;

fn command() -> Vec<u8> {
    let env = Envelope::new(
        Header {
            seq: 123_456,
            stamp_us: 1_795_000_000_000_000,
            sender: "pad".into(),
            destination: "robot_1".into(),
            channel: "joy/0".into(),
        },
        Body::Command(Command::Twist(Twist {
            vx: 0.5,
            vy: 0.0,
            vz: 0.0,
            wz: -0.25,
        })),
    );
    encode(&env).expect("encodes")
}

fn bench(c: &mut Criterion) {
    let secret = [7u8; 32];
    let key = Key::new(&secret);
    let unsigned = command();
    let mut sealed = unsigned.clone();
    key.seal(&mut sealed, 0, 1_795_000_000_000_000)
        .expect("seals");
    let (region, tag) = split(&sealed).expect("splits");
    let tag: Tag = tag.expect("signed");
    // What each MAC covers: the region and the tag's header.
    let mut covered = region.to_vec();
    covered.extend_from_slice(&key.sign(region, 0, 1)[..13]);
    println!(
        "command: {} bytes unsigned, {} signed; each MAC covers {} bytes",
        unsigned.len(),
        sealed.len(),
        covered.len()
    );

    c.bench_function(
        "HMAC-SHA-256 sign (as the router signs a robot's copy)",
        |b| b.iter(|| key.sign(black_box(region), 0, black_box(1_795_000_000_000_001))),
    );
    c.bench_function(
        "HMAC-SHA-256 verify (as the router checks a command)",
        |b| b.iter(|| assert!(key.verify(black_box(region), black_box(&tag)))),
    );
    c.bench_function("keyed BLAKE3 over the same bytes", |b| {
        b.iter(|| blake3::keyed_hash(&secret, black_box(&covered)))
    });
    let aes256 = <cmac::Cmac<aes::Aes256> as cmac::Mac>::new_from_slice(&secret).expect("keyed");
    c.bench_function("AES-256-CMAC over the same bytes", |b| {
        b.iter(|| cmac_of(&aes256, black_box(&covered)))
    });
    let aes128 =
        <cmac::Cmac<aes::Aes128> as cmac::Mac>::new_from_slice(&secret[..16]).expect("keyed");
    c.bench_function("AES-128-CMAC over the same bytes", |b| {
        b.iter(|| cmac_of(&aes128, black_box(&covered)))
    });
}

/// The CMAC of `bytes` from a keyed state (16 bytes, as a tag's MAC).
fn cmac_of<M: cmac::Mac + Clone>(keyed: &M, bytes: &[u8]) -> [u8; 16] {
    let mut m = keyed.clone();
    m.update(bytes);
    let mut tag = [0u8; 16];
    tag.copy_from_slice(&m.finalize().into_bytes()[..16]);
    tag
}

criterion_group!(benches, bench);
criterion_main!(benches);

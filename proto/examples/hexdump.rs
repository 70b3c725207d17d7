//! Prints the encoding of a few messages in hex (used to write golden tests
//! and the examples in docs/protocol.md).
use mech_proto::*;
fn main() {
    let h = Header { seq: 7, stamp_us: 1_000_000, sender: "gcs".into(), destination: "robot_1".into(), channel: "joy/0".into() };
    let msgs = [
        Envelope::new(Header { channel: String::new(), destination: "router".into(), sender: "robot_1".into(), ..h.clone() }, Body::Heartbeat(Heartbeat { uptime_ms: 1500 })),
        Envelope::new(h.clone(), Body::Command(Command::Twist(Twist { vx: 0.5, vy: 0.0, vz: 0.0, wz: -0.25 }))),
        Envelope::new(Header { channel: String::new(), ..h.clone() }, Body::Route(Route { robot: "robot_1".into(), channel: "joy/0".into(), epoch: 3 })),
    ];
    for m in &msgs {
        let b = encode(m).unwrap();
        println!("{}: {}", m.body.name(), b.iter().map(|x| format!("{x:02x}")).collect::<Vec<_>>().join(" "));
        assert_eq!(&decode(&b).unwrap(), m);
    }
}

//! Any bytes: decoding never panics; whatever decodes re-encodes to a message
//! that decodes to the same value; the stream and serial decoders never panic.
#![no_main]

use libfuzzer_sys::fuzz_target;
use mech_proto::framing::{SerialDecoder, StreamDecoder};

fuzz_target!(|data: &[u8]| {
    let _ = mech_proto::peek(data);
    if let Ok(env) = mech_proto::decode(data) {
        // A peer may send float32 or wider integer encodings; re-encoding
        // as float64 can grow a message past the size limit, nothing else.
        match mech_proto::encode(&env) {
            Ok(bytes) => {
                assert_eq!(mech_proto::decode(&bytes).expect("re-encoded message decodes"), env)
            }
            Err(e) => assert_eq!(e.kind(), mech_proto::ErrorKind::Oversized, "{e}"),
        }
    }
    let mut stream = StreamDecoder::new();
    stream.push(data);
    while stream.next_frame().is_some() {}
    let mut serial = SerialDecoder::new();
    serial.push(data);
    while serial.next_message().is_some() {}
});

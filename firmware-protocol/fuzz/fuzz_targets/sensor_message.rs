//! Sensor-link message decoder behind the CRC: mutated payloads almost never pass the CRC in
//! `sensor_frame`, so this target feeds `Frame::decode` directly (input = type, seq, payload).
//! A decoded message must re-encode to the same type, seq and payload.
#![no_main]
use bytes::BytesMut;
use firmware_protocol::Frame;
use firmware_protocol::frame::{self, RawFrame};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let [msg_type, seq, payload @ ..] = data else {
        return;
    };
    if payload.len() > frame::MAX_PAYLOAD {
        return;
    }
    let raw = RawFrame {
        msg_type: *msg_type,
        seq: *seq,
        payload,
    };
    if let Ok(decoded) = Frame::decode(raw) {
        let mut out = BytesMut::new();
        decoded.encode(&mut out);
        assert_eq!(
            frame::parse(&out),
            Ok(raw),
            "re-encoding changed the message"
        );
    }
});

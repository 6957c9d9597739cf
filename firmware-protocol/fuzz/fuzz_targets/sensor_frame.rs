//! Binary frame parser + message decoder: no panic; a decoded frame re-encodes byte for byte.
#![no_main]
use bytes::BytesMut;
use firmware_protocol::{Frame, frame};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(raw) = frame::parse(data) {
        if let Ok(decoded) = Frame::decode(raw) {
            let mut out = BytesMut::new();
            decoded.encode(&mut out);
            assert_eq!(&out[..], data, "re-encoding changed the frame");
        }
    }
});

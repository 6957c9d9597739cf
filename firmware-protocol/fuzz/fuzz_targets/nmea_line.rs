//! NMEA line parser: no panic; a decoded sentence re-encodes and parses to the same value.
#![no_main]
use bytes::BytesMut;
use firmware_protocol::nmea;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(sentence) = nmea::parse_line(data) {
        let mut out = BytesMut::new();
        sentence
            .encode(&mut out)
            .expect("a decoded sentence re-encodes");
        assert_eq!(nmea::parse_line(&out), Ok(sentence));
    }
});

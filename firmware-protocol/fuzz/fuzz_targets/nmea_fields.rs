//! NMEA field decoder behind the checksum: mutated lines almost never keep a valid checksum in
//! `nmea_line`, so this target feeds `nmea::parse_body` (the text between `$` and `*`)
//! directly. A decoded sentence must re-encode and decode to the same value.
#![no_main]
use bytes::BytesMut;
use firmware_protocol::nmea;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if let Ok(sentence) = nmea::parse_body(data) {
        let mut out = BytesMut::new();
        sentence
            .encode(&mut out)
            .expect("a decoded sentence re-encodes");
        assert_eq!(nmea::parse_line(&out), Ok(sentence));
    }
});

//! Sonar select/ack parser: no panic; a decoded command re-encodes byte for byte.
#![no_main]
use bytes::BytesMut;
use firmware_protocol::sonar_link;
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    if data.first() == Some(&b'@') {
        let _ = sonar_link::scan_command(data);
    }
    if let Ok(cmd) = sonar_link::parse_command(data) {
        let mut out = BytesMut::new();
        cmd.encode(&mut out);
        assert_eq!(&out[..], data);
    }
});

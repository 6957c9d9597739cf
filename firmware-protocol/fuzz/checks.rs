//! The properties the fuzz targets check, as plain functions: `fuzz_targets/*.rs` call them
//! under libFuzzer, and `../tests/fuzz_corpora.rs` calls them on every committed corpus file
//! (`corpora/<target>/`), so CI replays the corpora as ordinary tests.

use bytes::BytesMut;
use firmware_protocol::frame::{self, RawFrame};
use firmware_protocol::{
    Frame, HeadingFormat, HeadingWord, LineDecoder, LineItem, nmea, sonar_link,
};

/// Shared-line stream decoder: the same items whatever the chunking (first input byte =
/// chunk size), everything consumed at EOF, every decoded message re-encodes to bytes that
/// decode to it.
pub fn line_decoder(data: &[u8]) {
    let Some((&chunk, bytes)) = data.split_first() else {
        return;
    };
    let whole = LineDecoder::decode_all(bytes);

    let chunk = usize::from(chunk).max(1);
    let mut decoder = LineDecoder::new();
    let mut buf = BytesMut::new();
    let mut chunked = Vec::new();
    for piece in bytes.chunks(chunk) {
        buf.extend_from_slice(piece);
        while let Some(item) = decoder.decode(&mut buf) {
            chunked.push(item);
        }
    }
    while let Some(item) = decoder.decode_eof(&mut buf) {
        chunked.push(item);
    }
    assert!(buf.is_empty(), "decode_eof left bytes behind");
    assert_eq!(whole, chunked, "items depend on chunking");

    for item in whole {
        if matches!(item, LineItem::Error(_)) {
            continue;
        }
        let mut out = BytesMut::new();
        item.encode(&mut out).expect("a decoded message re-encodes");
        let again = LineDecoder::decode_all(&out);
        assert_eq!(again, vec![item], "re-encoded message decodes differently");
    }
}

/// NMEA line parser: a decoded sentence re-encodes and parses to the same value.
pub fn nmea_line(data: &[u8]) {
    if let Ok(sentence) = nmea::parse_line(data) {
        let mut out = BytesMut::new();
        sentence
            .encode(&mut out)
            .expect("a decoded sentence re-encodes");
        assert_eq!(nmea::parse_line(&out), Ok(sentence));
    }
}

/// NMEA field decoder behind the checksum (input = the text between `$` and `*`).
pub fn nmea_fields(data: &[u8]) {
    if let Ok(sentence) = nmea::parse_body(data) {
        let mut out = BytesMut::new();
        sentence
            .encode(&mut out)
            .expect("a decoded sentence re-encodes");
        assert_eq!(nmea::parse_line(&out), Ok(sentence));
    }
}

/// Binary frame parser + message decoder: a decoded frame re-encodes byte for byte.
pub fn sensor_frame(data: &[u8]) {
    if let Ok(raw) = frame::parse(data)
        && let Ok(decoded) = Frame::decode(raw)
    {
        let mut out = BytesMut::new();
        decoded.encode(&mut out);
        assert_eq!(&out[..], data, "re-encoding changed the frame");
    }
}

/// Sensor-link message decoder behind the CRC (input = type, seq, payload): a decoded
/// message re-encodes to the same type, seq and payload.
pub fn sensor_message(data: &[u8]) {
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
}

/// Sonar select/ack parser: a decoded command re-encodes byte for byte.
pub fn sonar_command(data: &[u8]) {
    if data.first() == Some(&b'@') {
        let _ = sonar_link::scan_command(data);
    }
    if let Ok(cmd) = sonar_link::parse_command(data) {
        let mut out = BytesMut::new();
        cmd.encode(&mut out);
        assert_eq!(&out[..], data);
    }
}

/// Vector 2X heading word decoder (the first two input bytes, big-endian; shorter inputs are
/// skipped): an accepted word
/// re-encodes to itself.
pub fn compass_word(data: &[u8]) {
    let [a, b, ..] = data else {
        return;
    };
    let word = HeadingWord(u16::from_be_bytes([*a, *b]));
    for format in [HeadingFormat::Binary, HeadingFormat::Bcd] {
        if let Ok(heading) = word.decode(format) {
            assert_eq!(HeadingWord::encode(heading, format), Ok(word));
        }
    }
}

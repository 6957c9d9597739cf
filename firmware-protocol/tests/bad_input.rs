//! Hostile and damaged input: each case checks the reported error and that the next good
//! message is still found.

mod common;

use bytes::BytesMut;
use firmware_protocol::sensor_link::Message;
use firmware_protocol::{
    Dbt, Frame, FrameError, LineDecoder, LineItem, LinkError, MessageError, NmeaError, Sentence,
    SentenceError, SonarCommandError, Talker,
};

fn good_frame() -> (Vec<u8>, LineItem) {
    let f = Frame::new(
        9,
        Message::TimeAdvance {
            ticks: 0x24_24_24_24,
        },
    );
    let mut b = BytesMut::new();
    f.encode(&mut b);
    (b.to_vec(), LineItem::Frame(f))
}

fn good_sentence() -> (Vec<u8>, LineItem) {
    let s = Sentence::Dbt(Dbt::from_depth_m(Talker::SOUNDER, 2.0).unwrap());
    let mut b = BytesMut::new();
    s.encode(&mut b).unwrap();
    (b.to_vec(), LineItem::Nmea(s))
}

fn cat(parts: &[&[u8]]) -> Vec<u8> {
    parts.concat()
}

fn err(e: impl Into<LinkError>) -> LineItem {
    LineItem::Error(e.into())
}

#[test]
fn pure_garbage_is_one_skipped_item() {
    let items = LineDecoder::decode_all(b"hello world \x00\x01\xff");
    assert_eq!(items, vec![err(LinkError::Skipped { count: 15 })]);
}

#[test]
fn line_endings_between_messages_are_not_garbage() {
    let (s, item) = good_sentence();
    assert_eq!(
        LineDecoder::decode_all(&cat(&[b"\r\n\r\n", &s, b"\n"])),
        vec![item]
    );
}

#[test]
fn dollar_inside_binary_payload_is_payload() {
    // TimeAdvance{0x24242424} has four '$' bytes in its payload.
    let (f, item) = good_frame();
    assert!(f.iter().filter(|&&b| b == b'$').count() >= 4);
    assert_eq!(LineDecoder::decode_all(&f), vec![item]);
}

#[test]
fn sync_bytes_inside_garbage_do_not_hide_the_next_frame() {
    let (f, item) = good_frame();
    let bytes = cat(&[b"\xEB\xEB\x90\x41\x00\x04", &f]);
    let items = LineDecoder::decode_all(&bytes);
    // EB EB: first EB is garbage (not followed by 90); EB 90 41 00 04 + 6 bytes of the real
    // frame fail the CRC; rescanning one byte at a time finds the real frame.
    assert!(matches!(
        items[1],
        LineItem::Error(LinkError::Frame(FrameError::ChecksumMismatch { .. }))
    ));
    assert_eq!(items.last(), Some(&item));
}

#[test]
fn corrupt_crc_reports_both_values_and_recovers() {
    let (mut f, item) = good_frame();
    let n = f.len();
    f[n - 1] ^= 0xFF;
    let items = LineDecoder::decode_all(&cat(&[&f, &good_frame().0]));
    let LineItem::Error(LinkError::Frame(FrameError::ChecksumMismatch {
        calculated,
        found,
        msg_type,
        seq,
    })) = items[0]
    else {
        panic!("expected a checksum mismatch, got {:?}", items[0]);
    };
    assert_eq!(found, calculated ^ 0x00FF);
    assert_eq!((msg_type, seq), (0x41, 9));
    assert_eq!(items.last(), Some(&item));
}

#[test]
fn over_long_length_byte_is_rejected_and_rescanned() {
    let (f, item) = good_frame();
    let items = LineDecoder::decode_all(&cat(&[&[0xEB, 0x90, 0x10, 0x00, 0xC8], &f]));
    assert_eq!(
        items[0],
        err(FrameError::LengthTooLong { len: 200, max: 64 })
    );
    assert_eq!(items[1], err(LinkError::Skipped { count: 4 }));
    assert_eq!(items[2], item);
}

#[test]
fn truncated_frame_at_end_of_stream() {
    let (f, item) = good_frame();
    let items = LineDecoder::decode_all(&cat(&[&f, &f[..7]]));
    assert_eq!(
        items,
        vec![item, err(FrameError::Truncated { have: 7, need: 11 })]
    );
}

#[test]
fn truncated_frame_followed_by_a_good_one_is_resolved_by_the_crc() {
    let (f, item) = good_frame();
    let items = LineDecoder::decode_all(&cat(&[&f[..6], &f, &f]));
    assert!(matches!(
        items[0],
        LineItem::Error(LinkError::Frame(FrameError::ChecksumMismatch { .. }))
    ));
    assert_eq!(items.iter().filter(|i| **i == item).count(), 2, "{items:?}");
}

#[test]
fn unknown_type_with_good_crc_consumes_the_frame() {
    let mut b = BytesMut::new();
    firmware_protocol::frame::encode(0x77, 3, b"$GP@", &mut b).unwrap();
    let (f, item) = good_frame();
    b.extend_from_slice(&f);
    assert_eq!(
        LineDecoder::decode_all(&b),
        vec![
            err(MessageError::UnknownType {
                msg_type: 0x77,
                seq: 3
            }),
            item
        ]
    );
}

#[test]
fn wrong_nmea_checksum_names_both_values() {
    let (s, item) = good_sentence();
    let mut bad = s.clone();
    let star = bad.iter().position(|&b| b == b'*').unwrap();
    bad[star + 1] = if bad[star + 1] == b'0' { b'1' } else { b'0' };
    let items = LineDecoder::decode_all(&cat(&[&bad, &s]));
    assert!(matches!(
        items[0],
        LineItem::Error(LinkError::Nmea(NmeaError::ChecksumMismatch { .. }))
    ));
    assert_eq!(items[1], item);
}

#[test]
fn missing_checksum_is_reported() {
    let items = LineDecoder::decode_all(b"$SDDBT,1.0,f,0.3,M,0.2,F\r\n");
    assert_eq!(items, vec![err(NmeaError::MissingChecksum)]);
}

#[test]
fn over_long_line_is_dropped_and_next_sentence_found() {
    let (s, item) = good_sentence();
    let mut long = b"$SDDBT,".to_vec();
    long.extend(std::iter::repeat_n(b'1', 100));
    long.extend_from_slice(b"\r\n");
    let items = LineDecoder::decode_all(&cat(&[&long, &s]));
    assert_eq!(items[0], err(NmeaError::TooLong { max: 82 }));
    assert_eq!(items[1], err(LinkError::Skipped { count: 106 }));
    assert_eq!(items[2], item);
}

#[test]
fn control_byte_inside_a_field_is_reported_with_offset() {
    let (s, item) = good_sentence();
    let items = LineDecoder::decode_all(&cat(&[b"$SDDBT,1\x07.0,f,,M,,F*00\r\n", &s]));
    assert_eq!(
        items[0],
        err(NmeaError::InvalidByte {
            byte: 0x07,
            offset: 8
        })
    );
    assert_eq!(items.last(), Some(&item));
}

#[test]
fn sync_byte_inside_a_sentence_starts_a_frame() {
    let (f, item) = good_frame();
    let items = LineDecoder::decode_all(&cat(&[b"$SDDBT,1.0", &f]));
    assert_eq!(
        items,
        vec![
            err(NmeaError::InvalidByte {
                byte: 0xEB,
                offset: 10
            }),
            err(LinkError::Skipped { count: 9 }),
            item
        ]
    );
}

#[test]
fn new_dollar_interrupts_a_partial_line() {
    let (s, item) = good_sentence();
    let items = LineDecoder::decode_all(&cat(&[b"$SDDBT,1.", &s]));
    assert_eq!(items, vec![err(NmeaError::Interrupted { len: 9 }), item]);
}

#[test]
fn cr_without_lf_is_a_bad_terminator() {
    let (s, item) = good_sentence();
    let items = LineDecoder::decode_all(&cat(&[b"$SDDBT,,f,,M,,F*28\rX", &s]));
    assert_eq!(items[0], err(NmeaError::BadTerminator { offset: 18 }));
    assert_eq!(items.last(), Some(&item));
}

#[test]
fn bad_fields_with_good_checksum_are_sentence_errors() {
    for (body, want) in [
        (
            "SDDBT,1.0,f,0.3,M,0.2",
            SentenceError::FieldCount {
                expected: 6,
                found: 5,
            },
        ),
        (
            "SDDBT,1.0,x,0.3,M,0.2,F",
            SentenceError::BadField {
                index: 1,
                expected: "unit letter",
            },
        ),
        (
            "SDDBT,1.00,f,0.3,M,0.2,F",
            SentenceError::BadField {
                index: 0,
                expected: "empty or d.d",
            },
        ),
        (
            "SDDBT,-1.0,f,0.3,M,0.2,F",
            SentenceError::BadField {
                index: 0,
                expected: "empty or d.d",
            },
        ),
        ("sdDBT,1.0,f,0.3,M,0.2,F", SentenceError::BadAddress),
        (
            "PEBHS,5,1.0,50",
            SentenceError::BadField {
                index: 0,
                expected: "transducer digit 1..4",
            },
        ),
        (
            "PEBHS,1,1.0,101",
            SentenceError::BadField {
                index: 2,
                expected: "quality 0..100",
            },
        ),
    ] {
        let sum = body.bytes().fold(0u8, |a, b| a ^ b);
        let line = format!("${body}*{sum:02X}\r\n");
        assert_eq!(
            LineDecoder::decode_all(line.as_bytes()),
            vec![err(want)],
            "{line:?}"
        );
    }
    let items = LineDecoder::decode_all(b"$GPGGA,,,,,,0,,,,,,,,*66\r\n");
    assert!(matches!(
        items[0],
        LineItem::Error(LinkError::Sentence(SentenceError::Unsupported { .. }))
    ));
}

#[test]
fn sonar_command_errors() {
    assert_eq!(
        LineDecoder::decode_all(b"@S9\r"),
        vec![err(SonarCommandError::BadTransducer { byte: b'9' })]
    );
    assert_eq!(
        LineDecoder::decode_all(b"@X"),
        vec![
            err(SonarCommandError::UnknownCommand { byte: b'X' }),
            err(LinkError::Skipped { count: 1 })
        ]
    );
    assert_eq!(
        LineDecoder::decode_all(b"@S"),
        vec![err(SonarCommandError::Truncated { have: 2 })]
    );
    // Missing CR: the '@' is dropped and the 'S1' that follows is garbage; the next select is found.
    let items = LineDecoder::decode_all(b"@S1@S1\r");
    assert_eq!(
        items[0],
        err(SonarCommandError::BadTerminator {
            offset: 3,
            byte: b'@'
        })
    );
    assert_eq!(items[1], err(LinkError::Skipped { count: 2 }));
    assert!(matches!(items[2], LineItem::Sonar(_)));
}

#[test]
fn truncated_sentence_at_end_of_stream() {
    assert_eq!(
        LineDecoder::decode_all(b"$SDDBT,1.0"),
        vec![err(NmeaError::Truncated { have: 10 })]
    );
}

//! Sensor-link messages against PROTOCOL.md: round trips, lengths, values.

use super::*;

fn roundtrip(message: Message) -> Frame {
    let mut buf = BytesMut::new();
    Frame::new(0x42, message).encode(&mut buf);
    let raw = frame::parse(&buf).unwrap();
    Frame::decode(raw).unwrap()
}

#[test]
fn adc_value_is_big_endian_with_top_bits_zero() {
    let msg = Message::AdcValue {
        channel: AdcChannel::new(3).unwrap(),
        value: AdcValue::new(0x03FF).unwrap(),
    };
    let mut buf = BytesMut::new();
    Frame::new(1, msg).encode(&mut buf);
    assert_eq!(&buf[5..8], &[0x03, 0x03, 0xFF]);
    assert_eq!(roundtrip(msg).message, msg);
}

#[test]
fn channel_nine_is_api_misuse() {
    assert_eq!(
        AdcChannel::new(9),
        Err(EncodeError::AdcChannelOutOfRange { channel: 9 })
    );
    assert_eq!(
        AdcValue::new(1024),
        Err(EncodeError::AdcValueOutOfRange { value: 1024 })
    );
}

#[test]
fn wire_channel_nine_is_bad_value_item() {
    let mut buf = BytesMut::new();
    frame::encode(msg_type::ADC_READ, 5, &[9], &mut buf).unwrap();
    let raw = frame::parse(&buf).unwrap();
    assert_eq!(
        Frame::decode(raw),
        Err(MessageError::BadValue {
            msg_type: msg_type::ADC_READ,
            seq: 5,
            offset: 0,
            value: 9
        })
    );
}

/// NAK mapping of PROTOCOL.md section 3: channel 9 gives BAD_VALUE at offset 0 with the
/// request's seq (the `nak` example), garbage gives no answer.
#[test]
fn nak_for_wire_errors_follows_the_table() {
    let e = LinkError::Message(MessageError::BadValue {
        msg_type: 0x10,
        seq: 0x11,
        offset: 0,
        value: 9,
    });
    assert_eq!(
        Frame::nak_for(&e),
        Some(Frame::new(
            0x11,
            Message::Nak {
                rejected_type: 0x10,
                code: ErrorCode::BadValue,
                detail: 0
            }
        ))
    );
    let e = LinkError::Message(MessageError::BadLength {
        msg_type: 0x10,
        seq: 1,
        expected: 1,
        found: 2,
    });
    assert!(matches!(
        Frame::nak_for(&e),
        Some(Frame {
            message: Message::Nak {
                code: ErrorCode::BadLength,
                detail: 1,
                ..
            },
            ..
        })
    ));
    let e = LinkError::Frame(FrameError::ChecksumMismatch {
        calculated: 1,
        found: 2,
        msg_type: 0x41,
        seq: 3,
    });
    assert!(matches!(
        Frame::nak_for(&e),
        Some(Frame {
            seq: 3,
            message: Message::Nak {
                code: ErrorCode::BadCrc,
                ..
            }
        })
    ));
    assert_eq!(Frame::nak_for(&LinkError::Skipped { count: 3 }), None);
    assert_eq!(
        Frame::nak_for(&LinkError::Frame(FrameError::LengthTooLong {
            len: 99,
            max: 64
        })),
        None
    );
}

#[test]
fn adc_samples_length_follows_mask() {
    let mut buf = BytesMut::new();
    // mask 0b101 needs 2 values (4 bytes) but only one is present.
    frame::encode(
        msg_type::ADC_SAMPLES,
        0,
        &[0, 0, 0, 1, 0b101, 0x01, 0x00],
        &mut buf,
    )
    .unwrap();
    let raw = frame::parse(&buf).unwrap();
    assert!(matches!(
        Frame::decode(raw),
        Err(MessageError::BadLength {
            expected: 9,
            found: 7,
            ..
        })
    ));
}

fn decode_raw(t: u8, payload: &[u8]) -> Result<Frame, MessageError> {
    let mut buf = BytesMut::new();
    frame::encode(t, 7, payload, &mut buf).unwrap();
    Frame::decode(frame::parse(&buf).unwrap())
}

/// TIME_STEP's length depends on its flags and its readings (PROTOCOL.md 2.9); bad flag
/// bits, directions and reading codes are BAD_VALUE at their offsets.
#[test]
fn time_step_lengths_and_values_are_checked() {
    let bad_len = |expected| move |r: Result<Frame, MessageError>| matches!(r, Err(MessageError::BadLength { expected: e, .. }) if e == expected);
    let bad_value = |offset| move |r: Result<Frame, MessageError>| matches!(r, Err(MessageError::BadValue { offset: o, .. }) if o == offset);
    let t = msg_type::TIME_STEP;
    assert!(bad_len(6)(decode_raw(t, &[0])));
    assert!(bad_len(6)(decode_raw(t, &[0, 0, 0, 0, 1])));
    // thrusters announced but missing
    assert!(bad_len(14)(decode_raw(t, &[0, 1, 0, 0, 0, 1, 0xFF, 0])));
    // 17 readings
    let mut long = vec![0, 0, 0, 0, 0, 1];
    long.extend([0u8; 17]);
    assert!(bad_len(22)(decode_raw(t, &long)));
    assert!(bad_value(1)(decode_raw(t, &[0, 0x04, 0, 0, 0, 1])));
    assert!(bad_value(6)(decode_raw(t, &[0, 0, 0, 0, 0, 1, 0x08])));
    // starboard's direction byte (payload offset 9) is 2
    assert!(bad_value(9)(decode_raw(
        t,
        &[0, 1, 0, 0, 0, 1, 0, 0, 0, 2, 0, 0, 0, 0]
    )));
    let ok = decode_raw(t, &[2, 0, 0, 0, 0, 1, 0x21, 0x07]).unwrap();
    assert_eq!(
        ok.message,
        Message::TimeStep {
            used: 2,
            stop_on_sonar: false,
            ticks: 1,
            thrusters: None,
            readings: Readings::new([Reading::Compass, Reading::Adc(AdcChannel::new(7).unwrap())])
                .unwrap(),
        }
    );
    // STEP: 6 bytes, then whole u16 values
    assert!(bad_len(6)(decode_raw(
        msg_type::STEP,
        &[0, 0, 0, 1, 0, 0, 1]
    )));
    assert!(Readings::new([Reading::Compass; 17]).is_err());
}

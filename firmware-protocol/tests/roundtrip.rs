//! Property tests: every message, sentence and command survives encode -> decode, alone and
//! between other messages and garbage.

use bytes::BytesMut;
use firmware_protocol::nmea::Tenths;
use firmware_protocol::sensor_link::{
    AdcChannel, AdcSamples, AdcValue, CalibrationAction, CalibrationState, CompassMode,
    CompassOutput, Counters, Direction, ErrorCode, MAX_READINGS, Message, Reading, Readings,
    StepValues, Thruster, ThrusterCommand, TimeMode,
};
use firmware_protocol::{
    Dbt, Dpt, EchoReport, Frame, HeadingWord, LineDecoder, LineItem, LinkError, Sentence,
    SonarCommand, Talker, Transducer,
};
use proptest::prelude::*;

fn channel() -> impl Strategy<Value = AdcChannel> {
    (0u8..8).prop_map(|c| AdcChannel::new(c).unwrap())
}
fn adc_value() -> impl Strategy<Value = AdcValue> {
    (0u16..1024).prop_map(|v| AdcValue::new(v).unwrap())
}
fn command() -> impl Strategy<Value = ThrusterCommand> {
    (any::<u8>(), any::<bool>()).prop_map(|(duty, rev)| ThrusterCommand {
        duty,
        direction: if rev {
            Direction::Reverse
        } else {
            Direction::Forward
        },
    })
}
fn heading_word() -> impl Strategy<Value = HeadingWord> {
    (0u16..0x0400).prop_map(HeadingWord)
}

fn message() -> impl Strategy<Value = Message> {
    prop_oneof![
        any::<u8>().prop_map(|client_version| Message::Hello { client_version }),
        Just(Message::CountersGet),
        channel().prop_map(|channel| Message::AdcRead { channel }),
        (any::<u8>(), 1u16..).prop_map(|(channels, period_ms)| Message::AdcStream {
            channels,
            period_ms
        }),
        Just(Message::AdcStream {
            channels: 0,
            period_ms: 0
        }),
        (0u8..2, 0u8..3).prop_map(|(m, o)| Message::CompassMode {
            mode: [CompassMode::Poll, CompassMode::Continuous][usize::from(m)],
            output: [
                CompassOutput::Binary,
                CompassOutput::Bcd,
                CompassOutput::Raw
            ][usize::from(o)],
        }),
        Just(Message::CompassRead),
        (0u8..4).prop_map(|a| Message::CompassCalibrate {
            action: [
                CalibrationAction::Start,
                CalibrationAction::TakePoint,
                CalibrationAction::Finish,
                CalibrationAction::Clear
            ][usize::from(a)],
        }),
        Just(Message::CompassReset),
        (0u8..4, command()).prop_map(|(i, command)| Message::ThrusterSet {
            thruster: Thruster::from_index(i).unwrap(),
            command
        }),
        [command(), command(), command(), command()]
            .prop_map(|commands| Message::ThrusterSetAll { commands }),
        Just(Message::TimeGet),
        any::<u32>().prop_map(|ticks| Message::TimeAdvance { ticks }),
        any::<bool>().prop_map(|l| Message::TimeMode {
            mode: if l {
                TimeMode::Lockstep
            } else {
                TimeMode::RealTime
            }
        }),
        any::<u8>().prop_map(|acked_type| Message::Ack { acked_type }),
        (any::<u8>(), any::<u16>(), any::<u32>(), any::<u8>()).prop_map(
            |(protocol_version, capabilities, tick_us, max_payload)| {
                Message::HelloReply {
                    protocol_version,
                    capabilities,
                    tick_us,
                    max_payload,
                }
            }
        ),
        any::<[u32; 7]>().prop_map(|c| Message::Counters(Counters {
            rx_frames: c[0],
            rx_crc_errors: c[1],
            rx_framing_errors: c[2],
            rx_skipped_bytes: c[3],
            rx_rejected: c[4],
            tx_frames: c[5],
            tx_naks: c[6],
        })),
        (channel(), adc_value()).prop_map(|(channel, value)| Message::AdcValue { channel, value }),
        heading_word().prop_map(|word| Message::CompassHeading { word }),
        (any::<i16>(), any::<i16>()).prop_map(|(x, y)| Message::CompassRaw { x, y }),
        (0u8..3, 0u8..3).prop_map(|(s, points)| Message::CalibrationStatus {
            state: [
                CalibrationState::Idle,
                CalibrationState::Collecting,
                CalibrationState::ReadyToFinish
            ][usize::from(s)],
            points,
        }),
        (any::<u32>(), any::<u32>()).prop_map(|(ticks, tick_us)| Message::Time { ticks, tick_us }),
        (any::<u8>(), any::<u8>(), any::<u8>()).prop_map(|(rejected_type, code, detail)| {
            Message::Nak {
                rejected_type,
                code: ErrorCode::from_u8(code),
                detail,
            }
        }),
        (
            any::<u32>(),
            proptest::collection::vec((channel(), adc_value()), 1..8)
        )
            .prop_map(|(ticks, pairs)| Message::AdcSamples {
                ticks,
                samples: AdcSamples::new(pairs)
            }),
        heading_word().prop_map(|word| Message::CompassHeadingPush { word }),
        (any::<i16>(), any::<i16>()).prop_map(|(x, y)| Message::CompassRawPush { x, y }),
        (
            any::<u8>(),
            any::<bool>(),
            any::<u32>(),
            proptest::option::of(proptest::array::uniform4(command())),
            proptest::collection::vec(
                prop_oneof![channel().prop_map(Reading::Adc), Just(Reading::Compass)],
                0..=MAX_READINGS
            )
        )
            .prop_map(|(used, stop_on_sonar, ticks, thrusters, readings)| {
                Message::TimeStep {
                    used,
                    stop_on_sonar,
                    ticks,
                    thrusters,
                    readings: Readings::new(readings).unwrap(),
                }
            }),
        (
            any::<u32>(),
            any::<u16>(),
            proptest::collection::vec(any::<u16>(), 0..=MAX_READINGS)
        )
            .prop_map(|(ticks, sonar_bytes, values)| Message::Step {
                ticks,
                sonar_bytes,
                values: StepValues::new(values).unwrap(),
            }),
    ]
}

fn talker() -> impl Strategy<Value = Talker> {
    "[A-Z]{2}".prop_map(|s| Talker::new(&s).unwrap())
}
fn tenths(min: i32) -> impl Strategy<Value = Option<Tenths>> {
    proptest::option::of((min..=Tenths::MAX).prop_map(|t| Tenths::from_tenths(t).unwrap()))
}

fn sentence() -> impl Strategy<Value = Sentence> {
    prop_oneof![
        (talker(), tenths(0), tenths(0), tenths(0)).prop_map(|(talker, feet, metres, fathoms)| {
            Sentence::Dbt(Dbt {
                talker,
                feet,
                metres,
                fathoms,
            })
        }),
        (talker(), 0.0..2000.0f64)
            .prop_map(|(talker, d)| Sentence::Dbt(Dbt::from_depth_m(talker, d).unwrap())),
        (
            talker(),
            tenths(0),
            tenths(-Tenths::MAX),
            proptest::option::of(tenths(0))
        )
            .prop_map(
                |(talker, depth_m, offset_m, max_range_m)| Sentence::Dpt(Dpt {
                    talker,
                    depth_m,
                    offset_m,
                    max_range_m
                })
            ),
        (1u8..=4, tenths(0), 0u8..=100).prop_map(|(t, range_m, quality_pct)| Sentence::Echo(
            EchoReport {
                transducer: Transducer::new(t).unwrap(),
                range_m,
                quality_pct,
            }
        )),
    ]
}

fn sonar_command() -> impl Strategy<Value = SonarCommand> {
    prop_oneof![
        (1u8..=4).prop_map(|t| SonarCommand::Select(Transducer::new(t).unwrap())),
        (1u8..=4).prop_map(|t| SonarCommand::Ack(Transducer::new(t).unwrap())),
        Just(SonarCommand::Nak),
    ]
}

fn item() -> impl Strategy<Value = LineItem> {
    prop_oneof![
        (any::<u8>(), message()).prop_map(|(seq, m)| LineItem::Frame(Frame::new(seq, m))),
        sentence().prop_map(LineItem::Nmea),
        sonar_command().prop_map(LineItem::Sonar),
    ]
}

fn encode(item: &LineItem) -> Vec<u8> {
    let mut b = BytesMut::new();
    assert!(item.encode(&mut b).unwrap());
    b.to_vec()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(2000))]

    #[test]
    fn every_message_round_trips(seq in any::<u8>(), m in message()) {
        let item = LineItem::Frame(Frame::new(seq, m));
        prop_assert_eq!(LineDecoder::decode_all(&encode(&item)), vec![item]);
    }

    #[test]
    fn every_sentence_round_trips_within_82_characters(s in sentence()) {
        let item = LineItem::Nmea(s);
        let bytes = encode(&item);
        prop_assert!(bytes.len() <= 82);
        prop_assert_eq!(LineDecoder::decode_all(&bytes), vec![item]);
    }

    #[test]
    fn every_sonar_command_round_trips(c in sonar_command()) {
        let item = LineItem::Sonar(c);
        prop_assert_eq!(LineDecoder::decode_all(&encode(&item)), vec![item]);
    }

    /// A mixed stream with garbage runs (bytes that start nothing) between messages decodes
    /// to the messages, each preceded by one Skipped item for its garbage run.
    #[test]
    fn mixed_stream_with_garbage_runs(
        parts in proptest::collection::vec(
            (proptest::collection::vec(any::<u8>().prop_filter("not a start byte", |b| !matches!(b, b'$' | b'@' | 0xEB | b'\r' | b'\n')), 0..6), item()),
            1..12),
        chunk in 1usize..40,
    ) {
        let mut bytes = Vec::new();
        let mut expected = Vec::new();
        for (garbage, item) in &parts {
            bytes.extend_from_slice(garbage);
            if !garbage.is_empty() {
                expected.push(LineItem::Error(LinkError::Skipped { count: garbage.len() }));
            }
            bytes.extend_from_slice(&encode(item));
            expected.push(item.clone());
        }
        let mut decoder = LineDecoder::new();
        let mut buf = BytesMut::new();
        let mut got = Vec::new();
        for piece in bytes.chunks(chunk) {
            buf.extend_from_slice(piece);
            while let Some(i) = decoder.decode(&mut buf) {
                got.push(i);
            }
        }
        while let Some(i) = decoder.decode_eof(&mut buf) {
            got.push(i);
        }
        prop_assert_eq!(got, expected);
    }

    /// Arbitrary bytes never panic, always get consumed, and do not depend on chunking.
    #[test]
    fn arbitrary_bytes_are_chunk_invariant(bytes in proptest::collection::vec(any::<u8>(), 0..300), chunk in 1usize..50) {
        let whole = LineDecoder::decode_all(&bytes);
        let mut decoder = LineDecoder::new();
        let mut buf = BytesMut::new();
        let mut got = Vec::new();
        for piece in bytes.chunks(chunk) {
            buf.extend_from_slice(piece);
            while let Some(i) = decoder.decode(&mut buf) {
                got.push(i);
            }
        }
        while let Some(i) = decoder.decode_eof(&mut buf) {
            got.push(i);
        }
        prop_assert!(buf.is_empty());
        prop_assert_eq!(got, whole);
    }
}

//! The sensor board against the sensor-link protocol: replies, pushes, retries, time.

use firmware_protocol::sensor_link::{
    AdcValue, CalibrationAction, CalibrationState, Direction, Thruster,
};
use firmware_protocol::{HeadingFormat, HeadingWord};

use super::*;
use crate::devices::fake::FakePlant;

const MS: u64 = 1_000_000;

fn board(lockstep: bool, watchdog_ms: Option<u64>) -> SensorBoard {
    SensorBoard::new(BoardSettings {
        tick_ns: 10 * MS,
        lockstep,
        compass_period_ns: 400 * MS,
        line_chars_per_s: 11_520.0,
        watchdog_ns: watchdog_ms.map(|m| m * MS),
        sonar_on_this_line: false,
    })
}

fn sent(out: Option<Output>) -> Frame {
    match out {
        Some(Output::Send(frame)) => frame,
        other => panic!("expected a frame, got {other:?}"),
    }
}

#[test]
fn adc_read_answers_with_the_plant_code_and_the_request_seq() {
    let mut plant = FakePlant {
        adc: [0, 0, 0, 0x2AB, 0, 0, 0, 0],
        ..FakePlant::default()
    };
    let mut b = board(false, None);
    let channel = AdcChannel::new(3).unwrap();
    let reply = sent(b.handle(Frame::new(7, Message::AdcRead { channel }), 0, &mut plant));
    assert_eq!(reply.seq, 7);
    assert_eq!(
        reply.message,
        Message::AdcValue {
            channel,
            value: AdcValue::new(0x2AB).unwrap()
        }
    );
}

#[test]
fn adc_stream_pushes_chosen_channels_every_period_until_stopped() {
    let mut plant = FakePlant {
        adc: [1, 2, 3, 4, 5, 6, 7, 8],
        ..FakePlant::default()
    };
    let mut b = board(false, None);
    let ack = sent(b.handle(
        Frame::new(
            1,
            Message::AdcStream {
                channels: 0b0000_0101,
                period_ms: 10,
            },
        ),
        0,
        &mut plant,
    ));
    assert_eq!(
        ack.message,
        Message::Ack {
            acked_type: msg_type::ADC_STREAM
        }
    );
    let mut out = Vec::new();
    b.poll(35 * MS, &mut plant, &mut out);
    let times: Vec<_> = out.iter().map(|(t, _)| *t).collect();
    assert_eq!(times, vec![10 * MS, 20 * MS, 30 * MS]);
    let Message::AdcSamples { ticks, samples } = out[0].1.message else {
        panic!("not samples")
    };
    assert_eq!(ticks, 1);
    assert_eq!(samples.mask(), 0b101);
    assert_eq!(
        samples.get(AdcChannel::new(2).unwrap()),
        Some(AdcValue::new(3).unwrap())
    );
    assert_ne!(
        out[0].1.seq, out[1].1.seq,
        "pushes carry their own sequence"
    );
    b.handle(
        Frame::new(
            2,
            Message::AdcStream {
                channels: 0,
                period_ms: 0,
            },
        ),
        35 * MS,
        &mut plant,
    );
    assert_eq!(b.poll_timeout(), None);
}

#[test]
fn compass_read_answers_at_once_with_the_latest_measurement() {
    let mut plant = FakePlant {
        heading_deg: 271,
        ..FakePlant::default()
    };
    let mut b = board(false, None);
    let reply = sent(b.handle(Frame::new(9, Message::CompassRead), 100 * MS, &mut plant));
    assert_eq!(reply.seq, 9);
    assert_eq!(
        reply.message,
        Message::CompassHeading {
            word: HeadingWord::encode(271, HeadingFormat::Binary).unwrap()
        }
    );
    assert_eq!(plant.compass_reads, vec![100 * MS]);
}

/// A retried request (same seq, type and payload) is answered again but not executed
/// again: a lost TIME reply must not make the client's OSWait advance time twice.
#[test]
fn retried_requests_are_not_executed_twice() {
    let mut plant = FakePlant::default();
    let mut b = board(true, None);
    let cal = |seq, action| Frame::new(seq, Message::CompassCalibrate { action });
    sent(b.handle(cal(1, CalibrationAction::Start), 0, &mut plant));
    let first = sent(b.handle(cal(2, CalibrationAction::TakePoint), 0, &mut plant));
    let retry = sent(b.handle(cal(2, CalibrationAction::TakePoint), 0, &mut plant));
    assert_eq!(first, retry);
    assert_eq!(
        plant.calibration_points, 1,
        "the retry took no second point"
    );
    assert_eq!(b.duplicates(), 1);
    // A new seq is a new request, even with the same payload.
    sent(b.handle(cal(3, CalibrationAction::TakePoint), 0, &mut plant));
    assert_eq!(plant.calibration_points, 2);

    let advance = Frame::new(4, Message::TimeAdvance { ticks: 5 });
    assert!(matches!(
        b.handle(advance, 0, &mut plant),
        Some(Output::Advance { .. })
    ));
    let time = b.finish_advance(4, 50 * MS);
    assert_eq!(
        b.handle(advance, 50 * MS, &mut plant),
        Some(Output::Send(time)),
        "no second advance"
    );
}

#[test]
fn hello_starts_a_clean_session() {
    let mut plant = FakePlant::default();
    let mut b = board(false, None);
    let full = ThrusterCommand {
        duty: 0,
        direction: Direction::Forward,
    };
    sent(b.handle(
        Frame::new(
            1,
            Message::ThrusterSetAll {
                commands: [full; 4],
            },
        ),
        0,
        &mut plant,
    ));
    sent(b.handle(
        Frame::new(
            2,
            Message::AdcStream {
                channels: 1,
                period_ms: 10,
            },
        ),
        0,
        &mut plant,
    ));
    let reply = sent(b.handle(
        Frame::new(3, Message::Hello { client_version: 1 }),
        5 * MS,
        &mut plant,
    ));
    assert!(matches!(
        reply.message,
        Message::HelloReply {
            protocol_version: 1,
            ..
        }
    ));
    assert_eq!(b.thrusters(), [ThrusterCommand::OFF; 4]);
    assert_eq!(plant.thrusters.last().unwrap().1, [ThrusterCommand::OFF; 4]);
    assert_eq!(b.poll_timeout(), None, "the stream stopped");
    let old = sent(b.handle(
        Frame::new(3, Message::Hello { client_version: 9 }),
        5 * MS,
        &mut plant,
    ));
    assert!(matches!(
        old.message,
        Message::Nak {
            code: ErrorCode::VersionMismatch,
            detail: 1,
            ..
        }
    ));
}

#[test]
fn a_stream_that_would_fill_the_line_is_refused() {
    let mut plant = FakePlant::default();
    let mut slow = SensorBoard::new(BoardSettings {
        line_chars_per_s: 480.0,
        ..board(false, None).settings
    });
    let nak = sent(slow.handle(
        Frame::new(
            1,
            Message::AdcStream {
                channels: 0xFF,
                period_ms: 10,
            },
        ),
        0,
        &mut plant,
    ));
    assert!(matches!(
        nak.message,
        Message::Nak {
            code: ErrorCode::BadValue,
            detail: 1,
            ..
        }
    ));
}

#[test]
fn continuous_bcd_compass_pushes_at_its_rate() {
    let mut plant = FakePlant {
        heading_deg: 123,
        ..FakePlant::default()
    };
    let mut b = board(false, None);
    b.handle(
        Frame::new(
            1,
            Message::CompassMode {
                mode: CompassMode::Continuous,
                output: CompassOutput::Bcd,
            },
        ),
        0,
        &mut plant,
    );
    let mut out = Vec::new();
    b.poll(1000 * MS, &mut plant, &mut out);
    assert_eq!(out.len(), 2, "2.5 Hz: pushes at 400 and 800 ms");
    assert_eq!(
        out[0].1.message,
        Message::CompassHeadingPush {
            word: HeadingWord(0x0123)
        }
    );
}

#[test]
fn calibration_steps_follow_the_plant_and_bad_steps_are_naked() {
    let mut plant = FakePlant::default();
    let mut b = board(false, None);
    let mut seq = 0u8;
    let mut cal = |action| {
        seq += 1;
        Frame::new(seq, Message::CompassCalibrate { action })
    };
    let finish_early = sent(b.handle(cal(CalibrationAction::Finish), 0, &mut plant));
    assert!(matches!(
        finish_early.message,
        Message::Nak {
            code: ErrorCode::BadState,
            ..
        }
    ));
    sent(b.handle(cal(CalibrationAction::Start), 0, &mut plant));
    sent(b.handle(cal(CalibrationAction::TakePoint), 0, &mut plant));
    let ready = sent(b.handle(cal(CalibrationAction::TakePoint), 0, &mut plant));
    assert_eq!(
        ready.message,
        Message::CalibrationStatus {
            state: CalibrationState::ReadyToFinish,
            points: 2
        }
    );
    let done = sent(b.handle(cal(CalibrationAction::Finish), 0, &mut plant));
    assert_eq!(
        done.message,
        Message::CalibrationStatus {
            state: CalibrationState::Idle,
            points: 0
        }
    );
}

#[test]
fn thruster_frames_reach_the_plant_and_the_watchdog_zeroes_them() {
    let mut plant = FakePlant::default();
    let mut b = board(false, Some(500));
    let full = ThrusterCommand {
        duty: 0,
        direction: Direction::Forward,
    };
    sent(b.handle(
        Frame::new(
            1,
            Message::ThrusterSet {
                thruster: Thruster::Stern,
                command: full,
            },
        ),
        100 * MS,
        &mut plant,
    ));
    assert_eq!(plant.thrusters.last().unwrap().1[3], full);
    assert_eq!(b.poll_timeout(), Some(600 * MS));
    let mut out = Vec::new();
    b.poll(599 * MS, &mut plant, &mut out);
    assert_eq!(b.watchdog_trips(), 0);
    b.poll(600 * MS, &mut plant, &mut out);
    assert_eq!(b.watchdog_trips(), 1);
    assert_eq!(
        plant.thrusters.last().unwrap(),
        &(600 * MS, [ThrusterCommand::OFF; 4])
    );
    assert!(out.is_empty(), "the watchdog sends nothing on the wire");
}

#[test]
fn lockstep_advance_is_carried_out_by_the_core_and_answered_with_time() {
    let mut plant = FakePlant::default();
    let mut realtime = board(false, None);
    let refused = sent(realtime.handle(
        Frame::new(3, Message::TimeAdvance { ticks: 5 }),
        0,
        &mut plant,
    ));
    assert!(matches!(
        refused.message,
        Message::Nak {
            code: ErrorCode::BadState,
            ..
        }
    ));

    let mut b = board(true, None);
    let out = b.handle(
        Frame::new(3, Message::TimeAdvance { ticks: 5 }),
        20 * MS,
        &mut plant,
    );
    assert_eq!(
        out,
        Some(Output::Advance {
            to: 70 * MS,
            seq: 3
        })
    );
    let time = b.finish_advance(3, 70 * MS);
    assert_eq!(time.seq, 3);
    assert_eq!(
        time.message,
        Message::Time {
            ticks: 7,
            tick_us: 10_000
        }
    );
}

#[test]
fn wire_errors_are_counted_and_naked_when_the_header_is_trustworthy() {
    let mut b = board(false, None);
    let bad_len = LinkError::Message(MessageError::BadLength {
        msg_type: msg_type::ADC_READ,
        seq: 12,
        expected: 1,
        found: 3,
    });
    let nak = sent(b.handle_error(&bad_len));
    assert_eq!(nak.seq, 12);
    assert_eq!(
        nak.message,
        Message::Nak {
            rejected_type: msg_type::ADC_READ,
            code: ErrorCode::BadLength,
            detail: 1
        }
    );
    let crc = LinkError::Frame(FrameError::ChecksumMismatch {
        calculated: 1,
        found: 2,
        msg_type: 0x10,
        seq: 1,
    });
    let advisory = sent(b.handle_error(&crc));
    assert!(matches!(
        advisory.message,
        Message::Nak {
            code: ErrorCode::BadCrc,
            rejected_type: 0x10,
            ..
        }
    ));
    assert_eq!(advisory.seq, 1);
    assert_eq!(b.counters().rx_crc_errors, 1);
    assert_eq!(b.counters().rx_rejected, 1);
    assert_eq!(b.counters().tx_naks, 2);
}

/// PROTOCOL.md: the bridge never NAKs a NAK (whole, damaged or mis-sized), and a reply or
/// push type sent to it gets UNKNOWN_TYPE whatever its size.
#[test]
fn naks_are_never_naked_and_reply_types_are_unknown() {
    let mut b = board(false, None);
    let nak_len = LinkError::Message(MessageError::BadLength {
        msg_type: msg_type::NAK,
        seq: 3,
        expected: 3,
        found: 1,
    });
    assert!(b.handle_error(&nak_len).is_none());
    let nak_crc = LinkError::Frame(FrameError::ChecksumMismatch {
        calculated: 1,
        found: 2,
        msg_type: msg_type::NAK,
        seq: 4,
    });
    assert!(b.handle_error(&nak_crc).is_none());
    let nak = Frame::new(
        5,
        Message::Nak {
            rejected_type: msg_type::HELLO,
            code: ErrorCode::BadCrc,
            detail: 0,
        },
    );
    assert!(b.handle(nak, 0, &mut FakePlant::default()).is_none());
    assert_eq!(b.counters().tx_naks, 0);
    assert_eq!(b.counters().rx_rejected, 2);
    for (reply_type, error) in [
        (
            msg_type::COUNTERS,
            MessageError::BadLength {
                msg_type: msg_type::COUNTERS,
                seq: 6,
                expected: 40,
                found: 0,
            },
        ),
        (
            msg_type::ADC_VALUE,
            MessageError::BadValue {
                msg_type: msg_type::ADC_VALUE,
                seq: 6,
                offset: 0,
                value: 0xFF,
            },
        ),
    ] {
        let out = sent(b.handle_error(&LinkError::Message(error)));
        assert_eq!(
            out.message,
            Message::Nak {
                rejected_type: reply_type,
                code: ErrorCode::UnknownType,
                detail: 0
            }
        );
    }
}

/// PROTOCOL.md 2.4: a frame with a good CRC is "received OK" only when it gets its reply;
/// one answered with any NAK (BAD_STATE and VERSION_MISMATCH included), or a NAK sent to
/// the bridge, is "rejected". A retry answered from the stored reply counts again.
#[test]
fn a_nak_counts_the_frame_as_rejected_not_received() {
    let mut plant = FakePlant::default();
    let mut b = board(false, None);
    let counts = |b: &SensorBoard| {
        let c = b.counters();
        (c.rx_frames, c.rx_rejected, c.tx_frames, c.tx_naks)
    };
    sent(b.handle(Frame::new(1, Message::TimeGet), 0, &mut plant));
    assert_eq!(counts(&b), (1, 0, 1, 0), "a TIME_GET is received OK");
    let advance = Frame::new(2, Message::TimeAdvance { ticks: 5 });
    let nak = sent(b.handle(advance, 0, &mut plant));
    assert!(matches!(
        nak.message,
        Message::Nak {
            code: ErrorCode::BadState,
            ..
        }
    ));
    assert_eq!(counts(&b), (1, 1, 2, 1), "BAD_STATE is a rejection");
    let again = sent(b.handle(advance, 0, &mut plant));
    assert_eq!(again, nak, "the retry gets the stored NAK");
    assert_eq!(counts(&b), (1, 2, 3, 2), "and counts as a rejection again");
    let hello = Frame::new(3, Message::Hello { client_version: 2 });
    let mismatch = sent(b.handle(hello, 0, &mut plant));
    assert!(matches!(
        mismatch.message,
        Message::Nak {
            code: ErrorCode::VersionMismatch,
            detail: 1,
            ..
        }
    ));
    assert_eq!(counts(&b), (1, 3, 4, 3), "VERSION_MISMATCH is a rejection");
    let stray_reply = Frame::new(4, Message::Ack { acked_type: 0x10 });
    sent(b.handle(stray_reply, 0, &mut plant));
    assert_eq!(counts(&b), (1, 4, 5, 4), "a reply type is a rejection");
    let stray_nak = Frame::new(
        5,
        Message::Nak {
            rejected_type: 0x10,
            code: ErrorCode::BadValue,
            detail: 0,
        },
    );
    assert!(b.handle(stray_nak, 0, &mut plant).is_none());
    assert_eq!(counts(&b), (1, 5, 5, 4), "a NAK is rejected, not answered");
    let stream = Frame::new(
        6,
        Message::AdcStream {
            channels: 1,
            period_ms: 0,
        },
    );
    sent(b.handle(stream, 0, &mut plant));
    assert_eq!(
        counts(&b),
        (1, 6, 6, 5),
        "BAD_VALUE from the board is a rejection"
    );
}

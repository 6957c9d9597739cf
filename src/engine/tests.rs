//! The engine on a scripted model: ordering, pacing, lockstep time and the feed.

use firmware_protocol::sensor_link::{AdcChannel, Message};
use firmware_protocol::sonar_link::SonarCommand;
use firmware_protocol::{Frame, Transducer};

use super::fake::FakeModel;
use super::*;
use crate::devices::multiplexer::{DepthSentence, InvalidEcho, MultiplexerSettings};
use crate::devices::sensor_board::BoardSettings;

const MS: u64 = 1_000_000;

fn core(lockstep: bool, shared: bool) -> Engine<FakeModel> {
    let board = SensorBoard::new(BoardSettings {
        tick_ns: 10 * MS,
        lockstep,
        compass_period_ns: 400 * MS,
        line_chars_per_s: 11_520.0,
        watchdog_ns: None,
        sonar_on_this_line: shared,
    });
    let mux = Multiplexer::new(MultiplexerSettings {
        sentence: DepthSentence::Dbt,
        talker: firmware_protocol::Talker::SOUNDER,
        invalid_echo: InvalidEcho::Omit,
        proprietary: false,
    });
    let lines = if shared {
        vec![LineSpec {
            name: "shared",
            carries: Carries::SHARED,
            settings: LineSettings::n81(115_200),
            tx_queue_bytes: 4096,
            release_quantum_ns: MS,
        }]
    } else {
        vec![
            LineSpec {
                name: "sonar",
                carries: Carries::SONAR,
                settings: LineSettings::n81(4800),
                tx_queue_bytes: 4096,
                release_quantum_ns: MS,
            },
            LineSpec {
                name: "sensor",
                carries: Carries::SENSOR,
                settings: LineSettings::n81(115_200),
                tx_queue_bytes: 4096,
                release_quantum_ns: MS,
            },
        ]
    };
    Engine::new(FakeModel::default(), board, mux, &lines, lockstep)
}

fn frame_bytes(seq: u8, message: Message) -> Vec<u8> {
    let mut buf = BytesMut::new();
    Frame::new(seq, message).encode(&mut buf);
    buf.to_vec()
}

/// An ADC_READ of `channel`.
fn adc_read(seq: u8, channel: u8) -> Vec<u8> {
    let channel = AdcChannel::new(channel).expect("a test's channel is 0-7");
    frame_bytes(seq, Message::AdcRead { channel })
}

/// An ADC_STREAM of the `channels` mask every 10 ms.
fn adc_stream(seq: u8, channels: u8) -> Vec<u8> {
    frame_bytes(
        seq,
        Message::AdcStream {
            channels,
            period_ms: 10,
        },
    )
}

fn decode(bytes: &[u8]) -> Vec<LineItem> {
    LineDecoder::decode_all(bytes)
}

#[test]
fn realtime_replies_wait_for_their_wire_time() {
    let mut c = core(false, false);
    let read = adc_read(5, 1);
    c.receive(1, &read).unwrap();
    assert_eq!(c.take_output(1), None, "no byte before one character time");
    // The reply (9 bytes) takes 9 x 86.8 us at 115200 baud.
    c.advance_to(c.next_deadline().unwrap()).unwrap();
    c.advance_to(MS).unwrap();
    let out = c.take_output(1).unwrap();
    let items = decode(&out);
    assert!(
        matches!(&items[..], [LineItem::Frame(f)] if f.seq == 5),
        "{items:?}"
    );
}

#[test]
fn lockstep_advance_releases_stream_samples_before_the_time_reply() {
    let mut c = core(true, false);
    c.receive(1, &adc_stream(1, 0b1)).unwrap();
    let ack = c
        .take_output(1)
        .expect("a lockstep reply is released at once");
    assert_eq!(decode(&ack).len(), 1);
    c.receive(1, &frame_bytes(2, Message::TimeAdvance { ticks: 5 }))
        .unwrap();
    let out = c.take_output(1).unwrap();
    let items = decode(&out);
    // Samples at 10..=40 ms are complete by 50 ms; the one due at 50 ms is still on the
    // wire, and the TIME reply follows it.
    let kinds: Vec<u8> = items
        .iter()
        .map(|i| match i {
            LineItem::Frame(f) => f.message.msg_type(),
            other => panic!("{other:?}"),
        })
        .collect();
    use firmware_protocol::sensor_link::msg_type::{ADC_SAMPLES, TIME};
    assert_eq!(
        kinds,
        vec![
            ADC_SAMPLES,
            ADC_SAMPLES,
            ADC_SAMPLES,
            ADC_SAMPLES,
            ADC_SAMPLES,
            TIME
        ]
    );
    assert_eq!(c.now(), 50 * MS);
}

/// Regression: within one advance nothing left the pacer until the end, so a lockstep
/// TIME_ADVANCE of 4 s with a 100 Hz stream queued 400 samples against the 4 KiB
/// transmit queue and dropped most of them, although the line had time for all.
#[test]
fn a_long_lockstep_advance_delivers_every_stream_sample() {
    let mut c = core(true, false);
    c.receive(1, &adc_stream(1, 0xFF)).unwrap();
    let _ack = c.take_output(1);
    c.receive(1, &frame_bytes(2, Message::TimeAdvance { ticks: 400 }))
        .unwrap();
    let items = decode(&c.take_output(1).unwrap());
    let samples = items
        .iter()
        .filter(|i| matches!(i, LineItem::Frame(f) if f.message.msg_type() == firmware_protocol::sensor_link::msg_type::ADC_SAMPLES))
        .count();
    // Samples at 10..=4000 ms (the last one goes out ahead of the TIME reply).
    assert_eq!(samples, 400, "{} items", items.len());
    assert_eq!(c.line_counters(1).dropped_tx, 0);
}

/// The same client bytes give the same output bytes, however the input is chunked.
#[test]
fn lockstep_output_does_not_depend_on_input_chunking() {
    let mut script = Vec::new();
    script.extend(adc_stream(1, 0b11));
    script.extend(frame_bytes(2, Message::TimeAdvance { ticks: 7 }));
    script.extend(b"junk\x00");
    script.extend(adc_read(3, 0));
    script.extend(frame_bytes(4, Message::TimeAdvance { ticks: 3 }));
    let run = |chunk: usize| {
        let mut c = core(true, false);
        let mut out = Vec::new();
        for piece in script.chunks(chunk) {
            c.receive(1, piece).unwrap();
            if let Some(b) = c.take_output(1) {
                out.extend_from_slice(&b);
            }
        }
        (out, c.line_counters(1))
    };
    let (whole, counters) = run(script.len());
    assert_eq!(counters.errors, 1, "the junk is one error item");
    for chunk in 1..script.len() {
        assert_eq!(run(chunk).0, whole, "chunk size {chunk}");
    }
}

/// An EyeBot that vanished mid-frame leaves a partial frame behind; after the idle limit
/// it is dropped and reported, and the next request is answered normally.
#[test]
fn a_partial_frame_is_dropped_after_the_idle_limit() {
    let mut c = core(true, false);
    let read = adc_read(1, 0);
    c.receive(1, &read[..4]).unwrap();
    let advance = frame_bytes(2, Message::TimeAdvance { ticks: 10 });
    // The advance arrives glued to the partial frame: the CRC fails, the rescan finds it.
    c.receive(1, &advance).unwrap();
    let items = decode(&c.take_output(1).unwrap());
    assert!(
        items
            .iter()
            .any(|i| matches!(i, LineItem::Frame(f) if f.seq == 2)),
        "{items:?}"
    );
    // Another half frame, then silence: dropped once 50 ms have passed.
    c.receive(1, &read[..5]).unwrap();
    let before = c.line_counters(1).errors;
    c.receive(1, &frame_bytes(3, Message::TimeAdvance { ticks: 0 }))
        .unwrap();
    let _ = c.take_output(1);
    assert!(c.line_counters(1).errors > before);
}

/// `replay = "FILE"`: logged sentences are forwarded at their simulated times in place of
/// the model's, only for the selected transducer when the log names transducers.
#[test]
fn a_scheduled_feed_forwards_the_selected_transducers_logged_ranges() {
    let mut c = core(true, false);
    let line = |text: &str| Bytes::from(format!("{text}\r\n"));
    c.set_feed_schedule(vec![
        (200 * MS, line("$SDDBT,8.2,f,2.5,M,1.4,F*0E")),
        (270 * MS, line("$PEBHS,1,2.5,90*71")),
        (1_200 * MS, line("$SDDBT,9.9,f,3.0,M,1.6,F*02")),
        (1_270 * MS, line("$PEBHS,2,3.0,90*76")),
        (2_200 * MS, line("$SDDBT,8.2,f,2.5,M,1.4,F*0E")),
    ]);
    let mut select = BytesMut::new();
    SonarCommand::Select(Transducer::new(1).unwrap()).encode(&mut select);
    c.receive(0, &select).unwrap();
    c.receive(1, &frame_bytes(1, Message::TimeAdvance { ticks: 300 }))
        .unwrap();
    let sonar = c.take_output(0).unwrap();
    let text = String::from_utf8_lossy(&sonar);
    assert_eq!(
        text, "@A1\r\n$SDDBT,8.2,f,2.5,M,1.4,F*0E\r\n$SDDBT,8.2,f,2.5,M,1.4,F*0E\r\n",
        "transducer 2's 3.0 m is withheld; the last, unmapped one goes out after its wait"
    );
    assert_eq!(c.mux_counters().fed_withheld, 1);
}

/// Regression: garbage after the last frame was consumed by the decoder (which reports a
/// run of garbage only before the next item) and, with the inbox empty, the idle flush
/// never ran: the error was never counted while the EyeBot stayed quiet.
#[test]
fn trailing_garbage_is_reported_after_the_idle_limit() {
    let mut c = core(false, false);
    let mut input = frame_bytes(1, Message::TimeGet);
    input.extend_from_slice(b"\x00\x01garbage");
    c.receive(1, &input).unwrap();
    assert_eq!(c.line_counters(1).frames_rx, 1);
    assert_eq!(
        c.line_counters(1).errors,
        0,
        "not reported before the idle limit"
    );
    c.advance_to(SENSOR_IDLE_FLUSH_NS + MS).unwrap();
    assert_eq!(
        c.line_counters(1).errors,
        1,
        "one report for the run of garbage"
    );
}

#[test]
fn a_shared_line_serves_the_multiplexer_and_the_board() {
    let mut c = core(true, true);
    let mut select = BytesMut::new();
    SonarCommand::Select(Transducer::new(3).unwrap()).encode(&mut select);
    c.receive(0, &select).unwrap();
    c.receive(0, &frame_bytes(9, Message::TimeAdvance { ticks: 110 }))
        .unwrap();
    let items = decode(&c.take_output(0).unwrap());
    assert!(
        matches!(items[0], LineItem::Sonar(SonarCommand::Ack(t)) if t.get() == 3),
        "{items:?}"
    );
    assert!(matches!(items[1], LineItem::Nmea(_)), "{items:?}");
    assert!(matches!(&items[2], LineItem::Frame(f) if f.seq == 9));
}

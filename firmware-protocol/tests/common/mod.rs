//! Shared test fixtures: the examples in PROTOCOL.md and what each one must decode to.
#![allow(dead_code)]

use firmware_protocol::nmea::Tenths;
use firmware_protocol::sensor_link::{
    AdcChannel, AdcSamples, AdcValue, CalibrationAction, CalibrationState, CompassMode,
    CompassOutput, Counters, Direction, ErrorCode, Message, Reading, Readings, StepValues,
    Thruster, ThrusterCommand, TimeMode,
};
use firmware_protocol::{
    Dbt, Dpt, EchoReport, Frame, HeadingWord, LineItem, Sentence, SonarCommand, Talker, Transducer,
};

pub const PROTOCOL_MD: &str = include_str!("../../PROTOCOL.md");

/// One example block of PROTOCOL.md: its name and its bytes on the wire.
#[derive(Debug, Clone)]
pub struct Example {
    pub name: String,
    pub bytes: Vec<u8>,
}

/// Every ```hex NAME and ```nmea NAME block of PROTOCOL.md, in document order.
pub fn examples() -> Vec<Example> {
    let mut out = Vec::new();
    let mut lines = PROTOCOL_MD.lines();
    while let Some(line) = lines.next() {
        let (kind, name) = match line.trim_start().strip_prefix("```") {
            Some(info) => match info.split_once(' ') {
                Some((kind @ ("hex" | "nmea"), name)) => (kind, name.trim().to_owned()),
                _ => continue,
            },
            None => continue,
        };
        let body: Vec<&str> = lines
            .by_ref()
            .take_while(|l| !l.trim_start().starts_with("```"))
            .collect();
        let bytes = if kind == "hex" {
            body.join(" ")
                .split_whitespace()
                .map(|h| {
                    u8::from_str_radix(h, 16).unwrap_or_else(|_| panic!("{name}: bad hex {h:?}"))
                })
                .collect()
        } else {
            assert_eq!(body.len(), 1, "{name}: an nmea block holds one sentence");
            let mut b = body[0].trim_end().as_bytes().to_vec();
            b.extend_from_slice(b"\r\n");
            b
        };
        out.push(Example { name, bytes });
    }
    out
}

fn ch(c: u8) -> AdcChannel {
    AdcChannel::new(c).unwrap()
}
fn adc(v: u16) -> AdcValue {
    AdcValue::new(v).unwrap()
}
fn t(v: i32) -> Option<Tenths> {
    Some(Tenths::from_tenths(v).unwrap())
}
fn frame(seq: u8, message: Message) -> LineItem {
    LineItem::Frame(Frame::new(seq, message))
}

/// What each named example means, written from the prose of PROTOCOL.md.
pub fn expected(name: &str) -> Option<LineItem> {
    let sd = Talker::SOUNDER;
    let t2 = Transducer::new(2).unwrap();
    let fwd = |duty| ThrusterCommand {
        duty,
        direction: Direction::Forward,
    };
    Some(match name {
        "select-2" => LineItem::Sonar(SonarCommand::Select(t2)),
        "ack-2" => LineItem::Sonar(SonarCommand::Ack(t2)),
        "sonar-nak" => LineItem::Sonar(SonarCommand::Nak),
        "nak" => frame(
            0x11,
            Message::Nak {
                rejected_type: 0x10,
                code: ErrorCode::BadValue,
                detail: 0,
            },
        ),
        "dbt" => LineItem::Nmea(Sentence::Dbt(Dbt {
            talker: sd,
            feet: t(105),
            metres: t(32),
            fathoms: t(17),
        })),
        "dbt-talker-ii" => LineItem::Nmea(Sentence::Dbt(Dbt {
            talker: Talker::new("II").unwrap(),
            feet: t(49),
            metres: t(15),
            fathoms: t(8),
        })),
        "dpt" => LineItem::Nmea(Sentence::Dpt(Dpt {
            talker: sd,
            depth_m: t(32),
            offset_m: t(0),
            max_range_m: None,
        })),
        "dpt-max-range" => LineItem::Nmea(Sentence::Dpt(Dpt {
            talker: sd,
            depth_m: t(32),
            offset_m: t(0),
            max_range_m: Some(t(100)),
        })),
        "dpt-negative-offset" => LineItem::Nmea(Sentence::Dpt(Dpt {
            talker: sd,
            depth_m: t(32),
            offset_m: t(-3),
            max_range_m: None,
        })),
        "dbt-no-echo" => LineItem::Nmea(Sentence::Dbt(Dbt::empty(sd))),
        "dpt-no-echo" => LineItem::Nmea(Sentence::Dpt(Dpt {
            talker: sd,
            depth_m: None,
            offset_m: t(0),
            max_range_m: None,
        })),
        "echo-report" => LineItem::Nmea(Sentence::Echo(EchoReport {
            transducer: t2,
            range_m: t(32),
            quality_pct: 87,
        })),
        "echo-report-no-echo" => LineItem::Nmea(Sentence::Echo(EchoReport {
            transducer: t2,
            range_m: None,
            quality_pct: 0,
        })),
        "hello" => frame(0x00, Message::Hello { client_version: 1 }),
        "hello-reply" => frame(
            0x00,
            Message::HelloReply {
                protocol_version: 1,
                capabilities: 0x017F,
                tick_us: 10_000,
                max_payload: 64,
            },
        ),
        "counters-get" => frame(0x01, Message::CountersGet),
        "counters" => frame(
            0x01,
            Message::Counters(Counters {
                rx_frames: 1234,
                rx_crc_errors: 2,
                rx_framing_errors: 1,
                rx_skipped_bytes: 17,
                rx_rejected: 1,
                tx_frames: 1230,
                tx_naks: 1,
            }),
        ),
        "ack-adc-stream" => frame(0x03, Message::Ack { acked_type: 0x11 }),
        "adc-read" => frame(0x02, Message::AdcRead { channel: ch(3) }),
        "adc-value" => frame(
            0x02,
            Message::AdcValue {
                channel: ch(3),
                value: adc(523),
            },
        ),
        "adc-stream" => frame(
            0x03,
            Message::AdcStream {
                channels: 0x04,
                period_ms: 10,
            },
        ),
        "adc-stream-stop" => frame(
            0x04,
            Message::AdcStream {
                channels: 0,
                period_ms: 0,
            },
        ),
        "adc-samples" => frame(
            0x00,
            Message::AdcSamples {
                ticks: 300,
                samples: AdcSamples::new([(ch(0), adc(500)), (ch(2), adc(100))]),
            },
        ),
        "compass-mode" => frame(
            0x05,
            Message::CompassMode {
                mode: CompassMode::Continuous,
                output: CompassOutput::Bcd,
            },
        ),
        "compass-read" => frame(0x06, Message::CompassRead),
        "compass-heading-bcd" => frame(
            0x06,
            Message::CompassHeading {
                word: HeadingWord(0x0270),
            },
        ),
        "compass-heading-binary" => frame(
            0x07,
            Message::CompassHeading {
                word: HeadingWord(270),
            },
        ),
        "compass-raw" => frame(0x08, Message::CompassRaw { x: -200, y: 300 }),
        "compass-heading-push" => frame(
            0x01,
            Message::CompassHeadingPush {
                word: HeadingWord(0x0359),
            },
        ),
        "compass-raw-push" => frame(0x02, Message::CompassRawPush { x: 100, y: -100 }),
        "compass-calibrate-start" => frame(
            0x09,
            Message::CompassCalibrate {
                action: CalibrationAction::Start,
            },
        ),
        "calibration-status" => frame(
            0x09,
            Message::CalibrationStatus {
                state: CalibrationState::Collecting,
                points: 0,
            },
        ),
        "compass-reset" => frame(0x0B, Message::CompassReset),
        "thruster-set" => frame(
            0x0C,
            Message::ThrusterSet {
                thruster: Thruster::Port,
                command: fwd(0),
            },
        ),
        "thruster-set-all" => frame(
            0x0D,
            Message::ThrusterSetAll {
                commands: [fwd(0), fwd(0), fwd(0xFF), fwd(0xFF)],
            },
        ),
        "time-get" => frame(0x0E, Message::TimeGet),
        "time" => frame(
            0x0E,
            Message::Time {
                ticks: 12345,
                tick_us: 10_000,
            },
        ),
        "time-advance" => frame(0x0F, Message::TimeAdvance { ticks: 10 }),
        "time-step" => frame(
            0x12,
            Message::TimeStep {
                used: 3,
                stop_on_sonar: false,
                ticks: 1,
                thrusters: Some([fwd(0x40), fwd(0x40), fwd(0xB0), fwd(0xB0)]),
                readings: Readings::new([
                    Reading::Adc(ch(1)),
                    Reading::Adc(ch(0)),
                    Reading::Compass,
                ])
                .unwrap(),
            },
        ),
        "step" => frame(
            0x12,
            Message::Step {
                ticks: 301,
                sonar_bytes: 0,
                values: StepValues::new([801, 164, 0x005A]).unwrap(),
            },
        ),
        "time-step-sonar" => frame(
            0x13,
            Message::TimeStep {
                used: 0,
                stop_on_sonar: true,
                ticks: 100,
                thrusters: None,
                readings: Readings::default(),
            },
        ),
        "step-sonar" => frame(
            0x13,
            Message::Step {
                ticks: 336,
                sonar_bytes: 5,
                values: StepValues::default(),
            },
        ),
        "time-mode" => frame(
            0x10,
            Message::TimeMode {
                mode: TimeMode::Lockstep,
            },
        ),
        _ => return None,
    })
}

/// What example `example` must decode to.
pub fn expected_for(example: &Example) -> LineItem {
    expected(&example.name).unwrap_or_else(|| {
        panic!(
            "PROTOCOL.md example {:?} has no expected value",
            example.name
        )
    })
}

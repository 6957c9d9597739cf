//! Decoding a sensor-link payload whose frame checked: the length each type must have, then
//! requests and replies field by field (`PROTOCOL.md` 2); a field out of range is a
//! [`MessageError`] naming its offset.

use nom::{
    IResult, Parser,
    combinator::all_consuming,
    number::complete::{be_i16, be_u8, be_u16, be_u32},
};

use super::*;
use crate::error::MessageError;

/// Payload length for each fixed-size type; `None` for an unknown type.
pub(super) fn fixed_len(t: u8) -> Option<u8> {
    use msg_type as m;
    Some(match t {
        m::HELLO => 1,
        m::COUNTERS_GET | m::COMPASS_READ | m::COMPASS_RESET | m::TIME_GET => 0,
        m::ADC_READ => 1,
        m::ADC_STREAM => 3,
        m::COMPASS_MODE => 2,
        m::COMPASS_CALIBRATE => 1,
        m::THRUSTER_SET => 3,
        m::THRUSTER_SET_ALL => 8,
        m::TIME_ADVANCE => 4,
        m::TIME_MODE => 1,
        m::ACK => 1,
        m::HELLO_REPLY => 8,
        m::COUNTERS => 28,
        m::ADC_VALUE => 3,
        m::COMPASS_HEADING | m::COMPASS_HEADING_PUSH => 2,
        m::COMPASS_RAW | m::COMPASS_RAW_PUSH => 4,
        m::CALIBRATION_STATUS => 2,
        m::TIME => 8,
        m::NAK => 3,
        // Variable: 5 + 2 * popcount(mask); checked separately.
        m::ADC_SAMPLES => 5,
        // Variable, at least this long; checked separately.
        m::TIME_STEP | m::STEP => 6,
        _ => return None,
    })
}

pub(super) type Res<'a, O> = IResult<&'a [u8], O>;
pub(super) type NomErr<'a> = nom::Err<nom::error::Error<&'a [u8]>>;

pub(super) fn u8s<const N: usize>(input: &[u8]) -> Res<'_, [u8; N]> {
    let mut out = [0u8; N];
    let mut rest = input;
    for slot in &mut out {
        let (r, b) = be_u8(rest)?;
        *slot = b;
        rest = r;
    }
    Ok((rest, out))
}

/// The type and seq of the frame being decoded and its payload length, for its errors.
#[derive(Debug, Clone, Copy)]
struct Fault {
    msg_type: u8,
    seq: u8,
    found: u8,
}

impl Fault {
    fn len(self, expected: u8) -> MessageError {
        MessageError::BadLength {
            msg_type: self.msg_type,
            seq: self.seq,
            expected,
            found: self.found,
        }
    }

    fn value(self, offset: u8, value: u8) -> MessageError {
        MessageError::BadValue {
            msg_type: self.msg_type,
            seq: self.seq,
            offset,
            value,
        }
    }
}

pub(super) fn decode_message(raw: RawFrame<'_>) -> Result<Message, MessageError> {
    let RawFrame {
        msg_type: t,
        seq,
        payload,
    } = raw;
    let unknown = MessageError::UnknownType { msg_type: t, seq };
    let Some(expected) = fixed_len(t) else {
        return Err(unknown);
    };
    let f = Fault {
        msg_type: t,
        seq,
        found: payload.len() as u8,
    };
    check_length(t, payload, expected, f)?;
    // The length is right, so the nom parsers below cannot run out of input; a failure would
    // still be reported as a length error rather than a panic.
    match decode_request(t, payload, expected, f)? {
        Some(message) => Ok(message),
        None => decode_reply(t, payload, expected, f)?.ok_or(unknown),
    }
}

/// The payload length of a `t` frame: fixed, or as its own fields say (ADC_SAMPLES, TIME_STEP,
/// STEP).
fn check_length(t: u8, payload: &[u8], expected: u8, f: Fault) -> Result<(), MessageError> {
    use msg_type as m;
    let found = f.found;
    if t == m::ADC_SAMPLES {
        let Some(&mask) = payload.get(4) else {
            return Err(f.len(expected));
        };
        let want = 5 + 2 * mask.count_ones() as u8;
        if found != want {
            return Err(f.len(want));
        }
        if mask == 0 {
            return Err(f.value(4, 0));
        }
    } else if t == m::TIME_STEP {
        let Some(&flags) = payload.get(1) else {
            return Err(f.len(expected));
        };
        let head = if flags & step_flag::THRUSTERS != 0 {
            14
        } else {
            6
        };
        if found < head {
            return Err(f.len(head));
        }
        if usize::from(found - head) > MAX_READINGS {
            return Err(f.len(head + MAX_READINGS as u8));
        }
    } else if t == m::STEP {
        if found < expected || !(found - expected).is_multiple_of(2) {
            return Err(f.len(expected));
        }
        if usize::from(found - expected) / 2 > MAX_READINGS {
            return Err(f.len(expected + 2 * MAX_READINGS as u8));
        }
    } else if found != expected {
        return Err(f.len(expected));
    }
    Ok(())
}

/// A parsed message, or a length error.
fn parsed(f: Fault, expected: u8, r: Res<'_, Message>) -> Result<Message, MessageError> {
    r.map(|(_, msg)| msg).map_err(|_| f.len(expected))
}

fn direction(f: Fault, offset: u8, v: u8) -> Result<Direction, MessageError> {
    match v {
        0 => Ok(Direction::Forward),
        1 => Ok(Direction::Reverse),
        _ => Err(f.value(offset, v)),
    }
}

fn adc_value(f: Fault, offset: u8, v: u16) -> Result<AdcValue, MessageError> {
    AdcValue::new(v).map_err(|_| f.value(offset, (v >> 8) as u8))
}

/// The EyeBot's requests (`None`: not a request type).
fn decode_request(
    t: u8,
    payload: &[u8],
    expected: u8,
    f: Fault,
) -> Result<Option<Message>, MessageError> {
    use msg_type as m;
    let message = match t {
        m::HELLO => parsed(
            f,
            expected,
            all_consuming(be_u8)
                .map(|v| Message::Hello { client_version: v })
                .parse(payload),
        )?,
        m::COUNTERS_GET => Message::CountersGet,
        m::COMPASS_READ => Message::CompassRead,
        m::COMPASS_RESET => Message::CompassReset,
        m::TIME_GET => Message::TimeGet,
        m::ADC_READ => {
            let [c] = payload_array::<1>(payload).map_err(|_| f.len(expected))?;
            Message::AdcRead {
                channel: AdcChannel::new(c).map_err(|_| f.value(0, c))?,
            }
        }
        m::ADC_STREAM => parsed(
            f,
            expected,
            all_consuming((be_u8, be_u16))
                .map(|(channels, period_ms)| Message::AdcStream {
                    channels,
                    period_ms,
                })
                .parse(payload),
        )
        .and_then(|msg| match msg {
            Message::AdcStream {
                channels,
                period_ms: 0,
            } if channels != 0 => Err(f.value(1, 0)),
            msg => Ok(msg),
        })?,
        m::COMPASS_MODE => {
            let [mode, output] = payload_array::<2>(payload).map_err(|_| f.len(expected))?;
            let mode = match mode {
                0 => CompassMode::Poll,
                1 => CompassMode::Continuous,
                v => return Err(f.value(0, v)),
            };
            let output = match output {
                0 => CompassOutput::Binary,
                1 => CompassOutput::Bcd,
                2 => CompassOutput::Raw,
                v => return Err(f.value(1, v)),
            };
            Message::CompassMode { mode, output }
        }
        m::COMPASS_CALIBRATE => {
            let [a] = payload_array::<1>(payload).map_err(|_| f.len(expected))?;
            let action = match a {
                0 => CalibrationAction::Start,
                1 => CalibrationAction::TakePoint,
                2 => CalibrationAction::Finish,
                3 => CalibrationAction::Clear,
                v => return Err(f.value(0, v)),
            };
            Message::CompassCalibrate { action }
        }
        m::THRUSTER_SET => {
            let [i, duty, dir] = payload_array::<3>(payload).map_err(|_| f.len(expected))?;
            let thruster = Thruster::from_index(i).map_err(|_| f.value(0, i))?;
            Message::ThrusterSet {
                thruster,
                command: ThrusterCommand {
                    duty,
                    direction: direction(f, 2, dir)?,
                },
            }
        }
        m::THRUSTER_SET_ALL => {
            let b = payload_array::<8>(payload).map_err(|_| f.len(expected))?;
            let mut commands = [ThrusterCommand::OFF; 4];
            for (i, c) in commands.iter_mut().enumerate() {
                let off = 2 * i;
                *c = ThrusterCommand {
                    duty: b[off],
                    direction: direction(f, off as u8 + 1, b[off + 1])?,
                };
            }
            Message::ThrusterSetAll { commands }
        }
        m::TIME_ADVANCE => parsed(
            f,
            expected,
            all_consuming(be_u32)
                .map(|ticks| Message::TimeAdvance { ticks })
                .parse(payload),
        )?,
        m::TIME_MODE => {
            let [v] = payload_array::<1>(payload).map_err(|_| f.len(expected))?;
            let mode = match v {
                0 => TimeMode::RealTime,
                1 => TimeMode::Lockstep,
                v => return Err(f.value(0, v)),
            };
            Message::TimeMode { mode }
        }
        m::TIME_STEP => decode_time_step(payload, expected, f)?,
        _ => return Ok(None),
    };
    Ok(Some(message))
}

fn decode_time_step(payload: &[u8], expected: u8, f: Fault) -> Result<Message, MessageError> {
    let (rest, (used, flags, ticks)) = (be_u8, be_u8, be_u32)
        .parse(payload)
        .map_err(|_: NomErr<'_>| f.len(expected))?;
    if flags & !(step_flag::THRUSTERS | step_flag::STOP_ON_SONAR) != 0 {
        return Err(f.value(1, flags));
    }
    let (rest, thrusters) = if flags & step_flag::THRUSTERS != 0 {
        let Some((b, rest)) = rest.split_first_chunk::<8>() else {
            return Err(f.len(14));
        };
        let mut commands = [ThrusterCommand::OFF; 4];
        for (i, c) in commands.iter_mut().enumerate() {
            let off = 2 * i;
            *c = ThrusterCommand {
                duty: b[off],
                direction: direction(f, 6 + off as u8 + 1, b[off + 1])?,
            };
        }
        (rest, Some(commands))
    } else {
        (rest, None)
    };
    let first = (payload.len() - rest.len()) as u8;
    let mut items = Vec::with_capacity(rest.len());
    for (i, &code) in rest.iter().enumerate() {
        items.push(Reading::from_code(code).ok_or_else(|| f.value(first + i as u8, code))?);
    }
    Ok(Message::TimeStep {
        used,
        stop_on_sonar: flags & step_flag::STOP_ON_SONAR != 0,
        ticks,
        thrusters,
        readings: Readings::new(items).map_err(|_| f.len(first))?,
    })
}

/// The bridge's replies and pushes (`None`: not a reply type).
fn decode_reply(
    t: u8,
    payload: &[u8],
    expected: u8,
    f: Fault,
) -> Result<Option<Message>, MessageError> {
    use msg_type as m;
    let message = match t {
        m::STEP => {
            let (mut rest, (ticks, sonar_bytes)) = (be_u32, be_u16)
                .parse(payload)
                .map_err(|_: NomErr<'_>| f.len(expected))?;
            let mut values = Vec::with_capacity(rest.len() / 2);
            while !rest.is_empty() {
                let (r, v) = be_u16(rest).map_err(|_: NomErr<'_>| f.len(expected))?;
                values.push(v);
                rest = r;
            }
            Message::Step {
                ticks,
                sonar_bytes,
                values: StepValues::new(values).map_err(|_| f.len(expected))?,
            }
        }
        m::ACK => parsed(
            f,
            expected,
            all_consuming(be_u8)
                .map(|acked_type| Message::Ack { acked_type })
                .parse(payload),
        )?,
        m::HELLO_REPLY => parsed(
            f,
            expected,
            all_consuming((be_u8, be_u16, be_u32, be_u8))
                .map(
                    |(protocol_version, capabilities, tick_us, max_payload)| Message::HelloReply {
                        protocol_version,
                        capabilities,
                        tick_us,
                        max_payload,
                    },
                )
                .parse(payload),
        )?,
        m::COUNTERS => parsed(
            f,
            expected,
            all_consuming((be_u32, be_u32, be_u32, be_u32, be_u32, be_u32, be_u32))
                .map(|(a, b, c, d, e, f, g)| {
                    Message::Counters(Counters {
                        rx_frames: a,
                        rx_crc_errors: b,
                        rx_framing_errors: c,
                        rx_skipped_bytes: d,
                        rx_rejected: e,
                        tx_frames: f,
                        tx_naks: g,
                    })
                })
                .parse(payload),
        )?,
        m::ADC_VALUE => {
            let (_, (c, v)) = all_consuming((be_u8, be_u16))
                .parse(payload)
                .map_err(|_: NomErr<'_>| f.len(expected))?;
            let channel = AdcChannel::new(c).map_err(|_| f.value(0, c))?;
            Message::AdcValue {
                channel,
                value: adc_value(f, 1, v)?,
            }
        }
        m::COMPASS_HEADING | m::COMPASS_HEADING_PUSH => {
            let (_, w) = all_consuming(be_u16)
                .parse(payload)
                .map_err(|_: NomErr<'_>| f.len(expected))?;
            if w & 0xFC00 != 0 {
                return Err(f.value(0, (w >> 8) as u8));
            }
            let word = HeadingWord(w);
            if t == m::COMPASS_HEADING {
                Message::CompassHeading { word }
            } else {
                Message::CompassHeadingPush { word }
            }
        }
        m::COMPASS_RAW | m::COMPASS_RAW_PUSH => {
            let (_, (x, y)) = all_consuming((be_i16, be_i16))
                .parse(payload)
                .map_err(|_: NomErr<'_>| f.len(expected))?;
            if t == m::COMPASS_RAW {
                Message::CompassRaw { x, y }
            } else {
                Message::CompassRawPush { x, y }
            }
        }
        m::CALIBRATION_STATUS => {
            let [s, points] = payload_array::<2>(payload).map_err(|_| f.len(expected))?;
            let state = match s {
                0 => CalibrationState::Idle,
                1 => CalibrationState::Collecting,
                2 => CalibrationState::ReadyToFinish,
                v => return Err(f.value(0, v)),
            };
            if points > 2 {
                return Err(f.value(1, points));
            }
            Message::CalibrationStatus { state, points }
        }
        m::TIME => parsed(
            f,
            expected,
            all_consuming((be_u32, be_u32))
                .map(|(ticks, tick_us)| Message::Time { ticks, tick_us })
                .parse(payload),
        )?,
        m::NAK => {
            let [rejected_type, code, detail] =
                payload_array::<3>(payload).map_err(|_| f.len(expected))?;
            Message::Nak {
                rejected_type,
                code: ErrorCode::from_u8(code),
                detail,
            }
        }
        m::ADC_SAMPLES => {
            let (mut rest, (ticks, mask)) = (be_u32, be_u8)
                .parse(payload)
                .map_err(|_: NomErr<'_>| f.len(expected))?;
            let mut values = [None; 8];
            for (ch, slot) in values.iter_mut().enumerate() {
                if mask & (1 << ch) != 0 {
                    let offset = (payload.len() - rest.len()) as u8;
                    let (r, v) = be_u16(rest).map_err(|_: NomErr<'_>| f.len(expected))?;
                    rest = r;
                    *slot = Some(adc_value(f, offset, v)?);
                }
            }
            Message::AdcSamples {
                ticks,
                samples: AdcSamples { values },
            }
        }
        _ => return Ok(None),
    };
    Ok(Some(message))
}

fn payload_array<const N: usize>(payload: &[u8]) -> Result<[u8; N], ()> {
    all_consuming(u8s::<N>)
        .parse(payload)
        .map(|(_, a)| a)
        .map_err(|_: NomErr<'_>| ())
}

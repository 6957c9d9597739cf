//! The Vector 2X compass: poll and continuous modes, binary, BCD and raw output, the
//! two-point calibration, reset.

use firmware_protocol::sensor_link::{CompassMode, CompassOutput, ErrorCode, Message};
use firmware_protocol::{Frame, HeadingFormat, HeadingWord};

use super::{Output, SensorBoard};
use crate::SimNanos;
use crate::devices::Plant;

impl SensorBoard {
    /// COMPASS_MODE, COMPASS_READ, COMPASS_CALIBRATE, COMPASS_RESET.
    pub(super) fn execute_compass(
        &mut self,
        frame: Frame,
        now: SimNanos,
        plant: &mut dyn Plant,
    ) -> Option<Output> {
        let seq = frame.seq;
        let kind = frame.message.msg_type();
        let out = match frame.message {
            Message::CompassMode { mode, output } => {
                self.compass_mode = mode;
                self.compass_output = output;
                self.next_compass_push_ns = match mode {
                    CompassMode::Continuous => Some(now + self.settings.compass_period_ns),
                    CompassMode::Poll => None,
                };
                Message::Ack { acked_type: kind }
            }
            Message::CompassRead => self.compass_message(plant, now, false),
            Message::CompassCalibrate { action } => match plant.compass_calibrate(action, now) {
                Ok(progress) => Message::CalibrationStatus {
                    state: progress.state,
                    points: progress.points,
                },
                Err(refused) => {
                    tracing::debug!(%refused, "calibration step refused");
                    return Some(self.nak(seq, kind, ErrorCode::BadState, 0));
                }
            },
            Message::CompassReset => {
                plant.compass_reset(now);
                self.compass_mode = CompassMode::Poll;
                self.compass_output = CompassOutput::Binary;
                self.next_compass_push_ns = None;
                Message::Ack { acked_type: kind }
            }
            _ => return None,
        };
        Some(self.reply(seq, out))
    }

    pub(super) fn compass_message(
        &mut self,
        plant: &mut dyn Plant,
        now: SimNanos,
        push: bool,
    ) -> Message {
        let sample = plant.compass(now);
        let heading = sample.heading_deg.min(359);
        let word = |format| HeadingWord::encode(heading, format).unwrap_or(HeadingWord(0));
        match (self.compass_output, push) {
            (CompassOutput::Binary, false) => Message::CompassHeading {
                word: word(HeadingFormat::Binary),
            },
            (CompassOutput::Bcd, false) => Message::CompassHeading {
                word: word(HeadingFormat::Bcd),
            },
            (CompassOutput::Raw, false) => Message::CompassRaw {
                x: sample.raw_x,
                y: sample.raw_y,
            },
            (CompassOutput::Binary, true) => Message::CompassHeadingPush {
                word: word(HeadingFormat::Binary),
            },
            (CompassOutput::Bcd, true) => Message::CompassHeadingPush {
                word: word(HeadingFormat::Bcd),
            },
            (CompassOutput::Raw, true) => Message::CompassRawPush {
                x: sample.raw_x,
                y: sample.raw_y,
            },
        }
    }
}

//! The ADC board: polled reads and a stream of chosen channels at a set period.

use firmware_protocol::Frame;
use firmware_protocol::sensor_link::{AdcChannel, AdcValue, ErrorCode, Message};

use super::{AdcStream, Output, SensorBoard};
use crate::SimNanos;
use crate::devices::Plant;

impl SensorBoard {
    /// ADC_READ, ADC_STREAM.
    pub(super) fn execute_adc(
        &mut self,
        frame: Frame,
        now: SimNanos,
        plant: &mut dyn Plant,
    ) -> Option<Output> {
        let seq = frame.seq;
        let kind = frame.message.msg_type();
        let out = match frame.message {
            Message::AdcRead { channel } => Message::AdcValue {
                channel,
                value: adc_value(plant, channel, now),
            },
            Message::AdcStream {
                channels,
                period_ms,
            } => {
                if channels == 0 {
                    self.stream = None;
                } else if period_ms == 0 || self.stream_overloads_line(channels, period_ms) {
                    return Some(self.nak(seq, kind, ErrorCode::BadValue, 1));
                } else {
                    let period_ns = u64::from(period_ms) * 1_000_000;
                    self.stream = Some(AdcStream {
                        mask: channels,
                        period_ns,
                        next_ns: now + period_ns,
                    });
                }
                Message::Ack { acked_type: kind }
            }
            _ => return None,
        };
        Some(self.reply(seq, out))
    }

    /// Whether streaming `channels` every `period_ms` would take more than half the line.
    fn stream_overloads_line(&self, channels: u8, period_ms: u16) -> bool {
        let frame_chars = (firmware_protocol::frame::HEADER_LEN
            + 5
            + 2 * channels.count_ones() as usize
            + firmware_protocol::frame::CRC_LEN) as f64;
        let chars_per_s = frame_chars * 1000.0 / f64::from(period_ms);
        chars_per_s > 0.5 * self.settings.line_chars_per_s
    }
}

pub(super) fn adc_value(plant: &mut dyn Plant, channel: AdcChannel, now: SimNanos) -> AdcValue {
    let raw = plant.adc(channel.get(), now).min(1023);
    AdcValue::new(raw).unwrap_or_else(|_| unreachable!("clamped to 10 bits"))
}

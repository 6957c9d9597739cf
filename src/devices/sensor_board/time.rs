//! Time: simulated time in ticks, lockstep advances and TIME_STEP with its take-back of
//! unused readings, which the bridge core carries out (the board only asks for them).

use firmware_protocol::Frame;
use firmware_protocol::sensor_link::{
    self, CompassOutput, ErrorCode, Message, Reading, StepValues, TimeMode,
};

use super::adc::adc_value;
use super::{OpenStep, Output, SensorBoard};
use crate::SimNanos;
use crate::devices::Plant;

impl SensorBoard {
    /// TIME_GET, TIME_ADVANCE, TIME_STEP, TIME_MODE.
    pub(super) fn execute_time(
        &mut self,
        frame: Frame,
        now: SimNanos,
        plant: &mut dyn Plant,
    ) -> Option<Output> {
        let seq = frame.seq;
        let kind = frame.message.msg_type();
        let out = match frame.message {
            Message::TimeGet => Message::Time {
                ticks: self.ticks(now),
                tick_us: (self.settings.tick_ns / 1000) as u32,
            },
            Message::TimeAdvance { ticks } => {
                if !self.settings.lockstep {
                    return Some(self.nak(seq, kind, ErrorCode::BadState, 0));
                }
                self.pending_advance = Some(frame);
                return Some(Output::Advance {
                    to: now + u64::from(ticks) * self.settings.tick_ns,
                    seq,
                });
            }
            Message::TimeStep {
                used,
                stop_on_sonar,
                ticks,
                thrusters,
                readings,
            } => {
                if !self.settings.lockstep {
                    return Some(self.nak(seq, kind, ErrorCode::BadState, 0));
                }
                let open = self.open_step.map_or(0, |o| o.readings.len());
                if usize::from(used) > open {
                    return Some(self.nak(seq, kind, ErrorCode::BadValue, 0));
                }
                if stop_on_sonar && self.settings.sonar_on_this_line {
                    return Some(self.nak(seq, kind, ErrorCode::Unsupported, 0));
                }
                if self.compass_output == CompassOutput::Raw
                    && readings.as_slice().contains(&Reading::Compass)
                {
                    return Some(self.nak(seq, kind, ErrorCode::BadState, 0));
                }
                self.take_back(plant, used);
                if let Some(commands) = thrusters {
                    self.thrusters = commands;
                    self.last_thruster_ns = Some(now);
                    plant.set_thrusters(self.thrusters, now);
                }
                self.pending_advance = Some(frame);
                self.pending_readings = readings;
                return Some(Output::Step {
                    to: now + u64::from(ticks) * self.settings.tick_ns,
                    seq,
                    stop_on_sonar,
                });
            }
            Message::TimeMode { mode } => {
                let ours = if self.settings.lockstep {
                    TimeMode::Lockstep
                } else {
                    TimeMode::RealTime
                };
                if mode != ours {
                    // The daemon's time mode is chosen when it starts (--time-mode).
                    return Some(self.nak(seq, kind, ErrorCode::BadState, 0));
                }
                Message::Ack { acked_type: kind }
            }
            _ => return None,
        };
        Some(self.reply(seq, out))
    }

    /// The TIME reply that ends a lockstep advance; call once simulated time reached `now`.
    pub fn finish_advance(&mut self, seq: u8, now: SimNanos) -> Frame {
        let message = Message::Time {
            ticks: self.ticks(now),
            tick_us: (self.settings.tick_ns / 1000) as u32,
        };
        let reply = Frame::new(seq, message);
        self.counters.tx_frames = self.counters.tx_frames.wrapping_add(1);
        if let Some(request) = self.pending_advance.take() {
            self.remember(request, reply);
        }
        reply
    }

    /// Takes back the last STEP's readings beyond the first `used`: the plant's reading state
    /// goes back to before them and the first `used` are made again (same values), so the
    /// bridge is where one ADC_READ/COMPASS_READ per used value would have left it.
    fn take_back(&mut self, plant: &mut dyn Plant, used: u8) {
        let Some(open) = self.open_step.take() else {
            return;
        };
        let used = usize::from(used);
        if used >= open.readings.len() {
            return;
        }
        self.taken_back += (open.readings.len() - used) as u64;
        plant.readings_restore();
        for &reading in &open.readings.as_slice()[..used] {
            self.reading(plant, reading, open.at);
        }
    }

    fn reading(&mut self, plant: &mut dyn Plant, reading: Reading, now: SimNanos) -> u16 {
        match reading {
            Reading::Adc(channel) => adc_value(plant, channel, now).get(),
            Reading::Compass => match self.compass_message(plant, now, false) {
                Message::CompassHeading { word } => word.0,
                // TIME_STEP refuses compass readings while the output is raw.
                _ => 0,
            },
        }
    }

    /// The STEP reply that ends a TIME_STEP, once simulated time reached `now`: makes its
    /// readings (after the plant saved its reading state, for a take-back).
    pub fn finish_step(
        &mut self,
        seq: u8,
        now: SimNanos,
        sonar_bytes: u16,
        plant: &mut dyn Plant,
    ) -> Frame {
        let readings = std::mem::take(&mut self.pending_readings);
        let mut values = [0u16; sensor_link::MAX_READINGS];
        if !readings.is_empty() {
            plant.readings_checkpoint();
            for (slot, &reading) in values.iter_mut().zip(readings.as_slice()) {
                *slot = self.reading(plant, reading, now);
            }
            self.open_step = Some(OpenStep { readings, at: now });
        }
        let values = StepValues::new(values.into_iter().take(readings.len()))
            .unwrap_or_else(|_| unreachable!("at most MAX_READINGS readings"));
        let reply = Frame::new(
            seq,
            Message::Step {
                ticks: self.ticks(now),
                sonar_bytes,
                values,
            },
        );
        self.counters.tx_frames = self.counters.tx_frames.wrapping_add(1);
        if let Some(request) = self.pending_advance.take() {
            self.remember(request, reply);
        }
        reply
    }
}

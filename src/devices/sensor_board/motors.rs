//! The motor driver: PWM duty and direction per thruster (the watchdog runs in `poll`).

use firmware_protocol::Frame;
use firmware_protocol::sensor_link::Message;

use super::{Output, SensorBoard};
use crate::SimNanos;
use crate::devices::Plant;

impl SensorBoard {
    /// THRUSTER_SET, THRUSTER_SET_ALL.
    pub(super) fn execute_motors(
        &mut self,
        frame: Frame,
        now: SimNanos,
        plant: &mut dyn Plant,
    ) -> Option<Output> {
        let seq = frame.seq;
        let kind = frame.message.msg_type();
        let out = match frame.message {
            Message::ThrusterSet { thruster, command } => {
                self.thrusters[thruster as usize] = command;
                self.last_thruster_ns = Some(now);
                plant.set_thrusters(self.thrusters, now);
                Message::Ack { acked_type: kind }
            }
            Message::ThrusterSetAll { commands } => {
                self.thrusters = commands;
                self.last_thruster_ns = Some(now);
                plant.set_thrusters(self.thrusters, now);
                Message::Ack { acked_type: kind }
            }
            _ => return None,
        };
        Some(self.reply(seq, out))
    }
}

//! Device emulators: the PICAXE sonar multiplexer master and the sensor-link board (ADC,
//! Vector 2X compass, motor driver, lockstep time), as sans-IO state machines over
//! `firmware-protocol`.
//!
//! Each device is driven the same way, sans-IO: `handle(input, now, plant)` for what
//! arrives from the EyeBot side, `poll(now, plant)` for what is due by simulated time `now`,
//! and `poll_timeout()` for when to call `poll` next. Devices never read a clock, never
//! sleep and never touch a port. What they know of the simulated vehicle comes through the
//! [`Plant`] trait, so every device is tested against a scripted plant.

pub mod multiplexer;
pub mod sensor_board;

use firmware_protocol::sensor_link::{CalibrationAction, CalibrationState, ThrusterCommand};

use crate::SimNanos;

/// A compass measurement as the Vector 2X produces it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CompassSample {
    /// Heading in whole degrees, 0..=359.
    pub heading_deg: u16,
    /// Raw-mode X and Y field words.
    pub raw_x: i16,
    pub raw_y: i16,
}

/// Where a compass calibration stands.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CalibrationProgress {
    pub state: CalibrationState,
    /// Points taken in the current calibration (0..=2).
    pub points: u8,
}

/// A calibration step that is not allowed in the current state (e.g. FINISH with one point).
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("calibration step {action:?} not allowed in state {state:?} with {points} point(s)")]
pub struct CalibrationRefused {
    pub action: CalibrationAction,
    pub state: CalibrationState,
    pub points: u8,
}

/// One event of the sonar multiplexer's timing model.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum SonarEvent {
    /// The relays now connect `transducer` (1..=4): the master acknowledges.
    Switched { transducer: u8 },
    /// The active controller produced a reading. `transducer` is the one that really made it
    /// (right after a switch it may still be the previous one); `range_m` is `None` when the
    /// echo was not valid.
    Reading {
        transducer: u8,
        range_m: Option<f64>,
        quality_pct: u8,
    },
}

/// What the device emulators see of the simulated vehicle and its sensors.
pub trait Plant {
    /// Converts ADC `channel` (0..=7) now: the 10-bit code.
    fn adc(&mut self, channel: u8, now: SimNanos) -> u16;
    /// The compass measurement completed at `now`.
    fn compass(&mut self, now: SimNanos) -> CompassSample;
    /// One calibration step (start, take a point, finish, clear).
    fn compass_calibrate(
        &mut self,
        action: CalibrationAction,
        now: SimNanos,
    ) -> Result<CalibrationProgress, CalibrationRefused>;
    /// Back to power-on state: calibration cleared.
    fn compass_reset(&mut self, now: SimNanos);
    /// The motor driver's outputs changed.
    fn set_thrusters(&mut self, commands: [ThrusterCommand; 4], now: SimNanos);
    /// The EyeBot asked the multiplexer master for `transducer` (1..=4).
    fn sonar_select(&mut self, transducer: u8, now: SimNanos);
    /// Sonar events due by `now`, in time order, with the time each happened.
    fn sonar_poll(&mut self, now: SimNanos, out: &mut Vec<(SimNanos, SonarEvent)>);
    /// When the next sonar event is due.
    fn sonar_timeout(&self) -> Option<SimNanos>;
    /// Saves what ADC and compass reads change (noise draws, the converter's carry-over from
    /// the previous channel), so that reads made ahead for a TIME_STEP can be taken back.
    fn readings_checkpoint(&mut self);
    /// Goes back to the state the last [`Plant::readings_checkpoint`] saved.
    fn readings_restore(&mut self);
}

#[cfg(test)]
pub(crate) mod fake {
    //! A scripted plant for device tests.

    use super::*;

    #[derive(Debug, Default)]
    pub struct FakePlant {
        pub adc: [u16; 8],
        pub heading_deg: u16,
        pub raw: (i16, i16),
        pub calibration_points: u8,
        pub calibrating: bool,
        pub thrusters: Vec<(SimNanos, [ThrusterCommand; 4])>,
        pub compass_reads: Vec<SimNanos>,
        pub sonar: Vec<(SimNanos, SonarEvent)>,
        pub selects: Vec<(SimNanos, u8)>,
        pub checkpoints: u32,
        pub restores: u32,
    }

    impl Plant for FakePlant {
        fn adc(&mut self, channel: u8, _now: SimNanos) -> u16 {
            self.adc[usize::from(channel)]
        }
        fn compass(&mut self, now: SimNanos) -> CompassSample {
            self.compass_reads.push(now);
            CompassSample {
                heading_deg: self.heading_deg,
                raw_x: self.raw.0,
                raw_y: self.raw.1,
            }
        }
        fn compass_calibrate(
            &mut self,
            action: CalibrationAction,
            _now: SimNanos,
        ) -> Result<CalibrationProgress, CalibrationRefused> {
            let refused = |s: &Self| CalibrationRefused {
                action,
                state: if s.calibrating {
                    CalibrationState::Collecting
                } else {
                    CalibrationState::Idle
                },
                points: s.calibration_points,
            };
            match action {
                CalibrationAction::Start => {
                    self.calibrating = true;
                    self.calibration_points = 0;
                }
                CalibrationAction::TakePoint if self.calibrating && self.calibration_points < 2 => {
                    self.calibration_points += 1
                }
                CalibrationAction::Finish if self.calibrating && self.calibration_points == 2 => {
                    self.calibrating = false;
                    self.calibration_points = 0;
                }
                CalibrationAction::Clear => {
                    self.calibrating = false;
                    self.calibration_points = 0;
                }
                _ => return Err(refused(self)),
            }
            let state = match (self.calibrating, self.calibration_points) {
                (false, _) => CalibrationState::Idle,
                (true, 2) => CalibrationState::ReadyToFinish,
                (true, _) => CalibrationState::Collecting,
            };
            Ok(CalibrationProgress {
                state,
                points: self.calibration_points,
            })
        }
        fn compass_reset(&mut self, _now: SimNanos) {
            self.calibrating = false;
            self.calibration_points = 0;
        }
        fn set_thrusters(&mut self, commands: [ThrusterCommand; 4], now: SimNanos) {
            self.thrusters.push((now, commands));
        }
        fn sonar_select(&mut self, transducer: u8, now: SimNanos) {
            self.selects.push((now, transducer));
        }
        fn sonar_poll(&mut self, now: SimNanos, out: &mut Vec<(SimNanos, SonarEvent)>) {
            let due = self.sonar.iter().take_while(|(t, _)| *t <= now).count();
            out.extend(self.sonar.drain(..due));
        }
        fn sonar_timeout(&self) -> Option<SimNanos> {
            self.sonar.first().map(|(t, _)| *t)
        }
        fn readings_checkpoint(&mut self) {
            self.checkpoints += 1;
        }
        fn readings_restore(&mut self) {
            self.restores += 1;
        }
    }
}

//! Sensors: the vehicle state in, the raw numbers the devices put on their wires out.
//!
//! ```text
//! VehicleState ──update()──▶ depth, paddle wheel, accelerometer ──voltage──▶ AdcBoard ──▶ u16 codes
//!              ──update()──▶ Compass ──▶ CompassReading (heading 0..359, raw X/Y counts)
//!  + RayCaster ──update()──▶ SonarSystem (4 transducers, 2 controllers, multiplexer) ──▶ SonarEvent
//! ```
//!
//! Nothing here encodes protocol bytes (that is `firmware-protocol`'s job) or reads a clock:
//! time is the state's `t_s` or an explicit argument. Every sensor has its own seeded random
//! stream ([`rng`]) and an error model from the noise package ([`noise`]). Settings come from
//! `configs/sensors/*.toml` through [`config::SensorsConfig`]; the physics and reasoning
//! behind each model are in `docs/sensors.md`.

pub mod accelerometer;
pub mod adc;
pub mod compass;
pub mod config;
pub mod depth;
pub mod multiplexer;
pub mod noise;
pub mod rng;
pub mod scene;
pub mod sonar;
pub mod velocity;

use crate::physics::state::{RayCaster, VehicleState};

pub use accelerometer::Accelerometer;
pub use adc::{AdcBoard, AdcError};
pub use compass::{Calibration, Compass, CompassMode, CompassReading};
pub use config::{AdcSource, SensorsConfig};
pub use depth::DepthSensor;
pub use multiplexer::{MuxError, SonarEvent, SonarSystem};
pub use sonar::RangeSteps;
pub use velocity::{PaddleWheel, PulseCounter};

/// Every Mako sensor, built from one config and one master seed.
#[derive(Debug, Clone)]
pub struct SensorSuite {
    pub adc: AdcBoard,
    pub depth: DepthSensor,
    pub velocity: PaddleWheel,
    pub accelerometer: Accelerometer,
    pub compass: Compass,
    pub sonar: SonarSystem,
}

impl SensorSuite {
    pub fn new(config: &SensorsConfig, master_seed: u64) -> Self {
        Self {
            adc: AdcBoard::new(&config.adc, master_seed),
            depth: DepthSensor::new(&config.depth, master_seed),
            velocity: PaddleWheel::new(&config.velocity, master_seed),
            accelerometer: Accelerometer::new(&config.accelerometer, master_seed),
            compass: Compass::new(&config.compass, master_seed),
            sonar: SonarSystem::new(&config.sonar, master_seed),
        }
    }

    /// Follows the vehicle after a physics step (at `state.t_s`). Sonar rays are cast only
    /// for pings that fall due.
    pub fn update(&mut self, state: &VehicleState, world: &dyn RayCaster) {
        self.depth.update(state);
        self.velocity.update(state);
        self.accelerometer.update(state);
        self.compass.update(state);
        self.sonar.update(state, world);
    }

    /// What the EyeBot's `OSGetAD(channel)` returns at `t_s`.
    pub fn read_adc(&mut self, channel: u8, t_s: f64) -> Result<u16, AdcError> {
        let v = match self.adc.source(channel)? {
            None => 0.0,
            Some(AdcSource::Depth) => self.depth.voltage(t_s),
            Some(AdcSource::Velocity) => self.velocity.voltage(),
            Some(AdcSource::AccelX) => self.accelerometer.voltage(0, t_s),
            Some(AdcSource::AccelY) => self.accelerometer.voltage(1, t_s),
            Some(AdcSource::AccelZ) => self.accelerometer.voltage(2, t_s),
        };
        let over = if self.adc.channel_of(AdcSource::Velocity).is_some() {
            (self.velocity.voltage() - self.adc.reference_v()).max(0.0)
        } else {
            0.0
        };
        self.adc.convert(channel, v, over)
    }

    /// `read_adc` for the channel wired to `source`.
    pub fn read_source(&mut self, source: AdcSource, t_s: f64) -> Option<u16> {
        let ch = self.adc.channel_of(source)?;
        self.read_adc(ch, t_s).ok()
    }
}

#[cfg(test)]
mod tests;

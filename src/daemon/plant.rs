//! The daemon's configuration turned into the simulation core's plant and devices: which
//! model files, where the vehicle starts, the line and tick settings of the emulators.

use super::clock::TimeMode;
use super::config::{DaemonConfig, Endpoint};
use crate::config::{ConfigError, ConfigSource};
use crate::devices::multiplexer::Multiplexer;
use crate::devices::sensor_board::{BoardSettings, SensorBoard};
pub use crate::engine::plant::MakoPlant;
use crate::physics;
use crate::sensors::SensorsConfig;

impl MakoPlant {
    /// Builds the vehicle, world and sensors named by `config` from `source`.
    pub fn from_config(
        source: &dyn ConfigSource,
        config: &DaemonConfig,
    ) -> Result<Self, ConfigError> {
        // A file that cannot be read is reported with the key that named it.
        let named_by = |key: &'static str, name: &str| {
            let name = name.to_string();
            move |e: ConfigError| match e {
                ConfigError::Unreadable { .. } => ConfigError::Referenced {
                    origin: config.origin.clone(),
                    key: key.into(),
                    name,
                    source: Box::new(e),
                },
                other => other,
            }
        };
        let vehicle = physics::load_vehicle(source, &config.vehicle)
            .map_err(named_by("vehicle", &config.vehicle))?;
        let world =
            physics::load_world(source, &config.world).map_err(named_by("world", &config.world))?;
        let model = physics::Model::new(vehicle, world);
        if let Some(why) = model.world().outside_pool(&config.start.position_m) {
            return Err(ConfigError::Invalid {
                origin: config.origin.clone(),
                key: "start.position_m".into(),
                line: config.start_line,
                message: format!("{why} (world `{}`)", config.world),
            });
        }
        let sensors_config = SensorsConfig::load(source, &config.sensors)
            .map_err(named_by("sensors", &config.sensors))?;
        Ok(MakoPlant::at_start(
            model,
            &sensors_config,
            config.start.position_m,
            config.start.heading_deg,
            config.seed,
        ))
    }
}

/// The device emulators for `config`.
pub fn devices(config: &DaemonConfig) -> (SensorBoard, Multiplexer) {
    let shared = config.sensor.endpoint == Endpoint::SharedWithSonar;
    let line = if shared {
        config.sonar.line
    } else {
        config.sensor.line
    };
    let board = SensorBoard::new(BoardSettings {
        tick_ns: config.tick.as_nanos() as u64,
        lockstep: config.time_mode == TimeMode::Lockstep,
        compass_period_ns: config.compass_period.as_nanos() as u64,
        line_chars_per_s: 1.0 / line.char_time_s(),
        watchdog_ns: config.watchdog.map(|d| d.as_nanos() as u64),
        sonar_on_this_line: shared,
    });
    (board, Multiplexer::new(config.multiplexer.clone()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::{DEFAULT_CONFIG, Document, Embedded};

    /// A model file that cannot be read is reported with the key that named it.
    #[test]
    fn a_missing_model_file_names_its_key() {
        let text = Embedded.read(DEFAULT_CONFIG).unwrap();
        let good = DaemonConfig::resolve(&Document::new("default", &text)).unwrap();
        for key in ["vehicle", "world", "sensors"] {
            let mut config = good.clone();
            let slot = match key {
                "vehicle" => &mut config.vehicle,
                "world" => &mut config.world,
                _ => &mut config.sensors,
            };
            *slot = "nowhere/missing.toml".into();
            let err = MakoPlant::from_config(&Embedded, &config)
                .expect_err("a missing file is an error")
                .to_string();
            assert!(
                err.starts_with(&format!("`{key}` = \"nowhere/missing.toml\"")),
                "{err}"
            );
        }
    }

    /// A configured start outside the pool names the file and the line of
    /// `start.position_m`, as every other config error does (it said
    /// `the daemon configuration:?:`).
    #[test]
    fn a_start_outside_the_pool_names_file_and_line() {
        let text = Embedded.read(DEFAULT_CONFIG).unwrap().replace(
            "position_m = [3.0, 2.5, 0.3]",
            "position_m = [300.0, 2.5, 0.3]",
        );
        let config = DaemonConfig::resolve(&Document::new("my/default.toml", &text)).unwrap();
        let line = text
            .lines()
            .position(|l| l.starts_with("position_m = [300.0"))
            .unwrap()
            + 1;
        let err = MakoPlant::from_config(&Embedded, &config)
            .expect_err("outside the pool")
            .to_string();
        assert!(
            err.starts_with(&format!("my/default.toml:{line}: `start.position_m`: ")),
            "{err}"
        );
        assert!(err.contains("outside the pool"), "{err}");
    }
}

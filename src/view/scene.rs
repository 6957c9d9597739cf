//! What the page draws that does not move: the pool, its obstacles, the hull and the sonar
//! transducers, from the same vehicle, world and sensor files the simulation uses.

use serde::Serialize;

use crate::config::{ConfigError, ConfigSource};
use crate::physics::config::Obstacle;
use crate::sensors::SensorsConfig;

/// The static scene, in the world frame (NED: x north, y east, z down), metres.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Scene {
    /// Pool extent: north, east, depth.
    pub pool_m: [f64; 3],
    pub obstacles: Vec<SceneObstacle>,
    /// The hull's half extents (forward, starboard, down) about the box centre.
    pub hull_half_m: [f64; 3],
    pub transducers: Vec<SceneTransducer>,
    /// The sonar's full beam width.
    pub beam_width_deg: f64,
    /// The longest range the detection table covers (the cone's drawn length).
    pub max_range_m: f64,
    /// The water current of the world file (the page shows it as an arrow).
    pub current_mps: [f64; 3],
}

/// An obstacle seen from above.
#[derive(Debug, Clone, PartialEq, Serialize)]
#[serde(tag = "shape", rename_all = "snake_case")]
pub enum SceneObstacle {
    Box {
        centre_m: [f64; 3],
        half_extents_m: [f64; 3],
        yaw_deg: f64,
    },
    Cylinder {
        centre_m: [f64; 3],
        radius_m: f64,
    },
}

/// A sonar transducer on the hull.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SceneTransducer {
    /// The wire's transducer number (1-4).
    pub id: u8,
    pub name: String,
    pub position_body_m: [f64; 3],
    pub azimuth_deg: f64,
    pub elevation_deg: f64,
}

fn arr(v: &nalgebra::Vector3<f64>) -> [f64; 3] {
    [v.x, v.y, v.z]
}

impl Scene {
    /// Loads the vehicle, world and sensor files named `vehicle`, `world`, `sensors` from
    /// `source` (as the daemon and `gap convert` do).
    pub fn load(
        source: &dyn ConfigSource,
        vehicle: &str,
        world: &str,
        sensors: &str,
    ) -> Result<Self, ConfigError> {
        let vehicle = crate::physics::load_vehicle(source, vehicle)?;
        let world = crate::physics::load_world(source, world)?;
        let sensors = SensorsConfig::load(source, sensors)?;
        Ok(Self::new(&vehicle, &world, &sensors))
    }

    pub fn new(
        vehicle: &crate::physics::config::VehicleConfig,
        world: &crate::physics::config::WorldConfig,
        sensors: &SensorsConfig,
    ) -> Self {
        let obstacles = world
            .obstacles
            .iter()
            .map(|o| match o {
                Obstacle::Box {
                    centre_m,
                    half_extents_m,
                    yaw_rad,
                } => SceneObstacle::Box {
                    centre_m: arr(centre_m),
                    half_extents_m: arr(half_extents_m),
                    yaw_deg: yaw_rad.to_degrees(),
                },
                Obstacle::VerticalCylinder {
                    centre_m, radius_m, ..
                } => SceneObstacle::Cylinder {
                    centre_m: arr(centre_m),
                    radius_m: *radius_m,
                },
            })
            .collect();
        let transducers = sensors
            .sonar
            .transducers
            .iter()
            .enumerate()
            .map(|(i, t)| SceneTransducer {
                id: u8::try_from(i + 1).unwrap_or(u8::MAX),
                name: t.name.clone(),
                position_body_m: t.position_body_m,
                azimuth_deg: t.azimuth_deg,
                elevation_deg: t.elevation_deg,
            })
            .collect();
        Self {
            pool_m: arr(&world.pool_m),
            obstacles,
            hull_half_m: arr(&vehicle.half_extents_m),
            transducers,
            beam_width_deg: sensors.sonar.beam_width_deg,
            max_range_m: sensors
                .sonar
                .detection
                .last()
                .map_or(10.0, |(range, _)| *range),
            current_mps: arr(&world.current_mps),
        }
    }
}

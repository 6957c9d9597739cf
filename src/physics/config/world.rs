//! The world file (pool, water, simulation step, contact, obstacles, course starts) resolved
//! into checked values; every range error names the file, the line and the key.

use nalgebra::Vector3;
use serde::Deserialize;

use super::check3;
use crate::config::{ConfigError, Document};
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawWorld {
    pool: RawPool,
    water: RawWater,
    simulation: RawSimulation,
    contact: RawContact,
    #[serde(default, rename = "obstacle")]
    obstacles: Vec<RawObstacle>,
    wall_following: RawWallFollowing,
    #[serde(default)]
    starts: std::collections::BTreeMap<String, RawCourseStart>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCourseStart {
    position_m: [f64; 3],
    heading_deg: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawPool {
    length_m: f64,
    width_m: f64,
    depth_m: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawWater {
    density_kgpm3: f64,
    gravity_mps2: f64,
    current_mps: [f64; 3],
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSimulation {
    step_s: f64,
    max_speed_mps: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawContact {
    restitution: f64,
    friction: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields, tag = "shape", rename_all = "snake_case")]
enum RawObstacle {
    Box {
        centre_m: [f64; 3],
        half_extents_m: [f64; 3],
        #[serde(default)]
        yaw_deg: f64,
    },
    VerticalCylinder {
        centre_m: [f64; 3],
        radius_m: f64,
        height_m: f64,
    },
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawWallFollowing {
    start_m: [f64; 3],
    heading_deg: f64,
    wall_distance_m: f64,
    side: WallSide,
}

/// Which side of the vehicle the followed wall is on.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum WallSide {
    Port,
    Starboard,
}

/// A static obstacle in the pool (world frame, NED).
#[derive(Debug, Clone, PartialEq)]
pub enum Obstacle {
    Box {
        centre_m: Vector3<f64>,
        half_extents_m: Vector3<f64>,
        yaw_rad: f64,
    },
    VerticalCylinder {
        centre_m: Vector3<f64>,
        radius_m: f64,
        height_m: f64,
    },
}

/// The wall-following course (thesis 4.8): where a run starts and what it keeps.
#[derive(Debug, Clone, PartialEq)]
pub struct WallFollowing {
    pub start_m: Vector3<f64>,
    pub heading_rad: f64,
    pub wall_distance_m: f64,
    pub side: WallSide,
}

/// A named place a run can start from (`eyebot-hil run --start NAME`).
#[derive(Debug, Clone, PartialEq)]
pub struct CourseStart {
    pub name: String,
    /// Centre of mass, NED (m).
    pub position_m: Vector3<f64>,
    /// Compass heading (deg, clockwise from north).
    pub heading_deg: f64,
}

/// How far inside the pool's side walls a start must lie (m): Mako's half-width (0.32 m)
/// less a little, so a vehicle started there does not begin inside a wall.
pub const START_CLEARANCE_M: f64 = 0.3;

/// The world, resolved.
#[derive(Debug, Clone, PartialEq)]
pub struct WorldConfig {
    /// Pool extent along north (x), east (y) and depth (z); the origin is a surface corner.
    pub pool_m: Vector3<f64>,
    pub water_density_kgpm3: f64,
    pub gravity_mps2: f64,
    /// Steady water current, world frame (NED).
    pub current_mps: Vector3<f64>,
    pub step_s: f64,
    /// Divergence guard: a body speed above this stops the run with an error.
    pub max_speed_mps: f64,
    pub restitution: f64,
    pub friction: f64,
    pub obstacles: Vec<Obstacle>,
    pub wall_following: WallFollowing,
    /// Named course starts in name order: the `[starts.NAME]` tables and `wall_following`.
    pub starts: Vec<CourseStart>,
}

impl WorldConfig {
    /// Parses and resolves a world file.
    pub fn from_document(doc: &Document<'_>) -> Result<Self, ConfigError> {
        let raw: RawWorld = doc.parse()?;
        let pool_m = Vector3::new(
            doc.check_range("pool.length_m", raw.pool.length_m, 2.0, 1000.0, "m")?,
            doc.check_range("pool.width_m", raw.pool.width_m, 2.0, 1000.0, "m")?,
            doc.check_range("pool.depth_m", raw.pool.depth_m, 0.6, 100.0, "m")?,
        );
        let step_s =
            doc.check_range("simulation.step_s", raw.simulation.step_s, 1e-4, 0.02, "s")?;
        let obstacles = resolve_obstacles(doc, raw.obstacles)?;
        let wf = raw.wall_following;
        let start_m = check3(doc, "wall_following.start_m", wf.start_m, 0.0, 1e3, "m")?;
        if let Some(why) = outside_pool(&pool_m, &start_m) {
            return Err(doc.invalid("wall_following.start_m", why));
        }
        let starts = resolve_starts(doc, &pool_m, &raw.starts, start_m, wf.heading_deg)?;
        Ok(WorldConfig {
            pool_m,
            water_density_kgpm3: doc.check_range(
                "water.density_kgpm3",
                raw.water.density_kgpm3,
                900.0,
                1100.0,
                "kg/m^3",
            )?,
            gravity_mps2: doc.check_range(
                "water.gravity_mps2",
                raw.water.gravity_mps2,
                9.7,
                9.9,
                "m/s^2",
            )?,
            current_mps: check3(
                doc,
                "water.current_mps",
                raw.water.current_mps,
                -2.0,
                2.0,
                "m/s",
            )?,
            step_s,
            max_speed_mps: doc.check_range(
                "simulation.max_speed_mps",
                raw.simulation.max_speed_mps,
                0.5,
                100.0,
                "m/s",
            )?,
            restitution: doc.check_range(
                "contact.restitution",
                raw.contact.restitution,
                0.0,
                1.0,
                "",
            )?,
            friction: doc.check_range("contact.friction", raw.contact.friction, 0.0, 2.0, "")?,
            obstacles,
            wall_following: WallFollowing {
                start_m,
                heading_rad: doc
                    .check_range(
                        "wall_following.heading_deg",
                        wf.heading_deg,
                        -360.0,
                        360.0,
                        "deg",
                    )?
                    .to_radians(),
                wall_distance_m: doc.check_range(
                    "wall_following.wall_distance_m",
                    wf.wall_distance_m,
                    0.1,
                    100.0,
                    "m",
                )?,
                side: wf.side,
            },
            starts,
        })
    }

    /// The course start called `name`.
    pub fn start_named(&self, name: &str) -> Option<&CourseStart> {
        self.starts.iter().find(|s| s.name == name)
    }

    /// Why a vehicle with its centre of mass at `position_m` (NED) cannot start there, or
    /// `None` when it can: inside the pool, at least [`START_CLEARANCE_M`] from each side
    /// wall, between the surface and the floor.
    pub fn outside_pool(&self, position_m: &Vector3<f64>) -> Option<String> {
        outside_pool(&self.pool_m, position_m)
    }
}

/// Checks the `[[obstacle]]` tables, in file order.
fn resolve_obstacles(
    doc: &Document<'_>,
    raw: Vec<RawObstacle>,
) -> Result<Vec<Obstacle>, ConfigError> {
    let mut obstacles = Vec::with_capacity(raw.len());
    for (i, o) in raw.into_iter().enumerate() {
        obstacles.push(resolve_obstacle(doc, &format!("obstacle.{i}"), o)?);
    }
    Ok(obstacles)
}

/// Checks one obstacle table (`key` is `obstacle.N`); a box's yaw becomes radians.
fn resolve_obstacle(
    doc: &Document<'_>,
    key: &str,
    o: RawObstacle,
) -> Result<Obstacle, ConfigError> {
    Ok(match o {
        RawObstacle::Box {
            centre_m,
            half_extents_m,
            yaw_deg,
        } => Obstacle::Box {
            centre_m: check3(doc, &format!("{key}.centre_m"), centre_m, -1e3, 1e3, "m")?,
            half_extents_m: check3(
                doc,
                &format!("{key}.half_extents_m"),
                half_extents_m,
                0.01,
                1e3,
                "m",
            )?,
            yaw_rad: doc
                .check_range(&format!("{key}.yaw_deg"), yaw_deg, -360.0, 360.0, "deg")?
                .to_radians(),
        },
        RawObstacle::VerticalCylinder {
            centre_m,
            radius_m,
            height_m,
        } => Obstacle::VerticalCylinder {
            centre_m: check3(doc, &format!("{key}.centre_m"), centre_m, -1e3, 1e3, "m")?,
            radius_m: doc.check_range(&format!("{key}.radius_m"), radius_m, 0.01, 100.0, "m")?,
            height_m: doc.check_range(&format!("{key}.height_m"), height_m, 0.01, 100.0, "m")?,
        },
    })
}

/// Checks the named `[starts.NAME]` course starts (each inside the pool) and returns them in
/// name order, with the wall-following start (`wall_start_m`, `wall_heading_deg`) added as
/// `wall_following` unless the file names a start so itself.
fn resolve_starts(
    doc: &Document<'_>,
    pool_m: &Vector3<f64>,
    raw: &std::collections::BTreeMap<String, RawCourseStart>,
    wall_start_m: Vector3<f64>,
    wall_heading_deg: f64,
) -> Result<Vec<CourseStart>, ConfigError> {
    let mut starts = Vec::with_capacity(raw.len() + 1);
    for (name, st) in raw {
        let key = format!("starts.{name}.position_m");
        let position_m = check3(doc, &key, st.position_m, -1e3, 1e3, "m")?;
        if let Some(why) = outside_pool(pool_m, &position_m) {
            return Err(doc.invalid(&key, why));
        }
        let heading_deg = doc.check_range(
            &format!("starts.{name}.heading_deg"),
            st.heading_deg,
            -360.0,
            360.0,
            "deg",
        )?;
        starts.push(CourseStart {
            name: name.clone(),
            position_m,
            heading_deg,
        });
    }
    if !raw.contains_key("wall_following") {
        starts.push(CourseStart {
            name: "wall_following".into(),
            position_m: wall_start_m,
            heading_deg: wall_heading_deg,
        });
        starts.sort_by(|a, b| a.name.cmp(&b.name));
    }
    Ok(starts)
}

fn outside_pool(pool_m: &Vector3<f64>, p: &Vector3<f64>) -> Option<String> {
    let c = START_CLEARANCE_M;
    let (l, w, d) = (pool_m.x, pool_m.y, pool_m.z);
    let why = if !(c..=l - c).contains(&p.x) {
        format!(
            "north {:.2} m is not within {c}..{:.2} m (the pool is {l} m long)",
            p.x,
            l - c
        )
    } else if !(c..=w - c).contains(&p.y) {
        format!(
            "east {:.2} m is not within {c}..{:.2} m (the pool is {w} m wide)",
            p.y,
            w - c
        )
    } else if !(0.0..=d).contains(&p.z) {
        format!(
            "depth {:.2} m is not within 0..{d} m (the pool is {d} m deep)",
            p.z
        )
    } else {
        return None;
    };
    Some(format!("the start lies outside the pool: {why}"))
}

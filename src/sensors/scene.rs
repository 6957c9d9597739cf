//! Analytic worlds: plane walls and open water, the geometry of the thesis table's sonar
//! rows (`thesis::sensors`, where a wall stands at a known distance) and of the sensor
//! tests. The daemon uses the physics crate's rapier3d pool; all implement [`RayCaster`].
//!
//! `BoxPool`, a stand-in for that pool in tests and benchmarks, is a test double: it is
//! compiled for this crate's tests and, through the `test-support` feature, for other
//! crates' tests and benchmarks, never into the binary.

use nalgebra::{Point3, Unit, Vector3};

use crate::physics::state::{RayCaster, RayHit};

/// An infinite plane; rays hit it from the side its normal points to.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PlaneWall {
    pub point_m: Point3<f64>,
    /// Unit normal pointing into the water.
    pub normal: Unit<Vector3<f64>>,
}

impl PlaneWall {
    fn hit(
        &self,
        origin: &Point3<f64>,
        dir: &Unit<Vector3<f64>>,
        max_range_m: f64,
    ) -> Option<RayHit> {
        let closing = dir.dot(&self.normal);
        if closing >= -1e-12 {
            return None;
        }
        let s = (self.point_m - origin).dot(&self.normal) / closing;
        (0.0..=max_range_m).contains(&s).then_some(RayHit {
            distance_m: s,
            normal: self.normal,
        })
    }
}

impl RayCaster for PlaneWall {
    fn cast_ray(
        &self,
        origin_m: &Point3<f64>,
        direction: &Unit<Vector3<f64>>,
        max_range_m: f64,
    ) -> Option<RayHit> {
        self.hit(origin_m, direction, max_range_m)
    }
}

/// A box pool in NED: walls at x = 0 and x = length, y = 0 and y = width, floor at z = depth.
/// The water surface is not a reflector here.
#[cfg(any(test, feature = "test-support"))]
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct BoxPool {
    walls: [PlaneWall; 5],
}

#[cfg(any(test, feature = "test-support"))]
impl BoxPool {
    pub fn new(length_m: f64, width_m: f64, depth_m: f64) -> Self {
        let wall = |p: [f64; 3], n: [f64; 3]| PlaneWall {
            point_m: Point3::from(p),
            normal: Unit::new_normalize(Vector3::from(n)),
        };
        Self {
            walls: [
                wall([0.0, 0.0, 0.0], [1.0, 0.0, 0.0]),
                wall([length_m, 0.0, 0.0], [-1.0, 0.0, 0.0]),
                wall([0.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
                wall([0.0, width_m, 0.0], [0.0, -1.0, 0.0]),
                wall([0.0, 0.0, depth_m], [0.0, 0.0, -1.0]),
            ],
        }
    }
}

#[cfg(any(test, feature = "test-support"))]
impl RayCaster for BoxPool {
    fn cast_ray(
        &self,
        origin_m: &Point3<f64>,
        direction: &Unit<Vector3<f64>>,
        max_range_m: f64,
    ) -> Option<RayHit> {
        nearest(&self.walls, origin_m, direction, max_range_m)
    }
}

/// The nearest hit of a ray among plane walls.
fn nearest(
    walls: &[PlaneWall],
    origin_m: &Point3<f64>,
    direction: &Unit<Vector3<f64>>,
    max_range_m: f64,
) -> Option<RayHit> {
    walls
        .iter()
        .filter_map(|w| w.hit(origin_m, direction, max_range_m))
        .min_by(|a, b| a.distance_m.total_cmp(&b.distance_m))
}

/// Any number of plane walls; a ray hits the nearest.
#[derive(Debug, Clone, PartialEq)]
pub struct Walls(pub Vec<PlaneWall>);

impl RayCaster for Walls {
    fn cast_ray(
        &self,
        origin_m: &Point3<f64>,
        direction: &Unit<Vector3<f64>>,
        max_range_m: f64,
    ) -> Option<RayHit> {
        nearest(&self.0, origin_m, direction, max_range_m)
    }
}

/// A world with nothing in it.
#[derive(Debug, Clone, Copy, Default)]
pub struct OpenWater;

impl RayCaster for OpenWater {
    fn cast_ray(&self, _: &Point3<f64>, _: &Unit<Vector3<f64>>, _: f64) -> Option<RayHit> {
        None
    }
}

/// A vehicle at rest at `position_m` with `attitude` (all velocities zero; the specific force
/// is gravity's reaction, (0, 0, -g) in the world frame). For tests, validation and benches.
pub fn at_rest(
    t_s: f64,
    position_m: Vector3<f64>,
    attitude: nalgebra::UnitQuaternion<f64>,
) -> crate::physics::state::VehicleState {
    let g = Vector3::new(0.0, 0.0, -super::accelerometer::G0_MPS2);
    crate::physics::state::VehicleState {
        t_s,
        position_m,
        attitude,
        velocity_body_mps: Vector3::zeros(),
        angular_velocity_body_radps: Vector3::zeros(),
        velocity_water_body_mps: Vector3::zeros(),
        specific_force_body_mps2: attitude.inverse_transform_vector(&g),
        angular_accel_body_radps2: Vector3::zeros(),
        thruster_force_n: [0.0; 4],
        thruster_effort: [0.0; 4],
        in_contact: false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn box_pool_hits_the_nearest_wall_with_an_inward_normal() {
        let pool = BoxPool::new(25.0, 10.0, 3.0);
        let o = Point3::new(5.0, 2.0, 1.0);
        let west = Unit::new_normalize(Vector3::new(0.0, -1.0, 0.0));
        let hit = pool.cast_ray(&o, &west, 50.0).unwrap();
        assert!((hit.distance_m - 2.0).abs() < 1e-12);
        assert!((hit.normal.y - 1.0).abs() < 1e-12);
        assert!(pool.cast_ray(&o, &west, 1.5).is_none());
        let up = Unit::new_normalize(Vector3::new(0.0, 0.0, -1.0));
        assert!(pool.cast_ray(&o, &up, 50.0).is_none());
    }
}

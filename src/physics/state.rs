//! What the physics exposes to the sensors: a snapshot of the vehicle, and ray casts into the
//! world geometry. Sensors depend on these two items only, never on rapier3d directly.

use nalgebra::{Point3, Unit, UnitQuaternion, Vector3};

/// Index of each thruster in every per-thruster array.
pub const PORT: usize = 0;
/// Starboard horizontal thruster.
pub const STARBOARD: usize = 1;
/// Bow vertical thruster.
pub const BOW: usize = 2;
/// Stern vertical thruster (the one nearest the depth sensor).
pub const STERN: usize = 3;

/// A snapshot of the vehicle after a physics step. SI units; world frame NED, body frame
/// forward-starboard-down (see [`crate::physics`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct VehicleState {
    /// Simulated time since the start of the run.
    pub t_s: f64,
    /// Position of the centre of mass in the world frame (`z` = depth of the CG).
    pub position_m: Vector3<f64>,
    /// Rotation taking body-frame vectors into the world frame.
    pub attitude: UnitQuaternion<f64>,
    /// Body-frame linear velocity over ground (u, v, w).
    pub velocity_body_mps: Vector3<f64>,
    /// Body-frame angular velocity (p, q, r).
    pub angular_velocity_body_radps: Vector3<f64>,
    /// Body-frame linear velocity relative to the water (differs from `velocity_body_mps`
    /// when a current flows). The paddle wheel turns with its x component.
    pub velocity_water_body_mps: Vector3<f64>,
    /// Specific force at the centre of mass in the body frame: the kinematic acceleration
    /// minus gravity, i.e. what an ideal accelerometer reads (at rest, level: (0, 0, -g)).
    pub specific_force_body_mps2: Vector3<f64>,
    /// Body-frame angular acceleration (p, q, r rates of change), for the specific force at a
    /// point away from the centre of mass.
    pub angular_accel_body_radps2: Vector3<f64>,
    /// Thrust each thruster produces now, after its lag (N; + = forward / down).
    pub thruster_force_n: [f64; 4],
    /// Signed PWM on-fraction commanded to each motor driver (-1..1; sign = direction).
    /// The depth sensor's EMI grows with the stern motor's magnitude.
    pub thruster_effort: [f64; 4],
    /// True while the hull touches a wall, the floor or an obstacle.
    pub in_contact: bool,
}

impl VehicleState {
    /// Roll, pitch and yaw (ZYX Euler angles, radians; yaw is the heading from north,
    /// clockwise seen from above).
    pub fn euler_rad(&self) -> (f64, f64, f64) {
        self.attitude.euler_angles()
    }

    /// Specific force at a body-frame point (m from the centre of mass) in the body frame:
    /// the centre's plus the point's tangential and centripetal accelerations of the rigid
    /// hull, `w_dot x p + w x (w x p)`. An accelerometer ahead of the centre reads a spin's
    /// angular acceleration in its sway axis.
    pub fn specific_force_at(&self, point_body_m: &Vector3<f64>) -> Vector3<f64> {
        let w = self.angular_velocity_body_radps;
        self.specific_force_body_mps2
            + self.angular_accel_body_radps2.cross(point_body_m)
            + w.cross(&w.cross(point_body_m))
    }

    /// Depth of a body-frame point below the surface (m).
    pub fn depth_of_m(&self, point_body_m: &Vector3<f64>) -> f64 {
        (self.position_m + self.attitude * point_body_m).z
    }
}

/// Where a ray met the world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct RayHit {
    /// Distance from the ray origin to the hit.
    pub distance_m: f64,
    /// Outward surface normal at the hit, world frame.
    pub normal: Unit<Vector3<f64>>,
}

/// Ray casts into the world's static geometry (pool walls, floor, obstacles). The physics
/// world implements it with rapier3d's query pipeline; sensor tests may use simpler scenes.
pub trait RayCaster {
    /// The nearest hit along `direction` from `origin_m` within `max_range_m`, if any.
    fn cast_ray(
        &self,
        origin_m: &Point3<f64>,
        direction: &Unit<Vector3<f64>>,
        max_range_m: f64,
    ) -> Option<RayHit>;
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A point 0.1 m ahead of the centre of mass, in a spin at 1 rad/s that speeds up at
    /// 2 rad/s^2, reads the centre's specific force plus its centripetal acceleration
    /// (-r^2 x = -0.1 m/s^2, towards the centre) in surge and its tangential acceleration
    /// (r_dot x = 0.2 m/s^2) in sway; the centre itself reads only the centre's.
    #[test]
    fn a_point_ahead_of_the_centre_reads_the_spins_accelerations() {
        let s = VehicleState {
            t_s: 0.0,
            position_m: Vector3::new(5.0, 5.0, 1.0),
            attitude: UnitQuaternion::identity(),
            velocity_body_mps: Vector3::zeros(),
            angular_velocity_body_radps: Vector3::new(0.0, 0.0, 1.0),
            velocity_water_body_mps: Vector3::zeros(),
            specific_force_body_mps2: Vector3::new(0.0, 0.0, -9.81),
            angular_accel_body_radps2: Vector3::new(0.0, 0.0, 2.0),
            thruster_force_n: [0.0; 4],
            thruster_effort: [0.0; 4],
            in_contact: false,
        };
        let centre = s.specific_force_at(&Vector3::zeros());
        assert_eq!(centre, s.specific_force_body_mps2);
        let ahead = s.specific_force_at(&Vector3::new(0.1, 0.0, 0.0)) - centre;
        assert!(
            (ahead - Vector3::new(-0.1, 0.2, 0.0)).norm() < 1e-12,
            "{ahead}"
        );
    }
}

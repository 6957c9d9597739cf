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

//! The pool: static rapier3d colliders (floor, four walls, obstacles), contact queries for the
//! hull and ray casts for the sonar.
//!
//! Only geometry comes from rapier (parry underneath); rapier's dynamics are not used, because
//! the vehicle is integrated by our own 6-DOF solver. rapier is f32 with glam math, so poses
//! are converted at this boundary. The walls and floor are 1 m thick boxes outside the water
//! volume, far thicker than the vehicle moves in one step (< 1 cm), so nothing tunnels.
//! A wall's box finds the hull in the broad phase; its contact is computed against the plane
//! of its face toward the water (a half-space), which is exact for a hull that meets one face
//! and costs one support point, where box against box takes GJK and EPA.

use nalgebra::{Point3, Unit, UnitQuaternion, Vector3};
use rapier3d::dynamics::{IntegrationParameters, RigidBodySet};
use rapier3d::geometry::{Aabb, BroadPhaseBvh, ColliderBuilder, ColliderHandle, ColliderSet, Ray};
use rapier3d::math::{Pose, Rotation, Vector};
use rapier3d::parry::query::{self, DefaultQueryDispatcher};
use rapier3d::parry::shape::{Cuboid, HalfSpace};
use rapier3d::pipeline::{QueryFilter, QueryPipeline};

use crate::physics::config::{Obstacle, WorldConfig};
use crate::physics::state::{RayCaster, RayHit};

/// Thickness of the wall and floor boxes.
const WALL_THICKNESS_M: f32 = 1.0;

/// One contact between the hull and the static world.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Contact {
    /// Point on the hull's surface, world frame.
    pub point_m: Vector3<f64>,
    /// Unit normal pointing from the obstacle into the hull (the direction to push it out).
    pub normal: Vector3<f64>,
    /// Signed distance: negative when penetrating.
    pub distance_m: f64,
}

/// The pool's static geometry.
pub struct Pool {
    bodies: RigidBodySet,
    colliders: ColliderSet,
    broad_phase: BroadPhaseBvh,
    /// The face toward the water of each wall and of the floor: the collider, the face's
    /// pose and its half-space (normal out of the wall, into the water).
    faces: Vec<(ColliderHandle, Pose, HalfSpace)>,
    size_m: Vector3<f64>,
}

impl std::fmt::Debug for Pool {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Pool")
            .field("size_m", &self.size_m)
            .field("colliders", &self.colliders.len())
            .finish()
    }
}

fn vec32(v: &Vector3<f64>) -> Vector {
    Vector::new(v.x as f32, v.y as f32, v.z as f32)
}

fn vec64(v: Vector) -> Vector3<f64> {
    Vector3::new(f64::from(v.x), f64::from(v.y), f64::from(v.z))
}

/// A rapier pose from a nalgebra f64 position and attitude.
fn pose32(position_m: &Vector3<f64>, attitude: &UnitQuaternion<f64>) -> Pose {
    let q = attitude.quaternion();
    Pose::from_parts(
        vec32(position_m),
        Rotation::from_xyzw(q.i as f32, q.j as f32, q.k as f32, q.w as f32),
    )
}

impl Pool {
    /// Builds the pool, walls, floor and obstacles of a world.
    pub fn new(world: &WorldConfig) -> Self {
        let mut colliders = ColliderSet::new();
        let (l, w, d) = (
            world.pool_m.x as f32,
            world.pool_m.y as f32,
            world.pool_m.z as f32,
        );
        let t = WALL_THICKNESS_M;
        // Walls reach 1 m above the surface so a surfaced hull still meets them.
        let wall_top = -1.0_f32;
        let wall_h = (d + t - wall_top) / 2.0;
        let wall_cz = (wall_top + d + t) / 2.0;
        // (centre, half extents, the face toward the water: a point on it and its normal).
        let boxes = [
            // floor
            (
                Vector::new(l / 2.0, w / 2.0, d + t / 2.0),
                Vector::new(l / 2.0 + t, w / 2.0 + t, t / 2.0),
                Vector::new(0.0, 0.0, d),
                Vector::new(0.0, 0.0, -1.0),
            ),
            // north and south walls (x = l, x = 0)
            (
                Vector::new(l + t / 2.0, w / 2.0, wall_cz),
                Vector::new(t / 2.0, w / 2.0 + t, wall_h),
                Vector::new(l, 0.0, 0.0),
                Vector::new(-1.0, 0.0, 0.0),
            ),
            (
                Vector::new(-t / 2.0, w / 2.0, wall_cz),
                Vector::new(t / 2.0, w / 2.0 + t, wall_h),
                Vector::new(0.0, 0.0, 0.0),
                Vector::new(1.0, 0.0, 0.0),
            ),
            // east and west walls (y = w, y = 0)
            (
                Vector::new(l / 2.0, w + t / 2.0, wall_cz),
                Vector::new(l / 2.0 + t, t / 2.0, wall_h),
                Vector::new(0.0, w, 0.0),
                Vector::new(0.0, -1.0, 0.0),
            ),
            (
                Vector::new(l / 2.0, -t / 2.0, wall_cz),
                Vector::new(l / 2.0 + t, t / 2.0, wall_h),
                Vector::new(0.0, 0.0, 0.0),
                Vector::new(0.0, 1.0, 0.0),
            ),
        ];
        let mut faces = Vec::with_capacity(boxes.len());
        for (centre, half, on_face, normal) in boxes {
            let handle = colliders.insert(
                ColliderBuilder::cuboid(half.x, half.y, half.z)
                    .translation(centre)
                    .build(),
            );
            faces.push((
                handle,
                Pose::from_translation(on_face),
                HalfSpace::new(normal),
            ));
        }
        for o in &world.obstacles {
            let collider = match o {
                Obstacle::Box {
                    centre_m,
                    half_extents_m,
                    yaw_rad,
                } => ColliderBuilder::cuboid(
                    half_extents_m.x as f32,
                    half_extents_m.y as f32,
                    half_extents_m.z as f32,
                )
                .translation(vec32(centre_m))
                .rotation(Vector::new(0.0, 0.0, *yaw_rad as f32)),
                // rapier's cylinder axis is y; turn it to the vertical (z).
                Obstacle::VerticalCylinder {
                    centre_m,
                    radius_m,
                    height_m,
                } => ColliderBuilder::cylinder((*height_m / 2.0) as f32, *radius_m as f32)
                    .translation(vec32(centre_m))
                    .rotation(Vector::new(std::f32::consts::FRAC_PI_2, 0.0, 0.0)),
            };
            colliders.insert(collider.build());
        }
        let mut broad_phase = BroadPhaseBvh::new();
        let params = IntegrationParameters::default();
        for (handle, collider) in colliders.iter() {
            broad_phase.set_aabb(&params, handle, collider.compute_aabb());
        }
        Self {
            bodies: RigidBodySet::new(),
            colliders,
            broad_phase,
            faces,
            size_m: world.pool_m,
        }
    }

    /// Pool extent (north, east, depth).
    pub fn size_m(&self) -> Vector3<f64> {
        self.size_m
    }

    fn query_pipeline(&self) -> QueryPipeline<'_> {
        self.broad_phase.as_query_pipeline(
            &DefaultQueryDispatcher,
            &self.bodies,
            &self.colliders,
            QueryFilter::default(),
        )
    }

    /// Contacts between a box-shaped hull (half extents, centre pose) and the static world,
    /// including touching pairs closer than `prediction_m`. The broad phase (rapier's BVH)
    /// skips the narrow phase entirely while the hull is away from every collider.
    pub fn hull_contacts(
        &self,
        half_extents_m: &Vector3<f64>,
        centre_m: &Vector3<f64>,
        attitude: &UnitQuaternion<f64>,
        prediction_m: f64,
        out: &mut Vec<Contact>,
    ) {
        out.clear();
        // World-frame half extents of the rotated box: |R| * h.
        let r = attitude.to_rotation_matrix();
        let m = r.matrix().abs();
        let ext = m * half_extents_m + Vector3::repeat(prediction_m);
        let aabb = Aabb::new(vec32(&(centre_m - ext)), vec32(&(centre_m + ext)));
        let pipeline = self.query_pipeline();
        let hull = Cuboid::new(vec32(half_extents_m));
        let hull_pose = pose32(centre_m, attitude);
        for (handle, collider) in pipeline.intersect_aabb_conservative(aabb) {
            let contact = match self.faces.iter().find(|(h, _, _)| *h == handle) {
                Some((_, pose, face)) => {
                    query::contact(pose, face, &hull_pose, &hull, prediction_m as f32)
                }
                None => query::contact(
                    collider.position(),
                    collider.shape(),
                    &hull_pose,
                    &hull,
                    prediction_m as f32,
                ),
            };
            if let Ok(Some(c)) = contact {
                out.push(Contact {
                    point_m: vec64(c.point2),
                    normal: vec64(c.normal1),
                    distance_m: f64::from(c.dist),
                });
            }
        }
    }
}

impl RayCaster for Pool {
    fn cast_ray(
        &self,
        origin_m: &Point3<f64>,
        direction: &Unit<Vector3<f64>>,
        max_range_m: f64,
    ) -> Option<RayHit> {
        if !(max_range_m.is_finite() && max_range_m > 0.0) {
            return None;
        }
        let ray = Ray::new(vec32(&origin_m.coords), vec32(direction));
        let (_, hit) =
            self.query_pipeline()
                .cast_ray_and_get_normal(&ray, max_range_m as f32, true)?;
        let normal = vec64(hit.normal);
        Some(RayHit {
            distance_m: f64::from(hit.time_of_impact),
            normal: Unit::try_new(normal, 1e-6).unwrap_or_else(|| -*direction),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::config::Document;

    fn pool() -> Pool {
        let w = WorldConfig::from_document(&Document::new(
            "pool.toml",
            include_str!("../../configs/worlds/pool.toml"),
        ))
        .expect("the shipped pool parses");
        Pool::new(&w)
    }

    /// The contact against each wall's face is the one GJK/EPA finds between the hull and the
    /// wall's box: the same depth and normal, for a hull that meets one face tilted and turned.
    #[test]
    fn face_contacts_agree_with_box_against_box() {
        let pool = pool();
        let half = Vector3::new(0.5, 0.3, 0.2);
        let size = pool.size_m();
        // (centre, roll, pitch, yaw): each a few cm into one face.
        let poses = [
            (Vector3::new(size.x - 0.5, 6.0, 0.8), 0.05, -0.1, 0.2),
            (Vector3::new(0.45, 6.0, 0.8), -0.1, 0.07, 2.9),
            (Vector3::new(12.0, size.y - 0.3, 1.0), 0.2, 0.0, 1.2),
            (Vector3::new(12.0, 0.28, 1.0), 0.0, 0.15, -1.4),
            (Vector3::new(12.0, 6.0, size.z - 0.21), 0.1, -0.05, 0.7),
        ];
        for (centre, r, p, y) in poses {
            let attitude = UnitQuaternion::from_euler_angles(r, p, y);
            let mut faces = Vec::new();
            pool.hull_contacts(&half, &centre, &attitude, 0.002, &mut faces);
            assert_eq!(faces.len(), 1, "one face touched at {centre:?}");
            let hull = Cuboid::new(vec32(&half));
            let hull_pose = pose32(&centre, &attitude);
            let (handle, _, _) = pool
                .faces
                .iter()
                .find(|(_, _, face)| (vec64(face.normal) - faces[0].normal).norm() < 1e-6)
                .expect("the contact's normal is a face's");
            let wall = &pool.colliders[*handle];
            let boxed = query::contact(wall.position(), wall.shape(), &hull_pose, &hull, 0.002)
                .expect("supported shapes")
                .expect("the boxes touch");
            assert!(
                (f64::from(boxed.dist) - faces[0].distance_m).abs() < 1e-4,
                "depth {} against {}",
                faces[0].distance_m,
                boxed.dist
            );
            assert!((vec64(boxed.normal1) - faces[0].normal).norm() < 1e-3);
        }
    }

    /// Away from every wall nothing is reported; an obstacle still meets the hull.
    #[test]
    fn open_water_has_no_contacts_and_obstacles_still_touch() {
        let mut faces = Vec::new();
        let half = Vector3::new(0.5, 0.3, 0.2);
        pool().hull_contacts(
            &half,
            &Vector3::new(12.0, 6.0, 1.0),
            &UnitQuaternion::identity(),
            0.002,
            &mut faces,
        );
        assert!(faces.is_empty());
        let text = format!(
            "{}\n[[obstacle]]\nshape = \"box\"\ncentre_m = [12.0, 6.0, 1.5]\n\
             half_extents_m = [0.3, 0.3, 0.5]\nyaw_deg = 0.0\n",
            include_str!("../../configs/worlds/pool.toml")
        );
        let w = WorldConfig::from_document(&Document::new("pool.toml", &text))
            .expect("the pool with an obstacle parses");
        Pool::new(&w).hull_contacts(
            &half,
            &Vector3::new(12.0, 6.0, 0.82),
            &UnitQuaternion::identity(),
            0.002,
            &mut faces,
        );
        assert_eq!(faces.len(), 1);
        assert!((faces[0].distance_m + 0.02).abs() < 1e-4);
        assert!((faces[0].normal - Vector3::new(0.0, 0.0, -1.0)).norm() < 1e-4);
    }
}

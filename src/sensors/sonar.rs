//! Sonar: one Navman 2100 transducer and what its controller makes of an echo
//! (thesis 3.3.2, 4.4, 4.8).
//!
//! **Beam.** A cone of rays, `beam_width_deg` full width: the axis plus `cone_rings` rings,
//! ring `k` at `k / rings` of the half width with `6 k` rays. Each ray is cast through the
//! [`RayCaster`]; a ray returns an echo only if it meets the surface within
//! `max_incidence_deg` of the surface normal (a smooth wall reflects specularly). The range
//! is the shortest such ray. Turned towards a wall, the shortest echoing ray leaves the normal,
//! so the range grows with the angle; once no ray is within `max_incidence_deg` of the
//! normal the echo is lost (beyond the beam).
//!
//! **Detection.** `p = p_table(r) * exp(-(beta / sigma)^2 / 2) / (1 + (v / v_half)^2)`:
//! the static rate of thesis table 4.7 interpolated linearly in range; `beta` is the angle
//! between the transducer axis and the surface normal (`incidence_sigma_deg`); `v` the
//! transducer's speed through the water (`speed_half_mps`, thesis fig 4.8). Below the table's
//! first range (2.0 m) the first entry holds down to `min_range_m`; nearer than that the
//! controller reports nothing (ringing). Past the last entry `p = 0`.
//!
//! **Optional effects.** Reverberation: with its probability a valid echo is replaced by the
//! second bounce (twice the range) when that is still inside the table's range. Crosstalk is
//! decided by the multiplexer, which knows what the other controller does.
//!
//! **Output.** The noise package (metres), then whole multiples of `resolution_m`.

use nalgebra::{Point3, Rotation3, Unit, Vector3};
use rand::RngExt;

use super::config::{SonarSettings, TransducerSettings};
use super::noise::ErrorModel;
use super::rng::{self, SensorRng};
use crate::physics::state::{RayCaster, VehicleState};

/// A range as the controller reports it: a whole number of resolution steps (decimetres at
/// the default 0.1 m).
#[derive(Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord)]
pub struct RangeSteps(pub u16);

/// The geometry of one echo.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Echo {
    /// Shortest echoing ray, m.
    pub range_m: f64,
    /// Angle between the transducer axis and the surface normal, deg.
    pub axis_to_normal_deg: f64,
    /// World point the axis-most echoing ray hit.
    pub hit_m: Point3<f64>,
}

/// One transducer: mounting, ray cone, its own noise stream.
#[derive(Debug, Clone)]
pub struct Transducer {
    pub name: String,
    pub controller: usize,
    position_body_m: Vector3<f64>,
    axis_body: Unit<Vector3<f64>>,
    rays_body: Vec<Unit<Vector3<f64>>>,
    errors: ErrorModel,
    rng: SensorRng,
}

impl Transducer {
    pub fn new(t: &TransducerSettings, s: &SonarSettings, master_seed: u64) -> Self {
        let (az, el) = (t.azimuth_deg.to_radians(), t.elevation_deg.to_radians());
        // Azimuth about body z (down, so + turns to starboard), elevation + up (-z).
        let rot = Rotation3::from_axis_angle(&Vector3::z_axis(), az)
            * Rotation3::from_axis_angle(&Vector3::y_axis(), el);
        let axis_body = Unit::new_normalize(rot * Vector3::x());
        let mut rays_body = vec![axis_body];
        let half = (s.beam_width_deg / 2.0).to_radians();
        for k in 1..=s.cone_rings {
            let cone = half * f64::from(k) / f64::from(s.cone_rings);
            let n = 6 * k;
            for j in 0..n {
                let phi = std::f64::consts::TAU * f64::from(j) / f64::from(n);
                let local =
                    Vector3::new(cone.cos(), cone.sin() * phi.cos(), cone.sin() * phi.sin());
                rays_body.push(Unit::new_normalize(rot * local));
            }
        }
        Self {
            name: t.name.clone(),
            controller: t.controller,
            position_body_m: Vector3::from(t.position_body_m),
            axis_body,
            rays_body,
            errors: ErrorModel::new(&s.errors),
            rng: rng::stream(master_seed, &format!("sonar.{}", t.name)),
        }
    }

    pub fn rays(&self) -> usize {
        self.rays_body.len()
    }

    /// World position of the transducer.
    pub fn origin_m(&self, state: &VehicleState) -> Point3<f64> {
        Point3::from(state.position_m + state.attitude * self.position_body_m)
    }

    /// World direction of the beam axis.
    pub fn axis_world(&self, state: &VehicleState) -> Unit<Vector3<f64>> {
        Unit::new_unchecked(state.attitude * self.axis_body.into_inner())
    }

    /// The echo geometry, without chance (`None`: no surface in reach and in the beam).
    pub fn echo(
        &self,
        state: &VehicleState,
        world: &dyn RayCaster,
        s: &SonarSettings,
    ) -> Option<Echo> {
        let origin = self.origin_m(state);
        let max_range = s.detection.last().map_or(0.0, |(r, _)| *r);
        let cos_max = s.max_incidence_deg.to_radians().cos();
        let axis = self.axis_world(state);
        let mut best: Option<Echo> = None;
        for ray in &self.rays_body {
            let dir = Unit::new_unchecked(state.attitude * ray.into_inner());
            let Some(hit) = world.cast_ray(&origin, &dir, max_range) else {
                continue;
            };
            let cos_inc = -dir.dot(&hit.normal);
            if cos_inc + 1e-12 < cos_max {
                continue;
            }
            if best.is_none_or(|b| hit.distance_m < b.range_m) {
                let beta = (-axis.dot(&hit.normal))
                    .clamp(-1.0, 1.0)
                    .acos()
                    .to_degrees();
                best = Some(Echo {
                    range_m: hit.distance_m,
                    axis_to_normal_deg: beta,
                    hit_m: origin + dir.into_inner() * hit.distance_m,
                });
            }
        }
        best
    }

    /// Every ray of the cone that meets a surface within `max_range_m`, without the incidence
    /// cut: `(distance m, angle between the ray and the surface normal deg, angle between the
    /// beam axis and that normal deg)`. For a prediction of how the echo depends on
    /// `max_incidence_deg` (the reality-gap re-simulation).
    pub fn ray_hits(
        &self,
        state: &VehicleState,
        world: &dyn RayCaster,
        max_range_m: f64,
    ) -> Vec<(f64, f64, f64)> {
        let origin = self.origin_m(state);
        let axis = self.axis_world(state);
        self.rays_body
            .iter()
            .filter_map(|ray| {
                let dir = Unit::new_unchecked(state.attitude * ray.into_inner());
                let hit = world.cast_ray(&origin, &dir, max_range_m)?;
                let inc = (-dir.dot(&hit.normal)).clamp(-1.0, 1.0).acos().to_degrees();
                let beta = (-axis.dot(&hit.normal))
                    .clamp(-1.0, 1.0)
                    .acos()
                    .to_degrees();
                Some((hit.distance_m, inc, beta))
            })
            .collect()
    }

    /// Speed of the transducer through the world (m/s).
    pub fn speed_mps(&self, state: &VehicleState) -> f64 {
        (state.velocity_body_mps
            + state
                .angular_velocity_body_radps
                .cross(&self.position_body_m))
        .norm()
    }

    /// One ping at `t_s`: the reported range, or `None` when the controller sees no valid echo.
    pub fn ping(
        &mut self,
        state: &VehicleState,
        world: &dyn RayCaster,
        s: &SonarSettings,
        t_s: f64,
    ) -> Option<RangeSteps> {
        let echo = self.echo(state, world, s)?;
        let p = detection_probability(
            s,
            echo.range_m,
            echo.axis_to_normal_deg,
            self.speed_mps(state),
        );
        self.report(echo.range_m, p, s, t_s)
    }

    /// Decides validity with probability `p` and turns a range into the reported value.
    pub fn report(
        &mut self,
        range_m: f64,
        p: f64,
        s: &SonarSettings,
        t_s: f64,
    ) -> Option<RangeSteps> {
        // Always draw the same number of decisions, so one ping's outcome never shifts the
        // stream for the next.
        let valid = self.rng.random_bool(p.clamp(0.0, 1.0));
        let reverb =
            s.reverberation_probability > 0.0 && self.rng.random_bool(s.reverberation_probability);
        if !valid {
            return None;
        }
        let max_range = s.detection.last().map_or(0.0, |(r, _)| *r);
        let mut r = range_m;
        if reverb {
            if 2.0 * r > max_range {
                return None;
            }
            r *= 2.0;
        }
        self.errors.push(t_s, r);
        let r = self.errors.sample(t_s, &mut self.rng)?;
        let steps = (r / s.resolution_m).round();
        (steps >= 0.0).then_some(RangeSteps(steps.min(f64::from(u16::MAX)) as u16))
    }
}

/// Static detection probability at `range_m` (table 4.7, interpolated; see the module doc).
pub fn table_probability(s: &SonarSettings, range_m: f64) -> f64 {
    let (Some(first), Some(last)) = (s.detection.first(), s.detection.last()) else {
        return 0.0;
    };
    if range_m < s.min_range_m || range_m > last.0 {
        return 0.0;
    }
    if range_m <= first.0 {
        return first.1;
    }
    for w in s.detection.windows(2) {
        let ((r0, p0), (r1, p1)) = (w[0], w[1]);
        if range_m <= r1 {
            return p0 + (p1 - p0) * (range_m - r0) / (r1 - r0);
        }
    }
    last.1
}

/// The full detection probability (module doc).
pub fn detection_probability(
    s: &SonarSettings,
    range_m: f64,
    axis_to_normal_deg: f64,
    speed_mps: f64,
) -> f64 {
    let angle = (-0.5 * (axis_to_normal_deg / s.incidence_sigma_deg).powi(2)).exp();
    let speed = 1.0 / (1.0 + (speed_mps / s.speed_half_mps).powi(2));
    table_probability(s, range_m) * angle * speed
}

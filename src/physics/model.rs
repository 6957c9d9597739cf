//! The 6-DOF vehicle model and its pure stepping function.
//!
//! Equations of motion (Fossen, *Handbook of Marine Craft Hydrodynamics and Motion Control*,
//! 2011, ch. 6-8), written in the velocity relative to the water `nu_r = nu - nu_c`:
//!
//! ```text
//! (M_RB + M_A) nu_r_dot = tau - C_RB(nu_r) nu_r - C_A(nu_r) nu_r - D(nu_r) nu_r - g(eta)
//! eta_dot = J(eta) (nu_r + nu_c)
//! ```
//!
//! For an irrotational, constant current this form is exact when `C_RB` uses the
//! parametrisation independent of linear velocity (Fossen 2011, property 8.1), which is what
//! [`Model::unforced_rates`] implements. The added mass sits inside the constant mass matrix,
//! whose inverse is computed once; nothing is estimated from the last step's acceleration.
//!
//! Integration: classical RK4 on (position, attitude quaternion, `nu_r`) with the thrust held
//! over the step, so its acceleration `M^-1 tau` is computed once a step and added to each
//! stage's unforced rates; the thruster lag and fluctuation are discretised exactly. After the step,
//! contacts with the pool are resolved by a position projection and a 6-DOF impulse through
//! the same inverse mass matrix (restitution plus Coulomb friction).

use std::cell::Cell;
use std::sync::atomic::{AtomicU64, Ordering};

use nalgebra::{Matrix3, Matrix6, Quaternion, UnitQuaternion, Vector3, Vector6};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::physics::config::{VehicleConfig, WorldConfig};
use crate::physics::state::VehicleState;
use crate::physics::thruster::{Direction, ThrusterCommand, ThrusterDynamics, static_thrust_n};
use crate::physics::world::{Contact, Pool};

/// The physics' own RNG stream (ChaCha stream id). Sensors draw from other streams, so adding
/// or removing a sensor never changes the vehicle's trajectory.
pub const PHYSICS_RNG_STREAM: u64 = 0x5048_5953; // "PHYS"

/// Contacts closer than this are resolved speculatively (no approach faster than the gap
/// closes within one step), and count as touching.
const CONTACT_PREDICTION_M: f64 = 0.002;
/// Propeller radius over which a thruster's thrust fades as it leaves the water.
const PROPELLER_RADIUS_M: f64 = 0.05;
/// How far (m) the top of the hull rises out of the water before the surface's heave damping
/// acts in full: a smooth onset keeps the force continuous for the integrator and the fits.
const SURFACE_BAND_M: f64 = 0.005;
/// Divergence guard for angular rate.
const MAX_ANGULAR_RATE_RADPS: f64 = 50.0;
/// How far outside the pool the centre of mass may be before the run counts as diverged.
const OUTSIDE_POOL_LIMIT_M: f64 = 1.0;

/// Why a step could not be taken. The run stops: the state is not advanced further.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum PhysicsError {
    #[error("t = {t_s:.3} s: {quantity} became non-finite")]
    NonFinite { t_s: f64, quantity: &'static str },
    #[error("t = {t_s:.3} s: {quantity} = {value:.3} exceeds the divergence limit {limit:.3}")]
    Diverged {
        t_s: f64,
        quantity: &'static str,
        value: f64,
        limit: f64,
    },
    #[error("thruster index {index} is out of range (0..4)")]
    NoSuchThruster { index: usize },
    #[error("the simulation stopped earlier: {0}")]
    Stopped(Box<PhysicsError>),
}

/// Where and how a run starts (world frame NED; velocities over ground, body frame).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct InitialState {
    pub position_m: Vector3<f64>,
    pub attitude: UnitQuaternion<f64>,
    pub velocity_body_mps: Vector3<f64>,
    pub angular_velocity_body_radps: Vector3<f64>,
}

/// Quantities a re-simulation sets from measurements at a segment boundary
/// ([`Model::reanchor`]); `None` keeps the state's own value. World frame NED.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct Anchor {
    pub north_m: Option<f64>,
    pub east_m: Option<f64>,
    /// Depth of the centre of mass (m).
    pub depth_m: Option<f64>,
    /// Yaw (rad, clockwise from north); roll and pitch are kept.
    pub heading_rad: Option<f64>,
}

/// The rates at a state from everything but the thrust: the body velocity turned into the
/// world frame (the position rate less the current), the quaternion rate, and the
/// acceleration `M^-1 (-C nu_r - D nu_r - g(eta) + surface)`. The thrust's acceleration
/// `M^-1 tau` is added per step, so one evaluation serves any thrust.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Rates {
    velocity_world: Vector3<f64>,
    q_dot: Quaternion<f64>,
    accel: Vector6<f64>,
}

/// The [`Rates`] at a state's own pose and velocity, remembered by whichever of
/// [`Model::vehicle_state`] and [`Model::step`] needs them first, with the identity of the
/// model that computed them. A hit gives the very bits a fresh evaluation would, so the cache
/// never makes two states differ: it takes no part in equality.
#[derive(Debug, Clone, Default)]
struct RatesCache(Cell<Option<(u64, Rates)>>);

impl PartialEq for RatesCache {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl RatesCache {
    fn get(&self, model_id: u64) -> Option<Rates> {
        self.0
            .get()
            .and_then(|(id, r)| (id == model_id).then_some(r))
    }

    fn set(&self, model_id: u64, rates: Rates) {
        self.0.set(Some((model_id, rates)));
    }

    fn clear(&self) {
        self.0.set(None);
    }
}

/// Every [`Model`] gets its own number, so a state's [`RatesCache`] is only read by the model
/// that filled it.
static NEXT_MODEL_ID: AtomicU64 = AtomicU64::new(0);

/// Everything that changes during a run. Cloning it and stepping both copies with the same
/// commands gives bit-identical results.
#[derive(Debug, Clone, PartialEq)]
pub struct SimState {
    step: u64,
    position_m: Vector3<f64>,
    attitude: UnitQuaternion<f64>,
    /// Body velocity relative to the water (u, v, w, p, q, r).
    nu_r: Vector6<f64>,
    thrust_lagged_n: [f64; 4],
    fluctuation: [f64; 4],
    thrust_n: [f64; 4],
    effort: [f64; 4],
    /// Acceleration of the last step's generalised thrust, `M^-1 tau` (body frame, about the CG).
    thrust_accel: Vector6<f64>,
    /// Velocity change from contact impulses in the last step, divided by the step.
    contact_accel: Vector6<f64>,
    in_contact: bool,
    contact_count: u64,
    contact_steps: u64,
    rng: ChaCha8Rng,
    rates: RatesCache,
}

impl SimState {
    /// Number of steps taken.
    pub fn steps(&self) -> u64 {
        self.step
    }

    /// How many separate times the hull has come into contact with the world.
    pub fn contact_count(&self) -> u64 {
        self.contact_count
    }

    /// How many steps ended with the hull touching the world.
    pub fn contact_steps(&self) -> u64 {
        self.contact_steps
    }
}

/// The world's down axis (z, NED) in body axes: the third row of the body-to-world rotation.
fn down_in_body(attitude: &UnitQuaternion<f64>) -> Vector3<f64> {
    attitude.to_rotation_matrix().matrix().row(2).transpose()
}

/// The vehicle in its world: constants precomputed from the configuration. Immutable while
/// stepping, so one model can step many states.
#[derive(Debug)]
pub struct Model {
    /// This instance's number, for [`RatesCache`].
    id: u64,
    vehicle: VehicleConfig,
    world: WorldConfig,
    pool: Pool,
    dt_s: f64,
    mass_kg: f64,
    inertia: Matrix3<f64>,
    added_lin: Vector3<f64>,
    added_ang: Vector3<f64>,
    m_inv: Matrix6<f64>,
    weight_n: f64,
    buoyancy_full_n: f64,
    /// `rho g` times [`VehicleConfig::surface_waterplane_m2`] (N/m).
    waterplane_n_per_m: f64,
    /// From the CG to the centre of the hull box (body frame).
    cg_to_box_m: Vector3<f64>,
    thruster_dynamics: ThrusterDynamics,
    /// Each motor's full forward thrust (the speed scale of its fluctuation).
    full_n: [f64; 4],
    /// Unit wrench of each thruster (direction; moment arm x direction).
    wrench: [Vector6<f64>; 4],
    /// Each motor's static thrust for every command, `[motor][reverse][duty]`: a command is
    /// one of 512, so the curve (two powers) is read, not computed, every step.
    static_n: Box<[[[f64; 256]; 2]; 4]>,
}

fn smoothstep(x: f64) -> f64 {
    let x = x.clamp(0.0, 1.0);
    x * x * (3.0 - 2.0 * x)
}

impl Model {
    /// Builds the model; the step size comes from the world settings.
    pub fn new(vehicle: VehicleConfig, world: WorldConfig) -> Self {
        let dt_s = world.step_s;
        let mass_kg = vehicle.mass_kg;
        let a = vehicle.added_mass;
        let mut m = Matrix6::zeros();
        m.fixed_view_mut::<3, 3>(0, 0)
            .copy_from(&(Matrix3::identity() * mass_kg));
        m.fixed_view_mut::<3, 3>(3, 3)
            .copy_from(&vehicle.inertia_kgm2);
        for (i, ai) in a.iter().enumerate() {
            m[(i, i)] += ai;
        }
        // M is symmetric positive definite (checked masses and inertias are positive).
        let m_inv = m.cholesky().map_or_else(Matrix6::identity, |c| c.inverse());
        let g = world.gravity_mps2;
        let wrench = std::array::from_fn(|i| {
            let t = &vehicle.thrusters[i];
            let moment = t.position_cg_m.cross(&t.direction);
            Vector6::new(
                t.direction.x,
                t.direction.y,
                t.direction.z,
                moment.x,
                moment.y,
                moment.z,
            )
        });
        let full_n = std::array::from_fn(|i| {
            vehicle.thruster_common.forward_max_n * vehicle.thrusters[i].gain
        });
        let static_n = Box::new(std::array::from_fn(|i| {
            std::array::from_fn(|reverse| {
                std::array::from_fn(|duty| {
                    let command = ThrusterCommand {
                        duty: duty as u8,
                        direction: if reverse == 1 {
                            Direction::Reverse
                        } else {
                            Direction::Forward
                        },
                    };
                    static_thrust_n(&vehicle.thruster_common, &vehicle.thrusters[i], command)
                })
            })
        }));
        Self {
            id: NEXT_MODEL_ID.fetch_add(1, Ordering::Relaxed),
            thruster_dynamics: ThrusterDynamics::new(&vehicle.thruster_common, dt_s),
            pool: Pool::new(&world),
            dt_s,
            mass_kg,
            inertia: vehicle.inertia_kgm2,
            added_lin: Vector3::new(a[0], a[1], a[2]),
            added_ang: Vector3::new(a[3], a[4], a[5]),
            m_inv,
            weight_n: mass_kg * g,
            buoyancy_full_n: world.water_density_kgpm3 * g * vehicle.displaced_volume_m3,
            waterplane_n_per_m: world.water_density_kgpm3 * g * vehicle.surface_waterplane_m2,
            cg_to_box_m: -vehicle.cg_from_box_centre_m,
            full_n,
            wrench,
            static_n,
            vehicle,
            world,
        }
    }

    pub fn vehicle(&self) -> &VehicleConfig {
        &self.vehicle
    }

    pub fn world(&self) -> &WorldConfig {
        &self.world
    }

    /// The pool geometry; it implements [`crate::physics::state::RayCaster`].
    pub fn pool(&self) -> &Pool {
        &self.pool
    }

    /// The fixed step.
    pub fn step_s(&self) -> f64 {
        self.dt_s
    }

    /// The inverse of the constant mass matrix M_RB + M_A.
    pub fn mass_matrix_inverse(&self) -> &Matrix6<f64> {
        &self.m_inv
    }

    /// Buoyancy fully submerged, and weight (N).
    pub fn buoyancy_and_weight_n(&self) -> (f64, f64) {
        (self.buoyancy_full_n, self.weight_n)
    }

    /// Submerged fraction of the hull (0..1) for a CG depth and attitude. The hull's displaced
    /// volume is spread over its vertical extent like a pair of horizontal cylinders: little
    /// volume at the very top and bottom (a smoothstep), so buoyancy falls smoothly as the
    /// hull surfaces.
    pub fn submerged_fraction(&self, depth_m: f64, attitude: &UnitQuaternion<f64>) -> f64 {
        self.submerged_fraction_down(depth_m, &down_in_body(attitude))
    }

    /// [`Model::submerged_fraction`] given the world's down axis in body axes.
    fn submerged_fraction_down(&self, depth_m: f64, down_body: &Vector3<f64>) -> f64 {
        let h = &self.vehicle.half_extents_m;
        let half_height = down_body.abs().dot(h);
        let centre_z = depth_m + down_body.dot(&self.cg_to_box_m);
        smoothstep((centre_z + half_height) / (2.0 * half_height))
    }

    /// How far the top of the hull box stands out of the water (m, 0 submerged, at most the
    /// box's height).
    fn top_emergence_m(&self, depth_m: f64, down_body: &Vector3<f64>) -> f64 {
        let half_height = down_body.abs().dot(&self.vehicle.half_extents_m);
        let centre_z = depth_m + down_body.dot(&self.cg_to_box_m);
        (half_height - centre_z).clamp(0.0, 2.0 * half_height)
    }

    /// Buoyancy (N) at a CG depth and attitude: the submerged fraction of the full buoyancy,
    /// less what the top's waterplane loses once it is out of the water
    /// ([`VehicleConfig::surface_waterplane_m2`]), never below zero.
    fn buoyancy_n(&self, depth_m: f64, down_body: &Vector3<f64>) -> f64 {
        let b = self.buoyancy_full_n * self.submerged_fraction_down(depth_m, down_body);
        if self.waterplane_n_per_m == 0.0 {
            return b;
        }
        (b - self.waterplane_n_per_m * self.top_emergence_m(depth_m, down_body)).max(0.0)
    }

    /// The heave damping of a hull whose top is out of the water
    /// ([`VehicleConfig::surface_damping_nspm`]) as a generalised force (body frame, at the
    /// CG): it opposes the world-vertical speed, and fades in over the first
    /// [`SURFACE_BAND_M`] the top rises.
    fn surface_damping(
        &self,
        depth_m: f64,
        down_body: &Vector3<f64>,
        nu: &Vector6<f64>,
    ) -> Vector6<f64> {
        let c = self.vehicle.surface_damping_nspm;
        if c == 0.0 {
            return Vector6::zeros();
        }
        let out = smoothstep(self.top_emergence_m(depth_m, down_body) / SURFACE_BAND_M);
        let down_speed = down_body.dot(&Vector3::new(nu[0], nu[1], nu[2]));
        let f = -down_body * (c * out * down_speed);
        Vector6::new(f.x, f.y, f.z, 0.0, 0.0, 0.0)
    }

    /// The CG depth at which the vehicle floats level at rest (buoyancy equals weight), or
    /// the depth with the hull just submerged if it is heavier than the water it displaces.
    pub fn floating_depth_m(&self) -> f64 {
        let level = UnitQuaternion::identity();
        let (mut lo, mut hi) = (-2.0 * self.vehicle.half_extents_m.z, 2.0);
        for _ in 0..80 {
            let mid = 0.5 * (lo + hi);
            if self.buoyancy_n(mid, &down_in_body(&level)) < self.weight_n {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        hi
    }

    /// A state at rest (or moving as `initial` says) with the thrusters off; `seed` selects
    /// the physics RNG stream's key.
    pub fn initial_state(&self, initial: &InitialState, seed: u64) -> SimState {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(PHYSICS_RNG_STREAM);
        let current_body = initial.attitude.inverse() * self.world.current_mps;
        let v_r = initial.velocity_body_mps - current_body;
        let w = initial.angular_velocity_body_radps;
        SimState {
            step: 0,
            position_m: initial.position_m,
            attitude: initial.attitude,
            nu_r: Vector6::new(v_r.x, v_r.y, v_r.z, w.x, w.y, w.z),
            thrust_lagged_n: [0.0; 4],
            fluctuation: [0.0; 4],
            thrust_n: [0.0; 4],
            effort: [0.0; 4],
            thrust_accel: Vector6::zeros(),
            contact_accel: Vector6::zeros(),
            in_contact: false,
            contact_count: 0,
            contact_steps: 0,
            rng,
            rates: RatesCache::default(),
        }
    }

    /// Replaces the parts of `state` that `anchor` names, keeping everything else (body
    /// velocities relative to the water, roll, pitch, thruster lag, noise streams). A
    /// re-simulation that re-anchors its state to measurements at segment boundaries
    /// (multiple shooting) uses it; stepping never calls it.
    pub fn reanchor(&self, state: &mut SimState, anchor: &Anchor) {
        state.rates.clear();
        if let Some(x) = anchor.north_m {
            state.position_m.x = x;
        }
        if let Some(y) = anchor.east_m {
            state.position_m.y = y;
        }
        if let Some(z) = anchor.depth_m {
            state.position_m.z = z;
        }
        if let Some(h) = anchor.heading_rad {
            let (roll, pitch, _) = state.attitude.euler_angles();
            state.attitude = UnitQuaternion::from_euler_angles(roll, pitch, h);
        }
    }

    /// Puts the vehicle at `position_m` with heading `heading_rad`, level and at rest over
    /// ground (moving with no water: its velocity through the water is minus the current),
    /// thruster lag and noise streams kept. The live view's "set pose" uses it.
    pub fn place(&self, state: &mut SimState, position_m: Vector3<f64>, heading_rad: f64) {
        state.rates.clear();
        state.position_m = position_m;
        state.attitude = UnitQuaternion::from_euler_angles(0.0, 0.0, heading_rad);
        let current_body = state.attitude.inverse() * self.world.current_mps;
        state.nu_r = Vector6::new(
            -current_body.x,
            -current_body.y,
            -current_body.z,
            0.0,
            0.0,
            0.0,
        );
    }

    /// Advances the clock one step with the vehicle held where it is, at rest over ground and
    /// with no thrust: what a re-simulation does with a state it could not step (diverged)
    /// until it can re-anchor it.
    pub fn hold(&self, state: &mut SimState) {
        state.rates.clear();
        let current_body = state.attitude.inverse() * self.world.current_mps;
        state.nu_r = Vector6::new(
            -current_body.x,
            -current_body.y,
            -current_body.z,
            0.0,
            0.0,
            0.0,
        );
        state.thrust_lagged_n = [0.0; 4];
        state.thrust_n = [0.0; 4];
        state.thrust_accel = Vector6::zeros();
        state.contact_accel = Vector6::zeros();
        state.step += 1;
    }

    /// Sets the steady water current (world frame, NED, m/s) from now on.
    pub fn set_current(&mut self, current_mps: Vector3<f64>) {
        self.world.current_mps = current_mps;
    }

    /// Generalised force of weight and buoyancy (body frame, about the CG), i.e. -g(eta).
    /// `down_body`: the world's down axis in body axes.
    fn restoring(&self, depth_m: f64, down_body: &Vector3<f64>) -> Vector6<f64> {
        let f_b = -down_body * self.buoyancy_n(depth_m, down_body);
        let force = down_body * self.weight_n + f_b;
        let moment = self.vehicle.cb_m.cross(&f_b);
        Vector6::new(force.x, force.y, force.z, moment.x, moment.y, moment.z)
    }

    /// Coriolis-centripetal (rigid body + added mass) and damping forces, C(nu_r) nu_r +
    /// D(nu_r) nu_r.
    fn coriolis_and_damping(&self, nu: &Vector6<f64>) -> Vector6<f64> {
        let v = Vector3::new(nu[0], nu[1], nu[2]);
        let w = Vector3::new(nu[3], nu[4], nu[5]);
        // C_RB (linear-velocity-independent form, CG at the origin).
        let f_rb = w.cross(&v) * self.mass_kg;
        let m_rb = w.cross(&(self.inertia * w));
        // C_A for diagonal added mass.
        let a1 = self.added_lin.component_mul(&v);
        let a2 = self.added_ang.component_mul(&w);
        let f_a = w.cross(&a1);
        let m_a = v.cross(&a1) + w.cross(&a2);
        let lin = &self.vehicle.damping_linear;
        let quad = &self.vehicle.damping_quadratic;
        let mut out = Vector6::new(
            f_rb.x + f_a.x,
            f_rb.y + f_a.y,
            f_rb.z + f_a.z,
            m_rb.x + m_a.x,
            m_rb.y + m_a.y,
            m_rb.z + m_a.z,
        );
        for i in 0..6 {
            out[i] += (lin[i] + quad[i] * nu[i].abs()) * nu[i];
        }
        let [y_r, n_v] = self.vehicle.damping_sway_yaw;
        out[1] += y_r * nu[5];
        out[5] += n_v * nu[1]
            + self.vehicle.damping_yaw_uv * nu[0] * nu[1]
            + self.vehicle.damping_yaw_ur * nu[0].abs() * nu[5];
        out
    }

    /// The rates from everything but the thrust ([`Rates`]).
    fn unforced_rates(
        &self,
        position_m: &Vector3<f64>,
        q: &Quaternion<f64>,
        nu: &Vector6<f64>,
    ) -> Rates {
        // One rotation matrix serves the position rate and the restoring force.
        let r = UnitQuaternion::new_normalize(*q).to_rotation_matrix();
        let v = Vector3::new(nu[0], nu[1], nu[2]);
        let w = Vector3::new(nu[3], nu[4], nu[5]);
        let down_body = r.matrix().row(2).transpose();
        let forces = self.restoring(position_m.z, &down_body) - self.coriolis_and_damping(nu)
            + self.surface_damping(position_m.z, &down_body, nu);
        Rates {
            velocity_world: r * v,
            q_dot: q * Quaternion::new(0.0, w.x, w.y, w.z) * 0.5,
            accel: self.m_inv * forces,
        }
    }

    /// [`Model::unforced_rates`] at the state's own pose and velocity, from its cache when
    /// this model filled it.
    fn state_rates(&self, state: &SimState) -> Rates {
        state.rates.get(self.id).unwrap_or_else(|| {
            let r =
                self.unforced_rates(&state.position_m, state.attitude.quaternion(), &state.nu_r);
            state.rates.set(self.id, r);
            r
        })
    }

    /// Right-hand side (position rate, quaternion rate, nu_r rate) from the unforced rates and
    /// the thrust's acceleration `M^-1 tau`.
    fn derivative(
        &self,
        rates: &Rates,
        thrust_accel: &Vector6<f64>,
    ) -> (Vector3<f64>, Quaternion<f64>, Vector6<f64>) {
        (
            rates.velocity_world + self.world.current_mps,
            rates.q_dot,
            rates.accel + thrust_accel,
        )
    }

    /// One RK4 step of (position, quaternion, nu_r) under a constant thrust acceleration, from
    /// `first`, the unforced rates at the start.
    fn rk4(
        &self,
        state: &SimState,
        first: &Rates,
        thrust_accel: &Vector6<f64>,
    ) -> (Vector3<f64>, Quaternion<f64>, Vector6<f64>) {
        let dt = self.dt_s;
        let p0 = state.position_m;
        let q0 = *state.attitude.quaternion();
        let n0 = state.nu_r;
        let h = 0.5 * dt;
        let at = |p: Vector3<f64>, q: Quaternion<f64>, n: Vector6<f64>| {
            self.derivative(&self.unforced_rates(&p, &q, &n), thrust_accel)
        };
        let (dp1, dq1, dn1) = self.derivative(first, thrust_accel);
        let (dp2, dq2, dn2) = at(p0 + dp1 * h, q0 + dq1 * h, n0 + dn1 * h);
        let (dp3, dq3, dn3) = at(p0 + dp2 * h, q0 + dq2 * h, n0 + dn2 * h);
        let (dp4, dq4, dn4) = at(p0 + dp3 * dt, q0 + dq3 * dt, n0 + dn3 * dt);
        let s = dt / 6.0;
        (
            p0 + (dp1 + (dp2 + dp3) * 2.0 + dp4) * s,
            q0 + (dq1 + (dq2 + dq3) * 2.0 + dq4) * s,
            n0 + (dn1 + (dn2 + dn3) * 2.0 + dn4) * s,
        )
    }

    /// Advances `state` by one fixed step under `commands`. Pure: the result depends only on
    /// the state and the commands (and the model), never on a clock. A step that fails
    /// (a quantity not finite, a divergence guard) leaves `state` as it was.
    pub fn step(
        &self,
        state: &mut SimState,
        commands: &[ThrusterCommand; 4],
    ) -> Result<(), PhysicsError> {
        let rng_at = state.rng.get_word_pos();
        let result = self.try_step(state, commands);
        if result.is_err() {
            state.rng.set_word_pos(rng_at);
        }
        result
    }

    /// [`Model::step`]: every field but the RNG's position is written only once the step
    /// has passed its checks.
    fn try_step(
        &self,
        state: &mut SimState,
        commands: &[ThrusterCommand; 4],
    ) -> Result<(), PhysicsError> {
        let dt = self.dt_s;

        // Thrusters: static curve -> lag -> fluctuation -> fade when out of the water.
        let mut tau = Vector6::zeros();
        let down_body = down_in_body(&state.attitude);
        let mut lagged_n = state.thrust_lagged_n;
        let mut fluctuation = state.fluctuation;
        let mut thrust_n = [0.0; 4];
        for (i, motor) in self.vehicle.thrusters.iter().enumerate() {
            let reverse = usize::from(commands[i].direction == Direction::Reverse);
            let target = self.static_n[i][reverse][usize::from(commands[i].duty)];
            let produced = self.thruster_dynamics.step(
                &mut lagged_n[i],
                &mut fluctuation[i],
                target,
                self.full_n[i],
                &mut state.rng,
            );
            let depth = state.position_m.z + down_body.dot(&motor.position_cg_m);
            let wet = smoothstep((depth + PROPELLER_RADIUS_M) / (2.0 * PROPELLER_RADIUS_M));
            thrust_n[i] = produced * wet;
            tau += self.wrench[i] * thrust_n[i];
        }

        // RK4; the thrust is held over the step, so its acceleration is computed once.
        let thrust_accel = self.m_inv * tau;
        let (mut position, q, mut nu) = self.rk4(state, &self.state_rates(state), &thrust_accel);
        let t_s = (state.step + 1) as f64 * dt;
        if !q.coords.iter().all(|x| x.is_finite()) || q.norm() < 1e-6 {
            return Err(PhysicsError::NonFinite {
                t_s,
                quantity: "attitude",
            });
        }
        let attitude = UnitQuaternion::new_normalize(q);

        // Contacts with the pool.
        let nu_before_contact = nu;
        let touching = self.resolve_contacts(&mut position, &attitude, &mut nu);

        // Divergence guard.
        if !position.iter().chain(nu.iter()).all(|x| x.is_finite()) {
            return Err(PhysicsError::NonFinite {
                t_s,
                quantity: "position or velocity",
            });
        }
        let speed = Vector3::new(nu[0], nu[1], nu[2]).norm();
        if speed > self.world.max_speed_mps {
            return Err(PhysicsError::Diverged {
                t_s,
                quantity: "speed through the water (m/s)",
                value: speed,
                limit: self.world.max_speed_mps,
            });
        }
        let rate = Vector3::new(nu[3], nu[4], nu[5]).norm();
        if rate > MAX_ANGULAR_RATE_RADPS {
            return Err(PhysicsError::Diverged {
                t_s,
                quantity: "angular rate (rad/s)",
                value: rate,
                limit: MAX_ANGULAR_RATE_RADPS,
            });
        }
        let size = self.world.pool_m;
        let outside = (0..3)
            .map(|a| (-position[a]).max(position[a] - size[a]))
            .fold(f64::NEG_INFINITY, f64::max);
        if outside > OUTSIDE_POOL_LIMIT_M {
            return Err(PhysicsError::Diverged {
                t_s,
                quantity: "distance of the CG outside the pool (m)",
                value: outside,
                limit: OUTSIDE_POOL_LIMIT_M,
            });
        }
        state.step += 1;
        state.thrust_lagged_n = lagged_n;
        state.fluctuation = fluctuation;
        state.thrust_n = thrust_n;
        state.effort = commands.map(|c| c.effort());
        state.thrust_accel = thrust_accel;
        state.contact_accel = (nu - nu_before_contact) / dt;
        if touching && !state.in_contact {
            state.contact_count += 1;
        }
        if touching {
            state.contact_steps += 1;
        }
        state.in_contact = touching;
        state.position_m = position;
        state.attitude = attitude;
        state.nu_r = nu;
        state.rates.clear();
        Ok(())
    }

    /// Benchmark baseline: the RK4 step of the rigid body alone, with no thrusters, no contact
    /// query and no divergence guard. Not for simulation; `benches/physics.rs` compares the
    /// full [`Model::step`] against it in the same run.
    #[doc(hidden)]
    pub fn step_rigid_body_only(&self, state: &mut SimState) {
        let first =
            self.unforced_rates(&state.position_m, state.attitude.quaternion(), &state.nu_r);
        let (position, q, nu) = self.rk4(state, &first, &Vector6::zeros());
        state.position_m = position;
        state.attitude = UnitQuaternion::new_normalize(q);
        state.nu_r = nu;
        state.rates.clear();
        state.step += 1;
    }

    /// Pushes the hull out of the geometry and removes approaching velocity at each contact
    /// (impulse through the full 6-DOF inverse mass, restitution and Coulomb friction).
    /// Returns whether the hull touches anything.
    fn resolve_contacts(
        &self,
        position: &mut Vector3<f64>,
        attitude: &UnitQuaternion<f64>,
        nu_r: &mut Vector6<f64>,
    ) -> bool {
        let mut contacts: Vec<Contact> = Vec::new();
        let centre = *position + attitude * self.cg_to_box_m;
        self.pool.hull_contacts(
            &self.vehicle.half_extents_m,
            &centre,
            attitude,
            CONTACT_PREDICTION_M,
            &mut contacts,
        );
        if contacts.is_empty() {
            return false;
        }
        let current_body = attitude.inverse() * self.world.current_mps;
        let e = self.world.restitution;
        let mu = self.world.friction;
        let mut touching = false;
        for c in &contacts {
            touching |= c.distance_m <= CONTACT_PREDICTION_M;
            if c.distance_m < 0.0 {
                *position += c.normal * -c.distance_m;
            }
            let r_b = attitude.inverse() * (c.point_m - *position);
            let n_b = attitude.inverse() * c.normal;
            let row = |d: &Vector3<f64>| {
                let m = r_b.cross(d);
                Vector6::new(d.x, d.y, d.z, m.x, m.y, m.z)
            };
            let jn = row(&n_b);
            let point_velocity = |nu: &Vector6<f64>| {
                let v = Vector3::new(nu[0], nu[1], nu[2]) + current_body;
                let w = Vector3::new(nu[3], nu[4], nu[5]);
                v + w.cross(&r_b)
            };
            let vn = point_velocity(nu_r).dot(&n_b);
            let target = if c.distance_m > 0.0 {
                // Speculative: may approach, but not close more than the gap in one step.
                let limit = -c.distance_m / self.dt_s;
                if vn >= limit {
                    continue;
                }
                limit
            } else if vn < 0.0 {
                -e * vn
            } else {
                continue;
            };
            let mj = self.m_inv * jn;
            let lambda = (target - vn) / jn.dot(&mj);
            *nu_r += mj * lambda;
            // Friction against the sliding direction, bounded by mu * normal impulse.
            let vp = point_velocity(nu_r);
            let vt = vp - n_b * vp.dot(&n_b);
            let slip = vt.norm();
            if slip > 1e-9 && mu > 0.0 {
                let jt = row(&(vt / slip));
                let mjt = self.m_inv * jt;
                let lambda_t = (-slip / jt.dot(&mjt)).max(-mu * lambda);
                *nu_r += mjt * lambda_t;
            }
        }
        touching
    }

    /// The sensors' view of a state.
    pub fn vehicle_state(&self, state: &SimState) -> VehicleState {
        let att = state.attitude;
        let v_r = Vector3::new(state.nu_r[0], state.nu_r[1], state.nu_r[2]);
        let w = Vector3::new(state.nu_r[3], state.nu_r[4], state.nu_r[5]);
        let current_body = att.inverse() * self.world.current_mps;
        let nu_dot = self.state_rates(state).accel + state.thrust_accel;
        // Kinematic acceleration of the CG in body axes is v_r_dot + w x v_r for a constant
        // current; the accelerometer reads it minus gravity.
        let accel = Vector3::new(
            nu_dot[0] + state.contact_accel[0],
            nu_dot[1] + state.contact_accel[1],
            nu_dot[2] + state.contact_accel[2],
        ) + w.cross(&v_r);
        let gravity_body = att.inverse_transform_vector(&Vector3::z()) * self.world.gravity_mps2;
        VehicleState {
            t_s: state.step as f64 * self.dt_s,
            position_m: state.position_m,
            attitude: att,
            velocity_body_mps: v_r + current_body,
            angular_velocity_body_radps: w,
            velocity_water_body_mps: v_r,
            specific_force_body_mps2: accel - gravity_body,
            angular_accel_body_radps2: Vector3::new(
                nu_dot[3] + state.contact_accel[3],
                nu_dot[4] + state.contact_accel[4],
                nu_dot[5] + state.contact_accel[5],
            ),
            thruster_force_n: state.thrust_n,
            thruster_effort: state.effort,
            in_contact: state.in_contact,
        }
    }
}

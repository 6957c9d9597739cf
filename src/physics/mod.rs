//! The simulated Mako: a fixed-step 6-DOF rigid-body model in a rapier3d pool.
//!
//! Frames (Fossen's conventions): the world frame is NED, x north, y east, z down, with its
//! origin at a pool corner on the water surface, so `z` is depth and yaw is compass heading.
//! The body frame is x forward, y starboard, z down, with its origin at the centre of mass.
//!
//! What is where:
//! - [`config`]: vehicle and world files, raw then resolved (mass distribution -> inertia).
//! - [`model`]: the equations of motion, the pure stepping function [`Model::step`] on a
//!   [`SimState`], contacts, the divergence guard.
//! - [`thruster`]: duty/direction commands, static curves, lag, fluctuation, the HDT lookup.
//! - [`world`]: the pool's rapier3d colliders; [`world::Pool`] implements [`state::RayCaster`].
//! - [`experiment`]: thesis experiments as data (initial state + MOTORDrive schedule).
//! - [`measure`]: the thesis's measurement methods (pool-side camera at 200 ms, overhead
//!   camera) applied to simulated traces.
//! - [`Simulation`]: a model, a state and the current commands, for callers that step one run.
//!
//! Step size: 10 ms by default (`simulation.step_s` in the world file), with RK4. The
//! justification and the measured step-size convergence are in `docs/calibration.md`.

pub mod config;
pub mod experiment;
pub mod measure;
pub mod model;
pub mod state;
pub mod thruster;
pub mod world;

pub use config::{VehicleConfig, WorldConfig};
pub use model::{Anchor, InitialState, Model, PhysicsError, SimState};
pub use thruster::{Direction, ThrusterCommand, hdt_command};

use crate::config::{ConfigError, ConfigSource, Document};
use state::VehicleState;

/// The default vehicle file inside a [`ConfigSource`].
pub const DEFAULT_VEHICLE: &str = "vehicles/mako.toml";
/// The default world file inside a [`ConfigSource`].
pub const DEFAULT_WORLD: &str = "worlds/pool.toml";

/// Loads and resolves a vehicle file by name from a config source.
pub fn load_vehicle(source: &dyn ConfigSource, name: &str) -> Result<VehicleConfig, ConfigError> {
    let text = source.read(name)?;
    VehicleConfig::from_document(&Document::new(source.describe(name), &text))
}

/// Loads and resolves a world file by name from a config source.
pub fn load_world(source: &dyn ConfigSource, name: &str) -> Result<WorldConfig, ConfigError> {
    let text = source.read(name)?;
    WorldConfig::from_document(&Document::new(source.describe(name), &text))
}

/// Builds a model from a vehicle and a world file in a config source.
pub fn load_model(
    source: &dyn ConfigSource,
    vehicle: &str,
    world: &str,
) -> Result<Model, ConfigError> {
    Ok(Model::new(
        load_vehicle(source, vehicle)?,
        load_world(source, world)?,
    ))
}

/// One run: a model, its state and the commands the motor drivers hold.
///
/// Stepping is deterministic: the same model, initial state, seed and command sequence give
/// bit-identical states however the steps are grouped into calls.
#[derive(Debug)]
pub struct Simulation {
    model: Model,
    state: SimState,
    commands: [ThrusterCommand; 4],
    stopped: Option<PhysicsError>,
}

impl Simulation {
    /// Starts a run; thrusters off.
    pub fn new(model: Model, initial: &InitialState, seed: u64) -> Self {
        let state = model.initial_state(initial, seed);
        Self {
            model,
            state,
            commands: [ThrusterCommand::OFF; 4],
            stopped: None,
        }
    }

    pub fn model(&self) -> &Model {
        &self.model
    }

    /// The pool geometry for sonar ray casts.
    pub fn ray_caster(&self) -> &world::Pool {
        self.model.pool()
    }

    /// Sets one motor driver's command (index [`state::PORT`] ..= [`state::STERN`]); it holds
    /// until changed.
    pub fn set_command(
        &mut self,
        index: usize,
        command: ThrusterCommand,
    ) -> Result<(), PhysicsError> {
        let slot = self
            .commands
            .get_mut(index)
            .ok_or(PhysicsError::NoSuchThruster { index })?;
        *slot = command;
        Ok(())
    }

    pub fn set_commands(&mut self, commands: [ThrusterCommand; 4]) {
        self.commands = commands;
    }

    pub fn commands(&self) -> [ThrusterCommand; 4] {
        self.commands
    }

    /// One fixed step. After an error every further call returns [`PhysicsError::Stopped`].
    pub fn step(&mut self) -> Result<(), PhysicsError> {
        if let Some(e) = &self.stopped {
            return Err(PhysicsError::Stopped(Box::new(e.clone())));
        }
        self.model
            .step(&mut self.state, &self.commands)
            .inspect_err(|e| {
                tracing::warn!(error = %e, "physics stopped");
                self.stopped = Some(e.clone());
            })
    }

    /// `n` fixed steps.
    pub fn step_n(&mut self, n: u64) -> Result<(), PhysicsError> {
        for _ in 0..n {
            self.step()?;
        }
        Ok(())
    }

    /// Puts the vehicle at rest at a position and heading ([`Model::place`]).
    pub fn place(&mut self, position_m: nalgebra::Vector3<f64>, heading_rad: f64) {
        self.model.place(&mut self.state, position_m, heading_rad);
    }

    /// Sets the water current from now on ([`Model::set_current`]).
    pub fn set_current(&mut self, current_mps: nalgebra::Vector3<f64>) {
        self.model.set_current(current_mps);
    }

    /// Simulated time (steps x step size).
    pub fn t_s(&self) -> f64 {
        self.state.steps() as f64 * self.model.step_s()
    }

    /// The sensors' view of the vehicle now.
    pub fn state(&self) -> VehicleState {
        self.model.vehicle_state(&self.state)
    }

    /// The full internal state (for snapshots and determinism checks).
    pub fn sim_state(&self) -> &SimState {
        &self.state
    }

    /// How many separate times the hull has hit the pool or an obstacle.
    pub fn contact_count(&self) -> u64 {
        self.state.contact_count()
    }
}

//! Thesis experiments as data: an initial state and a schedule of MOTORDrive commands
//! (signed percent per thruster, mapped to duty and direction through the vehicle's HDT
//! table), optionally with the simple heading or depth hold the experiment needs (the thesis
//! drove its speed runs under compass heading control, 4.5).
//!
//! The controllers here stand in for the EyeBot program of the experiment; they read the true
//! state, run at a fixed control period and hold their output between updates.

use nalgebra::{UnitQuaternion, Vector3};
use serde::Deserialize;

use crate::config::{ConfigError, Document};
use crate::physics::model::{InitialState, Model, PhysicsError};
use crate::physics::state::VehicleState;
use crate::physics::thruster::{ThrusterCommand, hdt_command};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawExperiment {
    name: String,
    description: String,
    duration_s: f64,
    #[serde(default = "default_control_period")]
    control_period_s: f64,
    initial: RawInitial,
    heading_hold: Option<RawHeadingHold>,
    depth_hold: Option<RawDepthHold>,
    #[serde(rename = "command")]
    commands: Vec<RawCommand>,
}

fn default_control_period() -> f64 {
    0.1
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawInitial {
    north_m: f64,
    east_m: f64,
    depth_m: Option<f64>,
    heading_deg: f64,
    #[serde(default)]
    surge_mps: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawHeadingHold {
    gain_percent_per_deg: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDepthHold {
    target_m: f64,
    gain_percent_per_m: f64,
    integral_percent_per_m_s: f64,
    damping_percent_per_mps: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCommand {
    t_s: f64,
    percent: [f64; 4],
}

/// Heading hold: differential port/starboard correction proportional to the heading error.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct HeadingHold {
    pub gain_percent_per_deg: f64,
}

/// Depth hold: PID on depth for both vertical thrusters (the integral carries the steady
/// push against the positive buoyancy; its contribution is clamped to +-100 %).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DepthHold {
    pub target_m: f64,
    pub gain_percent_per_m: f64,
    pub integral_percent_per_m_s: f64,
    pub damping_percent_per_mps: f64,
}

/// One schedule entry: from `t_s` on, MOTORDrive percentages (port, starboard, bow, stern).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ScheduledCommand {
    pub t_s: f64,
    pub percent: [f64; 4],
}

/// Initial position: depth `None` means floating at the surface in equilibrium.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ExperimentStart {
    pub north_m: f64,
    pub east_m: f64,
    pub depth_m: Option<f64>,
    pub heading_rad: f64,
    pub surge_mps: f64,
}

/// An experiment, resolved.
#[derive(Debug, Clone, PartialEq)]
pub struct Experiment {
    pub name: String,
    pub description: String,
    pub duration_s: f64,
    pub control_period_s: f64,
    pub start: ExperimentStart,
    pub heading_hold: Option<HeadingHold>,
    pub depth_hold: Option<DepthHold>,
    pub schedule: Vec<ScheduledCommand>,
}

impl Experiment {
    pub fn from_document(doc: &Document<'_>) -> Result<Self, ConfigError> {
        let raw: RawExperiment = doc.parse()?;
        let duration_s = doc.check_range("duration_s", raw.duration_s, 0.01, 3600.0, "s")?;
        let control_period_s =
            doc.check_range("control_period_s", raw.control_period_s, 0.001, 10.0, "s")?;
        let i = &raw.initial;
        let start = ExperimentStart {
            north_m: doc.check_range("initial.north_m", i.north_m, 0.0, 1e3, "m")?,
            east_m: doc.check_range("initial.east_m", i.east_m, 0.0, 1e3, "m")?,
            depth_m: match i.depth_m {
                Some(d) => Some(doc.check_range("initial.depth_m", d, -0.5, 100.0, "m")?),
                None => None,
            },
            heading_rad: doc
                .check_range("initial.heading_deg", i.heading_deg, -360.0, 360.0, "deg")?
                .to_radians(),
            surge_mps: doc.check_range("initial.surge_mps", i.surge_mps, -2.0, 2.0, "m/s")?,
        };
        let heading_hold = match &raw.heading_hold {
            Some(h) => Some(HeadingHold {
                gain_percent_per_deg: doc.check_range(
                    "heading_hold.gain_percent_per_deg",
                    h.gain_percent_per_deg,
                    0.0,
                    100.0,
                    "%/deg",
                )?,
            }),
            None => None,
        };
        let depth_hold = match &raw.depth_hold {
            Some(d) => Some(DepthHold {
                target_m: doc.check_range("depth_hold.target_m", d.target_m, 0.0, 100.0, "m")?,
                gain_percent_per_m: doc.check_range(
                    "depth_hold.gain_percent_per_m",
                    d.gain_percent_per_m,
                    0.0,
                    1e4,
                    "%/m",
                )?,
                integral_percent_per_m_s: doc.check_range(
                    "depth_hold.integral_percent_per_m_s",
                    d.integral_percent_per_m_s,
                    0.0,
                    1e4,
                    "%/(m s)",
                )?,
                damping_percent_per_mps: doc.check_range(
                    "depth_hold.damping_percent_per_mps",
                    d.damping_percent_per_mps,
                    0.0,
                    1e4,
                    "%/(m/s)",
                )?,
            }),
            None => None,
        };
        if raw.commands.is_empty() {
            return Err(doc.invalid("command", "at least one [[command]] is required"));
        }
        let mut schedule = Vec::with_capacity(raw.commands.len());
        let mut last = f64::NEG_INFINITY;
        for (k, c) in raw.commands.iter().enumerate() {
            let key = format!("command.{k}");
            let t = doc.check_range(&format!("{key}.t_s"), c.t_s, 0.0, duration_s, "s")?;
            if t < last {
                return Err(doc.invalid(&format!("{key}.t_s"), "commands must be in time order"));
            }
            last = t;
            for (j, p) in c.percent.iter().enumerate() {
                doc.check_range(&format!("{key}.percent.{j}"), *p, -100.0, 100.0, "%")?;
            }
            schedule.push(ScheduledCommand {
                t_s: t,
                percent: c.percent,
            });
        }
        Ok(Self {
            name: raw.name,
            description: raw.description,
            duration_s,
            control_period_s,
            start,
            heading_hold,
            depth_hold,
            schedule,
        })
    }

    /// The initial state in a model (a missing depth floats the vehicle at the surface).
    pub fn initial_state(&self, model: &Model) -> InitialState {
        let s = &self.start;
        let depth = s.depth_m.unwrap_or_else(|| model.floating_depth_m());
        InitialState {
            position_m: Vector3::new(s.north_m, s.east_m, depth),
            attitude: UnitQuaternion::from_euler_angles(0.0, 0.0, s.heading_rad),
            velocity_body_mps: Vector3::new(s.surge_mps, 0.0, 0.0),
            angular_velocity_body_radps: Vector3::zeros(),
        }
    }

    /// The scheduled MOTORDrive percentages at `t_s`.
    pub fn percent_at(&self, t_s: f64) -> [f64; 4] {
        // Rows are in time order (loading refuses others): the last row at or before `t_s`,
        // found by bisection, as the re-simulation asks for every step.
        let n = self.schedule.partition_point(|c| c.t_s <= t_s + 1e-9);
        n.checked_sub(1)
            .map_or([0.0; 4], |k| self.schedule[k].percent)
    }
}

fn wrap_deg(x: f64) -> f64 {
    (x + 180.0).rem_euclid(360.0) - 180.0
}

/// What a finished run reports besides its states.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RunSummary {
    pub steps: u64,
    /// Separate times the hull touched the pool or an obstacle.
    pub contact_count: u64,
}

/// Runs an experiment from its start, calling `observe` after every step (and once for the
/// initial state). Deterministic for a given model, experiment and seed.
pub fn run(
    model: &Model,
    experiment: &Experiment,
    seed: u64,
    mut observe: impl FnMut(&VehicleState),
) -> Result<RunSummary, PhysicsError> {
    let mut state = model.initial_state(&experiment.initial_state(model), seed);
    let dt = model.step_s();
    let steps = (experiment.duration_s / dt).round() as u64;
    let control_every = ((experiment.control_period_s / dt).round() as u64).max(1);
    let heading_target_deg = experiment.start.heading_rad.to_degrees();
    let tables: [&[f64; 11]; 4] = std::array::from_fn(|i| &model.vehicle().thrusters[i].hdt_duty);
    let mut commands = [ThrusterCommand::OFF; 4];
    let mut depth_integral = 0.0;
    let mut vs = model.vehicle_state(&state);
    observe(&vs);
    for k in 0..steps {
        if k % control_every == 0 {
            let t = k as f64 * dt;
            let mut percent = experiment.percent_at(t);
            if let Some(h) = experiment.heading_hold {
                let (_, _, yaw) = vs.euler_rad();
                // Positive error: the target lies clockwise, so push more on port.
                let delta =
                    h.gain_percent_per_deg * wrap_deg(heading_target_deg - yaw.to_degrees());
                percent[0] = (percent[0] + delta).clamp(-100.0, 100.0);
                percent[1] = (percent[1] - delta).clamp(-100.0, 100.0);
            }
            if let Some(d) = experiment.depth_hold {
                let w_down = (vs.attitude * vs.velocity_body_mps).z;
                let error = d.target_m - vs.position_m.z;
                depth_integral = (depth_integral
                    + d.integral_percent_per_m_s * error * experiment.control_period_s)
                    .clamp(-100.0, 100.0);
                let u = d.gain_percent_per_m * error + depth_integral
                    - d.damping_percent_per_mps * w_down;
                percent[2] = (percent[2] + u).clamp(-100.0, 100.0);
                percent[3] = (percent[3] + u).clamp(-100.0, 100.0);
            }
            for i in 0..4 {
                commands[i] = hdt_command(tables[i], percent[i]);
            }
        }
        model.step(&mut state, &commands)?;
        vs = model.vehicle_state(&state);
        observe(&vs);
    }
    Ok(RunSummary {
        steps: state.steps(),
        contact_count: state.contact_count(),
    })
}

/// Runs an experiment and keeps every state (the trace `simulate` writes).
pub fn trace(
    model: &Model,
    experiment: &Experiment,
    seed: u64,
) -> Result<Vec<VehicleState>, PhysicsError> {
    let mut out = Vec::with_capacity((experiment.duration_s / model.step_s()) as usize + 2);
    run(model, experiment, seed, |s| out.push(*s))?;
    Ok(out)
}

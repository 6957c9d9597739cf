//! How a re-simulation is cut ([`Shooting`]), what it produces and what the noise floor is
//! made of: the run of states ([`Run`]), a channel's floor ([`Floor`]) and the ensemble
//! size. `resim` makes them; `anchor`, `sonar`, `fit` and `report` read them.

use serde::Serialize;

use crate::physics::state::VehicleState;

/// How the re-simulation is cut.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Shooting {
    /// Segment length (s); `None` = one open-loop run (what `gap generate` uses to make data).
    pub segment_s: Option<f64>,
}

impl Shooting {
    /// Open loop: no re-anchoring.
    pub const OPEN_LOOP: Self = Self { segment_s: None };

    /// The default for analysing measured data. 5 s: long enough for the thrust and drag
    /// dynamics (surge time constant about 3 s, yaw about 2 s) to show inside a segment,
    /// short enough that a small yaw-rate error does not carry the track away (0.5 deg/s
    /// over 5 s moves a 0.4 m/s track 9 cm sideways, against a camera noise of 1 cm).
    /// `docs/gap.md` ("Re-simulation") has the comparison behind it.
    pub const DEFAULT: Self = Self {
        segment_s: Some(5.0),
    };
}

/// Ensemble size for the process-noise floor (and the null deviations each candidate's
/// significance is calibrated on, `fit`).
///
/// 96: the thrust fluctuation excites the lightly damped pitch/heave motion at the free
/// surface, whose phase wanders from run to run, so a few modes carry most of the process
/// noise in `depth_adc` and `accel_x_adc`. 24 members under-estimated that spread (on 40
/// generated nulls the mean squared normalised depth residual was 1.51 over 70-75 s instead
/// of 1) and under-sampled the null deviations along a lag fit's path, so a `thruster_lag`
/// fit gained up to 3x what the null calibration allowed and null data named a lag.
pub const ENSEMBLE: u64 = 96;

/// One re-simulated run: the state after every step (index 0 = start) and the commands.
#[derive(Debug, Clone)]
pub struct Run {
    pub dt_s: f64,
    pub states: Vec<VehicleState>,
    pub percent: Vec<[f64; 4]>,
    /// Segments the physics could not step to their end, in time order.
    pub divergences: Vec<Divergence>,
    /// Where the hull touched the pool: from the first contact in a segment to the segment's
    /// end (s, in time order). Contact impulses start on whichever step the hull first
    /// reaches a wall, so there the residuals jump as a parameter moves by any amount.
    pub contacts: Vec<[f64; 2]>,
}

/// A segment of a re-simulation that diverged: held from `t_s` to the segment's end.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Divergence {
    /// Start of the segment (s; 0 for an open-loop run).
    pub segment_start_s: f64,
    /// When the physics refused the step (s).
    pub t_s: f64,
    /// The quantity and value that diverged, as the physics said it.
    pub what: String,
}

/// How long after a contact segment its impulses stay in the state each segment carries over
/// to the next (velocities, rates, thruster lag), so that those samples are left out of fits
/// too (s). Surge is the slowest: `configs/vehicles/mako.toml`'s linear surge damping of
/// 3.3 N/(m/s) against a hull of tens of kilograms gives a time constant of several seconds.
pub const CONTACT_MEMORY_S: f64 = 10.0;

impl Run {
    /// True when `t_s` lies where the hull touched the pool ([`Run::contacts`]).
    pub fn in_contact(&self, t_s: f64) -> bool {
        self.contacts
            .iter()
            .any(|[a, b]| *a <= t_s && t_s < *b + CONTACT_MEMORY_S)
    }

    /// The state nearest `t_s` (clamped to the run).
    pub fn at(&self, t_s: f64) -> &VehicleState {
        let i = (t_s / self.dt_s).round().max(0.0) as usize;
        &self.states[i.min(self.states.len() - 1)]
    }

    pub fn percent_at(&self, t_s: f64) -> [f64; 4] {
        let i = (t_s / self.dt_s).round().max(0.0) as usize;
        self.percent[i.min(self.percent.len() - 1)]
    }
}

/// The model's noise floor for one channel.
#[derive(Debug, Clone)]
pub struct Floor {
    /// Per-sample 1-sigma spread (measurement and process noise together).
    pub sigma: Vec<f64>,
    /// Integrated autocorrelation time in samples: `n / tau` samples are independent.
    pub tau: f64,
    /// White measurement noise (1 sigma) per sample.
    pub measurement_std: Vec<f64>,
    /// Process-noise deviations of each ensemble run from the noise-free prediction: null
    /// residuals the model itself produces (without measurement noise).
    pub null: Vec<Vec<f64>>,
}

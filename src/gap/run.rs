//! How a re-simulation is cut ([`Shooting`]), what it produces and what the noise floor is
//! made of: the run of states ([`Run`]), a channel's floor ([`Floor`]) and the ensemble
//! size. `resim` makes them; `anchor`, `sonar`, `fit` and `report` read them.

use serde::Serialize;

use nalgebra::UnitQuaternion;

use crate::physics::VehicleConfig;
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
    /// Steps per re-anchored segment (`None`: one open-loop run). The state at each multiple
    /// is the anchored start of a new segment.
    pub segment_steps: Option<usize>,
    /// How long after a contact the depth channel's samples stay left out (s):
    /// [`depth_contact_memory_s`] of the re-simulated vehicle.
    pub depth_memory_s: f64,
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
/// too (s); the depth channel's memory is [`depth_contact_memory_s`]. Re-anchoring resets position and heading, not velocities, and at low speed a
/// velocity error decays with the linear damping alone. Surge is the slowest axis:
/// `configs/vehicles/mako.toml`'s 35 kg hull with 3.5 kg of added mass against a linear surge
/// damping of 3.327 N/(m/s) has a time constant of 11.6 s, and three of them (35 s) leave 5 %
/// of an error a contact made. A memory of 10 s, under one time constant, leaves 42 %: with
/// it, a null run of structure seed 434323 (case seed 379893, case 68), a slow spot turn beside
/// the wall the hull had touched, reads the track at 14.4 and 25.5 chi-square per sample
/// (known levels 1.43 and 1.10), most of it in the 30 s after that memory, and a water current
/// is named.
pub const CONTACT_MEMORY_S: f64 = 35.0;

/// How long before a contact's first step its samples are left out too (s). A candidate near
/// the base reaches the wall a step or a few earlier than the base does, and the impulse of
/// its first touch then lands on samples the base's contact does not cover: on a vehicle
/// that rides along a wall, a hard iron's chi-square jumped by 250 (accelerometer samples
/// at the touch) as its parameters moved by 0.005 uT, and its fit stopped where it started.
pub const CONTACT_LEAD_S: f64 = 1.0;

/// The channel whose contact memory follows the heave, roll and pitch alone
/// ([`depth_contact_memory_s`]).
pub const DEPTH_CHANNEL: &str = "depth_adc";

/// How long after a contact the depth channel's samples are left out (s): three of the
/// slowest time constants with which a velocity error a contact left in heave, roll or pitch
/// decays, at most [`CONTACT_MEMORY_S`].
///
/// The depth sensor reads the heave and, through its lever arm, roll and pitch; each segment
/// re-anchors the depth, so what a contact leaves in the depth channel is the error of those
/// velocities. Submerged, heave has no restoring force and its error decays with `(m + A_33)
/// / D_33` (7 s on `configs/vehicles/mako.toml`); roll and pitch are restored by the
/// metacentre and their error's envelope decays with `2 (I + A) / D` (6 s in pitch). The
/// surge and sway errors that [`CONTACT_MEMORY_S`] waits for reach the depth only through the
/// pitch angle. Waiting the surge's 35 s on the depth channel too left out the only held-out
/// samples a floating run has at its end: on structure 614923 (seed 560371) the
/// re-simulation touched a wall at 141-150 s, the run floats from 168 s, and two depth offsets
/// of 10-18 sigma, fitted at their truth, failed their held-out blocks.
pub fn depth_contact_memory_s(v: &VehicleConfig) -> f64 {
    let decay = |inertia: f64, damping: f64| {
        if damping > 0.0 {
            inertia / damping
        } else {
            f64::INFINITY
        }
    };
    let heave = decay(v.mass_kg + v.added_mass[2], v.damping_linear[2]);
    let roll = 2.0
        * decay(
            v.inertia_kgm2[(0, 0)] + v.added_mass[3],
            v.damping_linear[3],
        );
    let pitch = 2.0
        * decay(
            v.inertia_kgm2[(1, 1)] + v.added_mass[4],
            v.damping_linear[4],
        );
    let slowest = heave.max(roll).max(pitch);
    if slowest.is_finite() {
        (3.0 * slowest).min(CONTACT_MEMORY_S)
    } else {
        CONTACT_MEMORY_S
    }
}

/// True when `t_s` lies in one of the contact intervals `contacts` ([`Run::contacts`]),
/// within [`CONTACT_LEAD_S`] before it or within `memory_s` after it.
pub fn touching(contacts: &[[f64; 2]], t_s: f64, memory_s: f64) -> bool {
    contacts
        .iter()
        .any(|[a, b]| *a - CONTACT_LEAD_S <= t_s && t_s < *b + memory_s)
}

impl Run {
    /// How long after a contact the samples of `channel` stay left out (s).
    pub fn contact_memory_s(&self, channel: &str) -> f64 {
        if channel == DEPTH_CHANNEL {
            self.depth_memory_s
        } else {
            CONTACT_MEMORY_S
        }
    }

    /// A run with no states that touched the pool at `contacts`, for tests of what is left out.
    #[cfg(test)]
    pub(crate) fn touched_at(contacts: Vec<[f64; 2]>, depth_memory_s: f64) -> Self {
        Self {
            dt_s: 0.01,
            states: Vec::new(),
            percent: Vec::new(),
            divergences: Vec::new(),
            contacts,
            segment_steps: None,
            depth_memory_s,
        }
    }

    /// True when a sample of `channel` at `t_s` lies where the hull touched the pool
    /// ([`Run::contacts`]) or within the channel's memory of it.
    pub fn in_contact(&self, t_s: f64, channel: &str) -> bool {
        touching(&self.contacts, t_s, self.contact_memory_s(channel))
    }

    /// The state nearest `t_s` (clamped to the run).
    pub fn at(&self, t_s: f64) -> &VehicleState {
        let i = (t_s / self.dt_s).round().max(0.0) as usize;
        &self.states[i.min(self.states.len() - 1)]
    }

    /// The index of the first state of the segment that a sample taken at `t_s` belongs to
    /// (0 for an open-loop run). A sample at a segment start belongs to the new segment.
    pub fn segment_start_index(&self, t_s: f64) -> usize {
        let last = self.states.len().saturating_sub(1);
        let i = ((t_s / self.dt_s + 1e-6).floor().max(0.0) as usize).min(last);
        self.segment_steps.map_or(0, |n| i - i % n)
    }

    /// The state a reading taken at `sample_s` senses when it describes the vehicle at the
    /// earlier `seen_s` (a latency or lag): inside the sample's own segment the state there;
    /// before the segment's start that start's state carried back along its velocities and
    /// rates. The previous segment's end is not used: re-anchoring makes the states jump at
    /// each start, and a lookup across that jump would make a latency fit's objective jump
    /// wherever a sample's time minus the latency meets a segment start.
    pub fn seen_before(&self, sample_s: f64, seen_s: f64) -> Option<VehicleState> {
        let i = self.segment_start_index(sample_s);
        let start = self.states.get(i)?;
        let back = seen_s - i as f64 * self.dt_s;
        if back >= 0.0 {
            return None;
        }
        let mut s = *start;
        s.position_m += s.attitude * s.velocity_body_mps * back;
        s.attitude *= UnitQuaternion::from_scaled_axis(s.angular_velocity_body_radps * back);
        s.t_s += back;
        Some(s)
    }

    pub fn percent_at(&self, t_s: f64) -> [f64; 4] {
        let i = (t_s / self.dt_s).round().max(0.0) as usize;
        self.percent[i.min(self.percent.len() - 1)]
    }
}

/// Samples per degree of freedom of a channel's chi-square per sample `mean(z^2)`, `z_i =
/// (d_i + e_i) / sigma_i`, under the model's own noise: `d` process noise (one row of `null`
/// per ensemble member), `e` white measurement noise of spread `measurement_std`. A scaled
/// chi-square with the null's mean and variance (Satterthwaite) has `2 mean^2 / var` degrees of
/// freedom; this returns `n` over them (1 for white noise).
///
/// The variance is read two ways from the ensemble, and the larger is kept:
/// - **Gaussian**: `Var(sum z^2) = 2 sum_ij C_ij^2` for the correlations `C` of `z`; the
///   process part of `sum C^2` is the mean squared inner product of two distinct members
///   (unbiased, and steady with few members).
/// - **Spread**: each member's chi-square (the white part's expectation and variance taken
///   exactly) and the spread of those over the members. It holds what the Gaussian reading
///   misses (runs that wander more than others, a depth clamped at the surface), but a
///   heavy-tailed spread read from a few dozen members is more often under its value than over.
///
/// The mean correlation time (`tau`) is neither: process noise that wanders in one part of a
/// run (depth after a dive) widens the chi-square's spread far beyond what the average
/// correlation over the run says.
pub fn chi2_tau(null: &[Vec<f64>], sigma: &[f64], measurement_std: &[f64]) -> f64 {
    let n = sigma.len();
    if n == 0 {
        return 1.0;
    }
    let nf = n as f64;
    let w: Vec<f64> = (0..n)
        .map(|i| (measurement_std.get(i).copied().unwrap_or(0.0) / sigma[i]).powi(2))
        .collect();
    let white_mean = w.iter().sum::<f64>() / nf;
    let white_var = 2.0 * w.iter().map(|x| x * x).sum::<f64>() / (nf * nf);
    let members: Vec<Vec<f64>> = null
        .iter()
        .filter(|d| d.len() == n)
        .map(|d| d.iter().zip(sigma).map(|(x, s)| x / s).collect())
        .collect();
    let tau = |mean: f64, var: f64| {
        if mean > 0.0 && var > 0.0 {
            (nf * var / (2.0 * mean * mean)).max(1.0)
        } else {
            1.0
        }
    };
    let k = members.len();
    if k < 2 {
        return tau(white_mean, white_var);
    }
    let kf = k as f64;
    // Per member: the process part of its chi-square and the cross term's variance with the
    // white noise at the same samples.
    let (own, cross): (Vec<f64>, Vec<f64>) = members
        .iter()
        .map(|u| {
            let p = u.iter().map(|x| x * x).sum::<f64>() / nf;
            let c = u.iter().zip(&w).map(|(x, w)| 4.0 * x * x * w).sum::<f64>();
            (p, c / (nf * nf))
        })
        .unzip();
    let process_mean = own.iter().sum::<f64>() / kf;
    let mean = process_mean + white_mean;
    let noise_var = white_var + cross.iter().sum::<f64>() / kf;
    let spread = own.iter().map(|x| (x - process_mean).powi(2)).sum::<f64>() / (kf - 1.0);
    let mut pairs = 0.0;
    for a in 0..k {
        for b in a + 1..k {
            let g: f64 = members[a].iter().zip(&members[b]).map(|(x, y)| x * y).sum();
            pairs += g * g;
        }
    }
    let gaussian = 2.0 * pairs / (kf * (kf - 1.0) / 2.0) / (nf * nf);
    tau(mean, noise_var + spread.max(gaussian))
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
    /// [`Floor::chi2_tau`], read on first use (a floor made for a fit is never judged).
    pub chi2_tau_once: std::sync::OnceLock<f64>,
}

impl Floor {
    /// Samples per degree of freedom of the channel's chi-square per sample under the model's
    /// own noise ([`chi2_tau`]), and at least the correlation time `tau`: `n` over it gives the
    /// scaled chi-square the significance tests read. Both readings of the ensemble under-read
    /// a spread that wanders unequally between runs; where the mean correlation says more, it
    /// is kept (on a calibrated vehicle of another structure the Gaussian reading alone put a
    /// null run's depth channel off).
    pub fn chi2_tau(&self) -> f64 {
        *self
            .chi2_tau_once
            .get_or_init(|| chi2_tau(&self.null, &self.sigma, &self.measurement_std).max(self.tau))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, StandardNormal};

    /// White noise has one sample per degree of freedom; a process offset constant over a
    /// member's run, as large as the white noise, leaves `n / 4 + 3 / 4` samples per degree
    /// (`sum C^2` is `n^2 / 4 + 3 n / 4` for `C_ij = (1 + delta_ij) / 2`), to 15 % with 400
    /// members.
    #[test]
    fn samples_per_degree_of_white_noise_and_of_a_constant_offset() {
        let n = 400;
        let white = chi2_tau(&[], &vec![1.0; n], &vec![1.0; n]);
        assert!((white - 1.0).abs() < 1e-12, "{white}");
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let null: Vec<Vec<f64>> = (0..400)
            .map(|_| {
                let a: f64 = StandardNormal.sample(&mut rng);
                vec![a; n]
            })
            .collect();
        let sigma = vec![2f64.sqrt(); n];
        let tau = chi2_tau(&null, &sigma, &vec![1.0; n]);
        let expected = n as f64 / 4.0 + 0.75;
        assert!(
            (tau / expected - 1.0).abs() < 0.15,
            "{tau} against {expected}"
        );
    }

    /// The depth channel comes back from a contact once the heave, roll and pitch have
    /// forgotten it; every other channel waits for the surge. A heavier heave damping
    /// shortens the depth's wait, and with no heave damping it waits as long as the rest.
    #[test]
    fn the_depth_channel_forgets_a_contact_with_the_heave() {
        use crate::config::Embedded;
        use crate::physics::{DEFAULT_VEHICLE, load_vehicle};
        let mako = load_vehicle(&Embedded, DEFAULT_VEHICLE).unwrap();
        let memory = depth_contact_memory_s(&mako);
        let heave = (mako.mass_kg + mako.added_mass[2]) / mako.damping_linear[2];
        assert!(memory >= 3.0 * heave, "{memory} against heave {heave}");
        assert!(memory < CONTACT_MEMORY_S, "{memory}");

        let mut draggy = mako.clone();
        draggy.damping_linear[2] *= 2.0;
        assert!(depth_contact_memory_s(&draggy) < memory);
        let mut free = mako.clone();
        free.damping_linear[2] = 0.0;
        assert_eq!(depth_contact_memory_s(&free), CONTACT_MEMORY_S);

        let run = Run::touched_at(vec![[31.0, 33.0]], memory);
        let after_depth = 33.0 + memory + 0.5;
        assert!(after_depth < 33.0 + CONTACT_MEMORY_S);
        assert!(run.in_contact(33.0 + memory - 0.5, DEPTH_CHANNEL));
        assert!(!run.in_contact(after_depth, DEPTH_CHANNEL));
        for channel in ["x_m", "compass_deg", "accel_x_adc"] {
            assert!(run.in_contact(after_depth, channel), "{channel}");
            assert!(
                !run.in_contact(33.0 + CONTACT_MEMORY_S, channel),
                "{channel}"
            );
        }
        assert!(run.in_contact(31.0 - CONTACT_LEAD_S, DEPTH_CHANNEL));
    }
}

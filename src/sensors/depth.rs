//! Depth: SenSym SX15GD2 pressure bridge behind an amplifier (thesis 3.3.5, 4.1).
//!
//! Chain: depth of the sensor's mounting point, clamped at the surface (a gauge sensor reads
//! no negative pressure) -> hysteresis (backlash, `fraction * full scale`) -> optional
//! one-pole low-pass (the fixed Mako) -> the noise package (metres) -> `volts_per_m`
//! -> datasheet noise + EMI -> amplifier rails 0..=full scale volts.
//!
//! EMI from the stern motor's PWM (thesis 4.1, fig 4.1) is Gaussian with a standard
//! deviation proportional to the stern motor's PWM magnitude
//! (`|VehicleState::thruster_effort[STERN]|`), so its variance grows with the square of the
//! duty. With the low-pass on, EMI (broadband up to `emi_bandwidth_hz`) is attenuated by
//! `sqrt(pi/2 * fc / B)`, the noise-bandwidth ratio of a one-pole filter.

use rand::RngExt;
use rand_distr::StandardNormal;

use super::config::DepthSettings;
use super::noise::{Backlash, ErrorModel, LowPass};
use super::rng::{self, SensorRng};
use crate::physics::state::{STERN, VehicleState};

#[derive(Debug, Clone)]
pub struct DepthSensor {
    s: DepthSettings,
    position: nalgebra::Vector3<f64>,
    hysteresis: Option<Backlash>,
    low_pass: Option<LowPass>,
    errors: ErrorModel,
    emi_std_v: f64,
    rng: SensorRng,
}

impl DepthSensor {
    pub fn new(s: &DepthSettings, master_seed: u64) -> Self {
        Self {
            position: nalgebra::Vector3::from(s.position_body_m),
            hysteresis: (s.hysteresis_fraction_fs > 0.0)
                .then(|| Backlash::new(s.hysteresis_fraction_fs * s.full_scale_m)),
            low_pass: s.low_pass_cutoff_hz.map(LowPass::new),
            errors: ErrorModel::new(&s.errors),
            emi_std_v: 0.0,
            rng: rng::stream(master_seed, "depth"),
            s: s.clone(),
        }
    }

    /// EMI attenuation of the low-pass filter (1 without it).
    pub fn emi_attenuation(&self) -> f64 {
        self.s.low_pass_cutoff_hz.map_or(1.0, |fc| {
            (std::f64::consts::FRAC_PI_2 * fc / self.s.emi_bandwidth_hz).sqrt()
        })
    }

    /// The deterministic front of the chain after a physics step: the mounting point's depth,
    /// clamped at the surface, through the hysteresis and the low-pass (m), before the noise
    /// package. Stateful (backlash, filter): call once per step, in order. `update` uses it,
    /// and so does `gap`'s re-simulation, so its prediction follows the same chain.
    pub fn front_end_m(&mut self, state: &VehicleState) -> f64 {
        let mut d = state.depth_of_m(&self.position).max(0.0);
        if let Some(h) = &mut self.hysteresis {
            d = h.update(d);
        }
        if let Some(f) = &mut self.low_pass {
            d = f.update(state.t_s, d);
        }
        d
    }

    /// Follows the vehicle after a physics step.
    pub fn update(&mut self, state: &VehicleState) {
        let d = self.front_end_m(state);
        self.errors.push(state.t_s, d);
        let duty = state.thruster_effort[STERN].abs().min(1.0);
        self.emi_std_v = self.s.emi_v_rms_full_duty * duty * self.emi_attenuation();
    }

    /// The amplifier's output voltage when the ADC samples it at `t_s`.
    pub fn voltage(&mut self, t_s: f64) -> f64 {
        let Some(d) = self.errors.sample(t_s, &mut self.rng) else {
            return 0.0;
        };
        let mut v = d.max(0.0) * self.s.volts_per_m;
        let std = (self.s.noise_v_rms.powi(2) + self.emi_std_v.powi(2)).sqrt();
        if std > 0.0 {
            let n: f64 = self.rng.sample(StandardNormal);
            v += std * n;
        }
        v.clamp(0.0, self.s.full_scale_m * self.s.volts_per_m)
    }
}

//! Accelerometer: Freescale MMA7260Q at the 1.5 g range (thesis 3.3.1, 4.6, table 4.1).
//!
//! Each axis measures the body-frame specific force at the part's position
//! (`VehicleState::specific_force_at`: gravity projection plus motion, plus the tangential and
//! centripetal accelerations of a point away from the centre of mass; at rest and level
//! (0, 0, -g)). The sensor axes are the body
//! axes (forward, starboard, down). Chain per axis: one-pole low-pass (the part's internal
//! filter) -> noise package (m/s^2) -> `zero_g_v + sensitivity * f / g0` -> output noise
//! (4.7 mV rms) -> clipping to the output swing 0.45..2.85 V -> the ADC.

use nalgebra::Vector3;
use rand::RngExt;
use rand_distr::StandardNormal;

use super::config::AccelerometerSettings;
use super::noise::{ErrorModel, LowPass};
use super::rng::{self, SensorRng};
use crate::physics::state::VehicleState;

/// Standard gravity, the unit the datasheet's sensitivity is given in (m/s^2).
pub const G0_MPS2: f64 = 9.806_65;

#[derive(Debug, Clone)]
pub struct Accelerometer {
    s: AccelerometerSettings,
    filters: [LowPass; 3],
    errors: [ErrorModel; 3],
    rng: SensorRng,
}

impl Accelerometer {
    pub fn new(s: &AccelerometerSettings, master_seed: u64) -> Self {
        Self {
            filters: s.cutoff_hz.map(LowPass::new),
            errors: [(); 3].map(|_| ErrorModel::new(&s.errors)),
            rng: rng::stream(master_seed, "accelerometer"),
            s: s.clone(),
        }
    }

    pub fn update(&mut self, state: &VehicleState) {
        let specific = state.specific_force_at(&Vector3::from(self.s.position_body_m));
        for axis in 0..3 {
            let f = self.filters[axis].update(state.t_s, specific[axis]);
            self.errors[axis].push(state.t_s, f);
        }
    }

    /// The noiseless output voltage for specific force `f_mps2` (before clipping).
    pub fn ideal_voltage(&self, f_mps2: f64) -> f64 {
        self.s.zero_g_v + self.s.sensitivity_v_per_g * f_mps2 / G0_MPS2
    }

    /// The output voltage of `axis` (0 = x, 1 = y, 2 = z) when sampled at `t_s`.
    pub fn voltage(&mut self, axis: usize, t_s: f64) -> f64 {
        let Some(f) = self.errors[axis.min(2)].sample(t_s, &mut self.rng) else {
            return self.s.zero_g_v;
        };
        let mut v = self.ideal_voltage(f);
        if self.s.noise_v_rms > 0.0 {
            let n: f64 = self.rng.sample(StandardNormal);
            v += self.s.noise_v_rms * n;
        }
        v.clamp(self.s.min_v, self.s.max_v)
    }
}

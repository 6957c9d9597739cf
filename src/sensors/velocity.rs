//! Velocity: the Navman Speed 2100 paddle wheel (thesis 3.3.3, 4.5), and the EyeBot-side
//! pulse counter that turns its ADC channel into a speed.
//!
//! The paddle turns with the water-relative surge speed (`velocity_water_body_mps.x`, passed
//! through the noise package), `pulses_per_metre` half rotations per metre of water, either
//! direction. Each half rotation gives one pulse: the output is `high_v` for the first
//! `pulse_fraction` of every half rotation and 0 V otherwise. With `high_v` above the ADC
//! reference (the 12 V supply fault of thesis 3.3.3) the excess couples into every ADC
//! channel (see [`super::adc`]).
//!
//! [`PulseCounter`] is the reference of what the EyeBot program does: read the channel every
//! `poll_period_s` (10 ms), count rising edges, and once per `window_s` (1 s) report
//! `count / (pulses_per_metre * window_s) * firmware_scale`. The 5 cm/s resolution is not a
//! rounding step anywhere: it is one pulse per window (1 / (20 pulses/m * 1 s)).

use super::config::VelocitySettings;
use super::noise::ErrorModel;
use super::rng::{self, SensorRng};
use crate::physics::state::VehicleState;

#[derive(Debug, Clone)]
pub struct PaddleWheel {
    s: VelocitySettings,
    errors: ErrorModel,
    rng: SensorRng,
    /// Half rotations turned since the start (fractional).
    half_turns: f64,
    last_t_s: Option<f64>,
}

impl PaddleWheel {
    pub fn new(s: &VelocitySettings, master_seed: u64) -> Self {
        Self {
            errors: ErrorModel::new(&s.errors),
            rng: rng::stream(master_seed, "velocity"),
            half_turns: 0.0,
            last_t_s: None,
            s: s.clone(),
        }
    }

    pub fn update(&mut self, state: &VehicleState) {
        let t = state.t_s;
        self.errors.push(t, state.velocity_water_body_mps.x);
        // A dropout or a value not yet through the latency line leaves the paddle still.
        let u = self.errors.sample(t, &mut self.rng).unwrap_or(0.0);
        if let Some(last) = self.last_t_s {
            let dt = (t - last).max(0.0);
            self.half_turns += u.abs() * dt * self.s.pulses_per_metre;
        }
        self.last_t_s = Some(t);
    }

    /// True while the pulse output is high.
    pub fn is_high(&self) -> bool {
        self.half_turns.fract() < self.s.pulse_fraction
    }

    /// The output voltage now.
    pub fn voltage(&self) -> f64 {
        if self.is_high() { self.s.high_v } else { 0.0 }
    }

    /// Half rotations turned so far.
    pub fn half_turns(&self) -> f64 {
        self.half_turns
    }
}

/// The EyeBot-side computation: poll the ADC, count rising edges, report a speed per window.
#[derive(Debug, Clone)]
pub struct PulseCounter {
    pulses_per_metre: f64,
    window_s: f64,
    firmware_scale: f64,
    threshold_code: u16,
    was_high: Option<bool>,
    count: u32,
    window_start_s: Option<f64>,
}

impl PulseCounter {
    /// `threshold_code`: a code above it counts as high (mid-scale, 512, for a 0/5 V pulse).
    pub fn new(s: &VelocitySettings, threshold_code: u16) -> Self {
        Self {
            pulses_per_metre: s.pulses_per_metre,
            window_s: s.window_s,
            firmware_scale: s.firmware_scale,
            threshold_code,
            was_high: None,
            count: 0,
            window_start_s: None,
        }
    }

    /// Feeds one ADC reading taken at `t_s`; returns the speed (m/s, as the firmware reports
    /// it, i.e. including `firmware_scale`) when a window closes.
    pub fn poll(&mut self, code: u16, t_s: f64) -> Option<f64> {
        let high = code > self.threshold_code;
        if self.was_high == Some(false) && high {
            self.count += 1;
        }
        self.was_high = Some(high);
        let start = *self.window_start_s.get_or_insert(t_s);
        // Half a poll of slack so a window of 100 polls at 10 ms closes on the 100th.
        if t_s - start >= self.window_s - 1e-9 {
            let speed = f64::from(self.count) / (self.pulses_per_metre * self.window_s)
                * self.firmware_scale;
            self.count = 0;
            self.window_start_s = Some(t_s);
            Some(speed)
        } else {
            None
        }
    }
}

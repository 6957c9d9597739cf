//! Compass: the Vector 2X, a two-axis magneto-inductive sensor fixed to the hull (not
//! gimballed) (thesis 3.3.4, 4.2).
//!
//! The Earth field in NED is `F (cos I cos D, cos I sin D, sin I)` (total `F`, inclination
//! `I`, declination `D`; Perth by default). The sensor measures its body-frame x and y
//! components, so with the hull tilted part of the strong vertical field leaks into the
//! measuring plane: that is the tilt error (derivation in `docs/sensors.md`). The vehicle's
//! own iron distorts the plane field: `m = S b + h` (soft-iron matrix `S`, hard-iron offset
//! `h`, body frame, uT). Field noise is added per conversion. The two-point calibration
//! (`COMPASSCalibrate`: one reading, turn 180 deg, another) estimates `h` as the mean of the
//! two raw vectors and subtracts it from then on; it cannot remove `S`.
//!
//! Heading = `atan2(-m_y, m_x)` (magnetic, clockwise from magnetic north), through the noise
//! package (deg), rounded to 1 deg, 0..=359. Raw mode gives `m` in counts.
//!
//! Timing: in continuous mode a conversion completes every `continuous_period_s` (2.5 Hz);
//! in poll mode [`Compass::request`] starts one and its result is ready
//! `conversion_delay_s` later. Conversions use the field of the latest
//! [`Compass::update`].

use nalgebra::{Matrix2, Vector2, Vector3};
use rand::RngExt;
use rand_distr::StandardNormal;

use super::config::CompassSettings;
use super::noise::ErrorModel;
use super::rng::{self, SensorRng};
use crate::physics::state::VehicleState;

/// One compass output.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct CompassReading {
    /// Magnetic heading, whole degrees 0..=359.
    pub heading_deg: u16,
    /// Raw field in the sensor's x (forward) and y (starboard) axes, counts.
    pub raw_x: i16,
    pub raw_y: i16,
}

/// How the compass is being run.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CompassMode {
    /// Free-running: a new reading every `continuous_period_s`.
    Continuous,
    /// Slave/poll mode: a reading only on request.
    Poll,
}

/// Where the two-point calibration stands.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Calibration {
    None,
    /// One reading taken; turn 180 deg and take the second.
    FirstTaken,
    /// Hard-iron offset estimated (uT, body x and y).
    Done {
        offset_ut: [f64; 2],
    },
}

#[derive(Debug, Clone)]
pub struct Compass {
    s: CompassSettings,
    earth_ned_ut: Vector3<f64>,
    soft: Matrix2<f64>,
    hard: Vector2<f64>,
    errors: ErrorModel,
    rng: SensorRng,
    /// Distorted plane field at the latest update (uT), before noise.
    field_ut: Vector2<f64>,
    t_s: f64,
    mode: CompassMode,
    next_conversion_s: Option<f64>,
    calibration: Calibration,
    first_cal_ut: Vector2<f64>,
    latest: Option<(f64, CompassReading)>,
    delivered: bool,
    /// Recent (t_s, field) pairs when the settings give a latency: a conversion at `t`
    /// senses the field of `t - latency_s`, interpolated between physics steps.
    history: std::collections::VecDeque<(f64, Vector2<f64>)>,
}

impl Compass {
    pub fn new(s: &CompassSettings, master_seed: u64) -> Self {
        let (i, d) = (
            s.inclination_deg.to_radians(),
            s.declination_deg.to_radians(),
        );
        Self {
            earth_ned_ut: s.field_ut * Vector3::new(i.cos() * d.cos(), i.cos() * d.sin(), i.sin()),
            soft: Matrix2::new(
                s.soft_iron[0][0],
                s.soft_iron[0][1],
                s.soft_iron[1][0],
                s.soft_iron[1][1],
            ),
            hard: Vector2::from(s.hard_iron_ut),
            // The latency delays the sensed field (see `history`), not the finished reading,
            // so a delay shorter than the conversion period still shows.
            errors: ErrorModel::new(&crate::sensors::noise::NoiseSettings {
                latency_s: 0.0,
                ..s.errors.clone()
            }),
            rng: rng::stream(master_seed, "compass"),
            field_ut: Vector2::zeros(),
            t_s: 0.0,
            mode: CompassMode::Continuous,
            next_conversion_s: Some(0.0),
            calibration: Calibration::None,
            first_cal_ut: Vector2::zeros(),
            latest: None,
            delivered: true,
            history: std::collections::VecDeque::new(),
            s: s.clone(),
        }
    }

    /// The Earth field in NED, uT.
    pub fn earth_field_ned_ut(&self) -> Vector3<f64> {
        self.earth_ned_ut
    }

    pub fn mode(&self) -> CompassMode {
        self.mode
    }

    /// Switches mode at `t_s`. Continuous mode's first reading completes one period later.
    pub fn set_mode(&mut self, mode: CompassMode, t_s: f64) {
        self.mode = mode;
        self.next_conversion_s = match mode {
            CompassMode::Continuous => Some(t_s + self.s.continuous_period_s),
            CompassMode::Poll => None,
        };
    }

    /// Poll mode: starts a conversion at `t_s`; its reading is ready `conversion_delay_s`
    /// later. A request while one is running is ignored.
    pub fn request(&mut self, t_s: f64) {
        if self.mode == CompassMode::Poll && self.next_conversion_s.is_none() {
            self.next_conversion_s = Some(t_s + self.s.conversion_delay_s);
        }
    }

    /// The time the next reading completes, if one is scheduled.
    pub fn poll_timeout(&self) -> Option<f64> {
        self.next_conversion_s
    }

    /// Follows the vehicle after a physics step and completes the conversions due by then.
    pub fn update(&mut self, state: &VehicleState) {
        let b_body = state.attitude.inverse_transform_vector(&self.earth_ned_ut);
        self.field_ut = self.soft * Vector2::new(b_body.x, b_body.y) + self.hard;
        self.t_s = state.t_s;
        let latency_s = self.s.errors.latency_s;
        if latency_s > 0.0 {
            self.history.push_back((state.t_s, self.field_ut));
            while self.history.len() > 2 && self.history[1].0 <= state.t_s - latency_s - 1.0 {
                self.history.pop_front();
            }
        }
        while let Some(due) = self.next_conversion_s
            && due <= state.t_s
        {
            let reading = self.convert(due);
            self.latest = Some((due, reading));
            self.delivered = false;
            self.next_conversion_s = match self.mode {
                CompassMode::Continuous => Some(due + self.s.continuous_period_s),
                CompassMode::Poll => None,
            };
        }
    }

    /// A reading completed since the last call, if any (`COMPASSCheck` / `COMPASSGet`).
    pub fn poll(&mut self) -> Option<CompassReading> {
        if self.delivered {
            return None;
        }
        self.delivered = true;
        self.latest.map(|(_, r)| r)
    }

    /// The newest reading and when it completed.
    pub fn latest(&self) -> Option<(f64, CompassReading)> {
        self.latest
    }

    /// Converts the current field now, outside the schedule (for tests and validation).
    pub fn convert_now(&mut self) -> CompassReading {
        self.convert(self.t_s)
    }

    /// The field the sensor sees at `t_s`: the current one, or with a latency the field of
    /// `t_s - latency_s`, linearly interpolated between the recorded steps.
    fn sensed_field(&self, t_s: f64) -> Vector2<f64> {
        let latency_s = self.s.errors.latency_s;
        if latency_s <= 0.0 {
            return self.field_ut;
        }
        let due = t_s - latency_s;
        let Some(&(t0, f0)) = self.history.front() else {
            return self.field_ut;
        };
        if due <= t0 {
            return f0;
        }
        for w in self.history.iter().zip(self.history.iter().skip(1)) {
            let ((ta, fa), (tb, fb)) = (*w.0, *w.1);
            if due <= tb {
                let a = if tb > ta { (due - ta) / (tb - ta) } else { 1.0 };
                return fa + (fb - fa) * a;
            }
        }
        self.field_ut
    }

    fn noisy_field(&mut self, t_s: f64) -> Vector2<f64> {
        let mut m = self.sensed_field(t_s);
        if self.s.field_noise_ut > 0.0 {
            let nx: f64 = self.rng.sample(StandardNormal);
            let ny: f64 = self.rng.sample(StandardNormal);
            m += self.s.field_noise_ut * Vector2::new(nx, ny);
        }
        m
    }

    fn convert(&mut self, t_s: f64) -> CompassReading {
        let m = self.noisy_field(t_s);
        let counts = |x: f64| {
            (x * self.s.raw_counts_per_ut)
                .round()
                .clamp(f64::from(i16::MIN), f64::from(i16::MAX)) as i16
        };
        let corrected = match self.calibration {
            Calibration::Done { offset_ut } => m - Vector2::from(offset_ut),
            _ => m,
        };
        let heading = (-corrected.y).atan2(corrected.x).to_degrees();
        self.errors.push(t_s, heading);
        let heading = self.errors.sample(t_s, &mut self.rng).unwrap_or(heading);
        let whole = heading.round().rem_euclid(360.0) as u16 % 360;
        CompassReading {
            heading_deg: whole,
            raw_x: counts(m.x),
            raw_y: counts(m.y),
        }
    }

    /// `COMPASSCalibrate(0)`: forgets the calibration.
    pub fn calibration_reset(&mut self) {
        self.calibration = Calibration::None;
    }

    /// `COMPASSCalibrate(1)`: takes one calibration reading of the current field. The second
    /// call (after turning 180 deg) completes the calibration.
    pub fn calibration_reading(&mut self) -> Calibration {
        let m = self.noisy_field(self.t_s);
        self.calibration = match self.calibration {
            Calibration::FirstTaken => {
                let offset = (self.first_cal_ut + m) / 2.0;
                Calibration::Done {
                    offset_ut: [offset.x, offset.y],
                }
            }
            _ => {
                self.first_cal_ut = m;
                Calibration::FirstTaken
            }
        };
        self.calibration
    }

    pub fn calibration(&self) -> Calibration {
        self.calibration
    }
}

/// Wraps an angle difference into -180..180 deg.
pub fn wrap_deg(a: f64) -> f64 {
    (a + 180.0).rem_euclid(360.0) - 180.0
}

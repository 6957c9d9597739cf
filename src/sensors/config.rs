//! Sensor settings: TOML text -> raw structs (`deny_unknown_fields`) -> checked settings.
//!
//! The files live in `configs/sensors/`; every parameter there carries its unit and source.
//! Errors name the file, the line and the key (via [`Document`]).

use super::noise::NoiseSettings;
use crate::config::{ConfigError, ConfigSource, Document};

mod raw;
use raw::RawSensors;

// ---------------------------------------------------------------- resolved settings

/// Everything the sensor suite needs.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorsConfig {
    pub adc: AdcSettings,
    pub depth: DepthSettings,
    pub velocity: VelocitySettings,
    pub accelerometer: AccelerometerSettings,
    pub compass: CompassSettings,
    pub sonar: SonarSettings,
}

/// What is wired to an ADC channel (the HDT's analog table).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum AdcSource {
    Depth,
    Velocity,
    AccelX,
    AccelY,
    AccelZ,
}

impl AdcSource {
    pub const ALL: [AdcSource; 5] = [
        AdcSource::Depth,
        AdcSource::Velocity,
        AdcSource::AccelX,
        AdcSource::AccelY,
        AdcSource::AccelZ,
    ];

    pub fn key(self) -> &'static str {
        match self {
            AdcSource::Depth => "depth",
            AdcSource::Velocity => "velocity",
            AdcSource::AccelX => "accel_x",
            AdcSource::AccelY => "accel_y",
            AdcSource::AccelZ => "accel_z",
        }
    }
}

#[derive(Debug, Clone, PartialEq)]
pub struct AdcSettings {
    pub reference_v: f64,
    pub bits: u32,
    pub offset_lsb: f64,
    pub noise_v_rms: f64,
    pub first_read_retention: f64,
    pub overvoltage_coupling: f64,
    /// `channels[i]` is what channel `i` reads (`None` = unconnected, reads 0 V).
    pub channels: [Option<AdcSource>; 8],
}

impl DepthSettings {
    /// The largest EMI level a configuration accepts (V rms at full stern duty, before the
    /// front end's low-pass).
    pub const EMI_V_RMS_FULL_DUTY_MAX: f64 = 5.0;
}

#[derive(Debug, Clone, PartialEq)]
pub struct DepthSettings {
    pub position_body_m: [f64; 3],
    pub full_scale_m: f64,
    pub volts_per_m: f64,
    pub hysteresis_fraction_fs: f64,
    pub noise_v_rms: f64,
    pub emi_v_rms_full_duty: f64,
    pub low_pass_cutoff_hz: Option<f64>,
    pub emi_bandwidth_hz: f64,
    pub errors: NoiseSettings,
}

#[derive(Debug, Clone, PartialEq)]
pub struct VelocitySettings {
    pub pulses_per_metre: f64,
    pub pulse_fraction: f64,
    pub high_v: f64,
    pub poll_period_s: f64,
    pub window_s: f64,
    pub firmware_scale: f64,
    pub errors: NoiseSettings,
}

#[derive(Debug, Clone, PartialEq)]
pub struct AccelerometerSettings {
    /// Where the part sits in the body frame (m from the centre of mass): it reads the
    /// specific force there.
    pub position_body_m: [f64; 3],
    pub zero_g_v: f64,
    pub sensitivity_v_per_g: f64,
    pub min_v: f64,
    pub max_v: f64,
    pub noise_v_rms: f64,
    pub cutoff_hz: [f64; 3],
    pub errors: NoiseSettings,
}

#[derive(Debug, Clone, PartialEq)]
pub struct CompassSettings {
    pub field_ut: f64,
    pub inclination_deg: f64,
    pub declination_deg: f64,
    pub hard_iron_ut: [f64; 2],
    pub soft_iron: [[f64; 2]; 2],
    pub field_noise_ut: f64,
    pub raw_counts_per_ut: f64,
    pub continuous_period_s: f64,
    pub conversion_delay_s: f64,
    pub errors: NoiseSettings,
}

#[derive(Debug, Clone, PartialEq)]
pub struct TransducerSettings {
    pub name: String,
    pub controller: usize,
    pub position_body_m: [f64; 3],
    pub azimuth_deg: f64,
    pub elevation_deg: f64,
}

#[derive(Debug, Clone, PartialEq)]
pub struct SonarTiming {
    pub period_s: f64,
    pub command_latency_s: f64,
    pub relay_switch_s: f64,
    pub reacquire_pings: u32,
    pub ack_latency_s: f64,
    pub sentence_latency_s: f64,
}

#[derive(Debug, Clone, PartialEq)]
pub struct SonarSettings {
    pub beam_width_deg: f64,
    pub cone_rings: u32,
    pub min_range_m: f64,
    /// (range m, detection probability 0..1), ranges strictly increasing.
    pub detection: Vec<(f64, f64)>,
    pub max_incidence_deg: f64,
    pub incidence_sigma_deg: f64,
    pub speed_half_mps: f64,
    pub resolution_m: f64,
    pub crosstalk_probability: f64,
    pub reverberation_probability: f64,
    pub errors: NoiseSettings,
    pub timing: SonarTiming,
    pub transducers: Vec<TransducerSettings>,
}

impl SensorsConfig {
    /// Loads and checks `name` from `source`.
    pub fn load(source: &dyn ConfigSource, name: &str) -> Result<Self, ConfigError> {
        let text = source.read(name)?;
        Self::from_text(source.describe(name), &text)
    }

    /// Parses and checks sensor settings from TOML text; `origin` names it in errors.
    pub fn from_text(origin: impl Into<String>, text: &str) -> Result<Self, ConfigError> {
        let doc = Document::new(origin, text);
        let raw: RawSensors = doc.parse()?;
        raw.resolve(&doc)
    }

    /// The same sensors with every error source switched off: no noise, no EMI, no
    /// distortion, no dropouts, ideal ADC. Geometry, scaling, rates and timing stay.
    pub fn ideal(&self) -> Self {
        let mut c = self.clone();
        c.adc.offset_lsb = 0.0;
        c.adc.noise_v_rms = 0.0;
        c.adc.first_read_retention = 0.0;
        c.adc.overvoltage_coupling = 0.0;
        c.depth.hysteresis_fraction_fs = 0.0;
        c.depth.noise_v_rms = 0.0;
        c.depth.emi_v_rms_full_duty = 0.0;
        c.depth.low_pass_cutoff_hz = None;
        c.depth.errors = NoiseSettings::default();
        c.velocity.errors = NoiseSettings::default();
        c.velocity.high_v = c.velocity.high_v.min(c.adc.reference_v);
        c.accelerometer.noise_v_rms = 0.0;
        c.accelerometer.errors = NoiseSettings::default();
        c.compass.hard_iron_ut = [0.0; 2];
        c.compass.soft_iron = [[1.0, 0.0], [0.0, 1.0]];
        c.compass.field_noise_ut = 0.0;
        c.compass.errors = NoiseSettings::default();
        c.sonar.errors = NoiseSettings::default();
        c.sonar.crosstalk_probability = 0.0;
        c.sonar.reverberation_probability = 0.0;
        c
    }
}

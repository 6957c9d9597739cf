//! The sensor files as written (`deny_unknown_fields`) and their resolution into the
//! checked settings of [`super`]: every range check, with the file, line and key in its error.

use serde::Deserialize;

use super::super::noise::NoiseSettings;
use super::*;
use crate::config::{ConfigError, Document};

// ---------------------------------------------------------------- raw structs

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub(super) struct RawSensors {
    adc: RawAdc,
    depth: RawDepth,
    velocity: RawVelocity,
    accelerometer: RawAccelerometer,
    compass: RawCompass,
    sonar: RawSonar,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawNoise {
    latency_s: Option<f64>,
    rate_hz: Option<f64>,
    bias: Option<f64>,
    drift_std_per_sqrt_s: Option<f64>,
    gaussian_std: Option<f64>,
    uniform_half_width: Option<f64>,
    impulse_probability: Option<f64>,
    impulse_low: Option<f64>,
    impulse_high: Option<f64>,
    quantisation_step: Option<f64>,
    dropout_probability: Option<f64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAdc {
    reference_v: f64,
    bits: u32,
    offset_lsb: f64,
    noise_v_rms: f64,
    first_read_retention: f64,
    overvoltage_coupling: f64,
    channels: RawChannels,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawChannels {
    depth: Option<i64>,
    velocity: Option<i64>,
    accel_x: Option<i64>,
    accel_y: Option<i64>,
    accel_z: Option<i64>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawDepth {
    position_body_m: [f64; 3],
    full_scale_m: f64,
    volts_per_m: f64,
    hysteresis_fraction_fs: f64,
    noise_v_rms: f64,
    emi_v_rms_full_duty: f64,
    low_pass_cutoff_hz: Option<f64>,
    emi_bandwidth_hz: f64,
    #[serde(default)]
    errors: RawNoise,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawVelocity {
    pulses_per_metre: f64,
    pulse_fraction: f64,
    high_v: f64,
    poll_period_s: f64,
    window_s: f64,
    firmware_scale: f64,
    #[serde(default)]
    errors: RawNoise,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawAccelerometer {
    #[serde(default)]
    position_body_m: [f64; 3],
    zero_g_v: f64,
    sensitivity_v_per_g: f64,
    min_v: f64,
    max_v: f64,
    noise_v_rms: f64,
    cutoff_hz: [f64; 3],
    #[serde(default)]
    errors: RawNoise,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawCompass {
    field_ut: f64,
    inclination_deg: f64,
    declination_deg: f64,
    hard_iron_ut: [f64; 2],
    soft_iron: [[f64; 2]; 2],
    field_noise_ut: f64,
    raw_counts_per_ut: f64,
    continuous_period_s: f64,
    conversion_delay_s: f64,
    #[serde(default)]
    errors: RawNoise,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTransducer {
    name: String,
    controller: i64,
    position_body_m: [f64; 3],
    azimuth_deg: f64,
    elevation_deg: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawTiming {
    period_s: f64,
    command_latency_s: f64,
    relay_switch_s: f64,
    reacquire_pings: i64,
    ack_latency_s: f64,
    sentence_latency_s: f64,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSonar {
    beam_width_deg: f64,
    cone_rings: i64,
    min_range_m: f64,
    detection_range_m: Vec<f64>,
    detection_percent: Vec<f64>,
    max_incidence_deg: f64,
    incidence_sigma_deg: f64,
    speed_half_mps: f64,
    resolution_m: f64,
    crosstalk_probability: f64,
    reverberation_probability: f64,
    #[serde(default)]
    errors: RawNoise,
    timing: RawTiming,
    transducer: Vec<RawTransducer>,
}

// ---------------------------------------------------------------- resolution

fn positive(
    doc: &Document<'_>,
    key: &str,
    v: f64,
    max: f64,
    unit: &str,
) -> Result<f64, ConfigError> {
    let v = doc.check_range(key, v, 0.0, max, unit)?;
    if v > 0.0 {
        Ok(v)
    } else {
        Err(doc.invalid(key, format!("must be greater than 0 {unit}")))
    }
}

fn probability(doc: &Document<'_>, key: &str, v: f64) -> Result<f64, ConfigError> {
    doc.check_range(key, v, 0.0, 1.0, "(probability)")
}

impl RawNoise {
    fn resolve(&self, doc: &Document<'_>, prefix: &str) -> Result<NoiseSettings, ConfigError> {
        let k = |name: &str| format!("{prefix}.errors.{name}");
        let nonneg = |name: &str, v: Option<f64>| -> Result<f64, ConfigError> {
            v.map_or(Ok(0.0), |v| {
                doc.check_range(&k(name), v, 0.0, 1e6, "(sensor unit)")
            })
        };
        let impulse = match (
            self.impulse_probability,
            self.impulse_low,
            self.impulse_high,
        ) {
            (None, None, None) => None,
            (Some(p), Some(lo), Some(hi)) => {
                probability(doc, &k("impulse_probability"), p)?;
                if !(lo.is_finite() && hi.is_finite()) {
                    return Err(doc.invalid(&k("impulse_low"), "must be finite"));
                }
                Some((p, lo, hi))
            }
            _ => {
                return Err(doc.invalid(
                    &k("impulse_probability"),
                    "impulse noise needs impulse_probability, impulse_low and impulse_high together",
                ));
            }
        };
        Ok(NoiseSettings {
            latency_s: nonneg("latency_s", self.latency_s)?,
            rate_hz: match self.rate_hz {
                Some(r) => Some(positive(doc, &k("rate_hz"), r, 1e6, "Hz")?),
                None => None,
            },
            bias: match self.bias {
                Some(b) => doc.check_range(&k("bias"), b, -1e6, 1e6, "(sensor unit)")?,
                None => 0.0,
            },
            drift_std_per_sqrt_s: nonneg("drift_std_per_sqrt_s", self.drift_std_per_sqrt_s)?,
            gaussian_std: nonneg("gaussian_std", self.gaussian_std)?,
            uniform_half_width: nonneg("uniform_half_width", self.uniform_half_width)?,
            impulse,
            quantisation_step: match self.quantisation_step {
                Some(q) => Some(positive(
                    doc,
                    &k("quantisation_step"),
                    q,
                    1e6,
                    "(sensor unit)",
                )?),
                None => None,
            },
            dropout_probability: match self.dropout_probability {
                Some(p) => probability(doc, &k("dropout_probability"), p)?,
                None => 0.0,
            },
        })
    }
}

fn finite3(doc: &Document<'_>, key: &str, v: [f64; 3], max: f64) -> Result<[f64; 3], ConfigError> {
    for (i, x) in v.iter().enumerate() {
        doc.check_range(&format!("{key}.{i}"), *x, -max, max, "m")?;
    }
    Ok(v)
}

impl RawSensors {
    pub(super) fn resolve(self, doc: &Document<'_>) -> Result<SensorsConfig, ConfigError> {
        let adc = self.adc.resolve(doc)?;
        let depth = self.depth.resolve(doc)?;
        let velocity = self.velocity.resolve(doc)?;
        let accelerometer = self.accelerometer.resolve(doc)?;
        let compass = self.compass.resolve(doc)?;
        let sonar = self.sonar.resolve(doc)?;
        Ok(SensorsConfig {
            adc,
            depth,
            velocity,
            accelerometer,
            compass,
            sonar,
        })
    }
}

impl RawDepth {
    /// Checks the depth sensor's settings; a low-pass cutoff, if any, must lie below the
    /// EMI bandwidth it filters.
    fn resolve(&self, doc: &Document<'_>) -> Result<DepthSettings, ConfigError> {
        let d = self;
        let depth = DepthSettings {
            position_body_m: finite3(doc, "depth.position_body_m", d.position_body_m, 2.0)?,
            full_scale_m: positive(doc, "depth.full_scale_m", d.full_scale_m, 100.0, "m")?,
            volts_per_m: positive(doc, "depth.volts_per_m", d.volts_per_m, 100.0, "V/m")?,
            hysteresis_fraction_fs: doc.check_range(
                "depth.hysteresis_fraction_fs",
                d.hysteresis_fraction_fs,
                0.0,
                0.1,
                "(fraction of full scale)",
            )?,
            noise_v_rms: doc.check_range("depth.noise_v_rms", d.noise_v_rms, 0.0, 1.0, "V")?,
            emi_v_rms_full_duty: doc.check_range(
                "depth.emi_v_rms_full_duty",
                d.emi_v_rms_full_duty,
                0.0,
                DepthSettings::EMI_V_RMS_FULL_DUTY_MAX,
                "V",
            )?,
            low_pass_cutoff_hz: match d.low_pass_cutoff_hz {
                Some(f) => Some(positive(doc, "depth.low_pass_cutoff_hz", f, 1e5, "Hz")?),
                None => None,
            },
            emi_bandwidth_hz: positive(
                doc,
                "depth.emi_bandwidth_hz",
                d.emi_bandwidth_hz,
                1e7,
                "Hz",
            )?,
            errors: d.errors.resolve(doc, "depth")?,
        };
        if let Some(fc) = depth.low_pass_cutoff_hz
            && fc >= depth.emi_bandwidth_hz
        {
            return Err(doc.invalid(
                "depth.low_pass_cutoff_hz",
                format!(
                    "{fc} Hz must lie below depth.emi_bandwidth_hz ({} Hz)",
                    depth.emi_bandwidth_hz
                ),
            ));
        }
        Ok(depth)
    }
}

impl RawVelocity {
    /// Checks the velocity sensor's settings; its averaging window must span at least one
    /// poll period.
    fn resolve(&self, doc: &Document<'_>) -> Result<VelocitySettings, ConfigError> {
        let v = self;
        let velocity = VelocitySettings {
            pulses_per_metre: positive(
                doc,
                "velocity.pulses_per_metre",
                v.pulses_per_metre,
                1e4,
                "pulses/m",
            )?,
            pulse_fraction: {
                let f = doc.check_range(
                    "velocity.pulse_fraction",
                    v.pulse_fraction,
                    0.0,
                    1.0,
                    "(fraction)",
                )?;
                if f <= 0.0 || f >= 1.0 {
                    return Err(doc.invalid(
                        "velocity.pulse_fraction",
                        "must lie strictly between 0 and 1",
                    ));
                }
                f
            },
            high_v: positive(doc, "velocity.high_v", v.high_v, 24.0, "V")?,
            poll_period_s: positive(doc, "velocity.poll_period_s", v.poll_period_s, 1.0, "s")?,
            window_s: positive(doc, "velocity.window_s", v.window_s, 60.0, "s")?,
            firmware_scale: positive(
                doc,
                "velocity.firmware_scale",
                v.firmware_scale,
                100.0,
                "(factor)",
            )?,
            errors: v.errors.resolve(doc, "velocity")?,
        };
        if velocity.window_s < velocity.poll_period_s {
            return Err(doc.invalid(
                "velocity.window_s",
                "must be at least velocity.poll_period_s",
            ));
        }
        Ok(velocity)
    }
}

impl RawAccelerometer {
    /// Checks the accelerometer's settings; the zero-g voltage must lie strictly inside its
    /// output range.
    fn resolve(&self, doc: &Document<'_>) -> Result<AccelerometerSettings, ConfigError> {
        let a = self;
        let r = AccelerometerSettings {
            position_body_m: finite3(doc, "accelerometer.position_body_m", a.position_body_m, 2.0)?,
            zero_g_v: positive(doc, "accelerometer.zero_g_v", a.zero_g_v, 5.0, "V")?,
            sensitivity_v_per_g: positive(
                doc,
                "accelerometer.sensitivity_v_per_g",
                a.sensitivity_v_per_g,
                5.0,
                "V/g",
            )?,
            min_v: doc.check_range("accelerometer.min_v", a.min_v, 0.0, 5.0, "V")?,
            max_v: doc.check_range("accelerometer.max_v", a.max_v, 0.0, 5.0, "V")?,
            noise_v_rms: doc.check_range(
                "accelerometer.noise_v_rms",
                a.noise_v_rms,
                0.0,
                1.0,
                "V",
            )?,
            cutoff_hz: {
                for (i, f) in a.cutoff_hz.iter().enumerate() {
                    positive(doc, &format!("accelerometer.cutoff_hz.{i}"), *f, 1e5, "Hz")?;
                }
                a.cutoff_hz
            },
            errors: a.errors.resolve(doc, "accelerometer")?,
        };
        if !(r.min_v < r.zero_g_v && r.zero_g_v < r.max_v) {
            return Err(doc.invalid(
                "accelerometer.zero_g_v",
                "must lie strictly between accelerometer.min_v and accelerometer.max_v",
            ));
        }
        Ok(r)
    }
}

impl RawCompass {
    /// Checks the compass's hard- and soft-iron calibration (the soft-iron matrix must be
    /// invertible), then its field and timing settings.
    fn resolve(&self, doc: &Document<'_>) -> Result<CompassSettings, ConfigError> {
        let c = self;
        for (i, h) in c.hard_iron_ut.iter().enumerate() {
            doc.check_range(
                &format!("compass.hard_iron_ut.{i}"),
                *h,
                -1000.0,
                1000.0,
                "uT",
            )?;
        }
        for (i, row) in c.soft_iron.iter().enumerate() {
            for (j, x) in row.iter().enumerate() {
                doc.check_range(
                    &format!("compass.soft_iron.{i}.{j}"),
                    *x,
                    -2.0,
                    2.0,
                    "(factor)",
                )?;
            }
        }
        let det = c.soft_iron[0][0] * c.soft_iron[1][1] - c.soft_iron[0][1] * c.soft_iron[1][0];
        if det.abs() < 0.1 {
            return Err(doc.invalid("compass.soft_iron", "matrix is (nearly) singular"));
        }
        Ok(CompassSettings {
            field_ut: positive(doc, "compass.field_ut", c.field_ut, 100.0, "uT")?,
            inclination_deg: doc.check_range(
                "compass.inclination_deg",
                c.inclination_deg,
                -89.0,
                89.0,
                "deg",
            )?,
            declination_deg: doc.check_range(
                "compass.declination_deg",
                c.declination_deg,
                -180.0,
                180.0,
                "deg",
            )?,
            hard_iron_ut: c.hard_iron_ut,
            soft_iron: c.soft_iron,
            field_noise_ut: doc.check_range(
                "compass.field_noise_ut",
                c.field_noise_ut,
                0.0,
                50.0,
                "uT",
            )?,
            raw_counts_per_ut: positive(
                doc,
                "compass.raw_counts_per_ut",
                c.raw_counts_per_ut,
                300.0,
                "counts/uT",
            )?,
            continuous_period_s: positive(
                doc,
                "compass.continuous_period_s",
                c.continuous_period_s,
                10.0,
                "s",
            )?,
            conversion_delay_s: doc.check_range(
                "compass.conversion_delay_s",
                c.conversion_delay_s,
                0.0,
                10.0,
                "s",
            )?,
            errors: c.errors.resolve(doc, "compass")?,
        })
    }
}
impl RawAdc {
    fn resolve(&self, doc: &Document<'_>) -> Result<AdcSettings, ConfigError> {
        let bits = self.bits;
        if !(8..=16).contains(&bits) {
            return Err(doc.invalid("adc.bits", format!("{bits} bits: expected 8..=16")));
        }
        let mut channels = [None; 8];
        let c = &self.channels;
        for (source, ch) in [
            (AdcSource::Depth, c.depth),
            (AdcSource::Velocity, c.velocity),
            (AdcSource::AccelX, c.accel_x),
            (AdcSource::AccelY, c.accel_y),
            (AdcSource::AccelZ, c.accel_z),
        ] {
            let Some(ch) = ch else { continue };
            let key = format!("adc.channels.{}", source.key());
            let idx = usize::try_from(ch)
                .ok()
                .filter(|i| *i < 8)
                .ok_or_else(|| doc.invalid(&key, format!("channel {ch}: expected 0..=7")))?;
            if let Some(other) = channels[idx] {
                return Err(doc.invalid(
                    &key,
                    format!(
                        "channel {idx} is already wired to `{}`",
                        AdcSource::key(other)
                    ),
                ));
            }
            channels[idx] = Some(source);
        }
        Ok(AdcSettings {
            reference_v: positive(doc, "adc.reference_v", self.reference_v, 10.0, "V")?,
            bits,
            offset_lsb: doc.check_range("adc.offset_lsb", self.offset_lsb, -0.5, 0.5, "LSB")?,
            noise_v_rms: doc.check_range("adc.noise_v_rms", self.noise_v_rms, 0.0, 0.5, "V")?,
            first_read_retention: doc.check_range(
                "adc.first_read_retention",
                self.first_read_retention,
                0.0,
                1.0,
                "(fraction)",
            )?,
            overvoltage_coupling: doc.check_range(
                "adc.overvoltage_coupling",
                self.overvoltage_coupling,
                0.0,
                1.0,
                "(V per V)",
            )?,
            channels,
        })
    }
}

impl RawSonar {
    fn resolve(&self, doc: &Document<'_>) -> Result<SonarSettings, ConfigError> {
        let detection = self.resolve_detection(doc)?;
        let rings = u32::try_from(self.cone_rings)
            .ok()
            .filter(|r| *r <= 8)
            .ok_or_else(|| doc.invalid("sonar.cone_rings", "expected 0..=8"))?;
        let timing = self.timing.resolve(doc)?;
        let transducers = self.resolve_transducers(doc)?;
        Ok(SonarSettings {
            beam_width_deg: positive(
                doc,
                "sonar.beam_width_deg",
                self.beam_width_deg,
                90.0,
                "deg",
            )?,
            cone_rings: rings,
            min_range_m: doc.check_range("sonar.min_range_m", self.min_range_m, 0.0, 10.0, "m")?,
            detection,
            max_incidence_deg: doc.check_range(
                "sonar.max_incidence_deg",
                self.max_incidence_deg,
                0.0,
                90.0,
                "deg",
            )?,
            incidence_sigma_deg: positive(
                doc,
                "sonar.incidence_sigma_deg",
                self.incidence_sigma_deg,
                90.0,
                "deg",
            )?,
            speed_half_mps: positive(
                doc,
                "sonar.speed_half_mps",
                self.speed_half_mps,
                10.0,
                "m/s",
            )?,
            resolution_m: positive(doc, "sonar.resolution_m", self.resolution_m, 1.0, "m")?,
            crosstalk_probability: probability(
                doc,
                "sonar.crosstalk_probability",
                self.crosstalk_probability,
            )?,
            reverberation_probability: probability(
                doc,
                "sonar.reverberation_probability",
                self.reverberation_probability,
            )?,
            errors: self.errors.resolve(doc, "sonar")?,
            timing,
            transducers,
        })
    }

    /// Checks the detection curve: one percentage per range, at least two points, ranges
    /// strictly increasing; returns (range m, probability) pairs.
    fn resolve_detection(&self, doc: &Document<'_>) -> Result<Vec<(f64, f64)>, ConfigError> {
        if self.detection_range_m.len() != self.detection_percent.len()
            || self.detection_range_m.len() < 2
        {
            return Err(doc.invalid(
                "sonar.detection_percent",
                format!(
                    "needs one percentage per range and at least two points; got {} ranges, {} percentages",
                    self.detection_range_m.len(),
                    self.detection_percent.len()
                ),
            ));
        }
        let mut detection = Vec::with_capacity(self.detection_range_m.len());
        for (i, (r, p)) in self
            .detection_range_m
            .iter()
            .zip(&self.detection_percent)
            .enumerate()
        {
            let r = positive(doc, &format!("sonar.detection_range_m.{i}"), *r, 100.0, "m")?;
            let p =
                doc.check_range(&format!("sonar.detection_percent.{i}"), *p, 0.0, 100.0, "%")?;
            if let Some((prev, _)) = detection.last()
                && r <= *prev
            {
                return Err(doc.invalid(
                    &format!("sonar.detection_range_m.{i}"),
                    "ranges must increase strictly",
                ));
            }
            detection.push((r, p / 100.0));
        }
        Ok(detection)
    }

    /// Checks the four `[[sonar.transducer]]` tables: each on controller 0 or 1 with a
    /// unique non-empty name, two per controller.
    fn resolve_transducers(
        &self,
        doc: &Document<'_>,
    ) -> Result<Vec<TransducerSettings>, ConfigError> {
        if self.transducer.len() != 4 {
            return Err(doc.invalid(
                "sonar.transducer",
                format!(
                    "the multiplexer has four transducers; got {}",
                    self.transducer.len()
                ),
            ));
        }
        let mut transducers = Vec::new();
        let mut per_controller = [0usize; 2];
        for (i, tr) in self.transducer.iter().enumerate() {
            let key = |k: &str| format!("sonar.transducer.{i}.{k}");
            let controller = usize::try_from(tr.controller)
                .ok()
                .filter(|c| *c < 2)
                .ok_or_else(|| doc.invalid(&key("controller"), "expected 0 or 1"))?;
            per_controller[controller] += 1;
            if tr.name.is_empty()
                || transducers
                    .iter()
                    .any(|t: &TransducerSettings| t.name == tr.name)
            {
                return Err(doc.invalid(&key("name"), "names must be non-empty and unique"));
            }
            transducers.push(TransducerSettings {
                name: tr.name.clone(),
                controller,
                position_body_m: finite3(doc, &key("position_body_m"), tr.position_body_m, 2.0)?,
                azimuth_deg: doc.check_range(
                    &key("azimuth_deg"),
                    tr.azimuth_deg,
                    -180.0,
                    180.0,
                    "deg",
                )?,
                elevation_deg: doc.check_range(
                    &key("elevation_deg"),
                    tr.elevation_deg,
                    -90.0,
                    90.0,
                    "deg",
                )?,
            });
        }
        if per_controller != [2, 2] {
            return Err(doc.invalid(
                "sonar.transducer",
                format!("each controller owns two transducers; got {per_controller:?}"),
            ));
        }
        Ok(transducers)
    }
}

impl RawTiming {
    /// Checks the sonar's timing: ping period, latencies, relay switching and the pings lost
    /// while a transducer reacquires.
    fn resolve(&self, doc: &Document<'_>) -> Result<SonarTiming, ConfigError> {
        let t = self;
        Ok(SonarTiming {
            period_s: positive(doc, "sonar.timing.period_s", t.period_s, 60.0, "s")?,
            command_latency_s: doc.check_range(
                "sonar.timing.command_latency_s",
                t.command_latency_s,
                0.0,
                10.0,
                "s",
            )?,
            relay_switch_s: doc.check_range(
                "sonar.timing.relay_switch_s",
                t.relay_switch_s,
                0.0,
                10.0,
                "s",
            )?,
            reacquire_pings: u32::try_from(t.reacquire_pings)
                .ok()
                .filter(|p| *p <= 10)
                .ok_or_else(|| doc.invalid("sonar.timing.reacquire_pings", "expected 0..=10"))?,
            ack_latency_s: doc.check_range(
                "sonar.timing.ack_latency_s",
                t.ack_latency_s,
                0.0,
                10.0,
                "s",
            )?,
            sentence_latency_s: doc.check_range(
                "sonar.timing.sentence_latency_s",
                t.sentence_latency_s,
                0.0,
                10.0,
                "s",
            )?,
        })
    }
}

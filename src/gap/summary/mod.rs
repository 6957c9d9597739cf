//! Summary observations: a quantity measured in an experiment, with its uncertainty, instead
//! of a time series. The thesis reports Mako's vehicle measurements this way (top speed
//! 0.44 m/s, coast-down 32 s, spot-turn circle 0.8 m, ...), so `gap` takes them too.
//!
//! ```toml
//! # summary.toml (in a measurement directory, or any file passed to `gap --measured`)
//! name = "mako-2008"
//! description = "Mako's vehicle measurements, thesis chapter 4"
//!
//! [[observation]]
//! name = "top speed"
//! experiment = "experiments/acceleration.toml"   # embedded name, or relative to this file
//! quantity = "top_speed_mps"                     # see [`Quantity`]
//! value = 0.44                                   # in the quantity's unit
//! sigma = 0.02                                   # 1 sigma, same unit
//! source = "thesis 4.5, fig 4.10"
//! from_s = 25.0                                  # optional, per quantity
//! ```
//!
//! The workflow ([`analyse`]): re-run every experiment with the model (thrust fluctuation off,
//! the experiment's own heading hold on), read each quantity the way the thesis read Mako
//! ([`crate::physics::measure`]), normalise `z = (sim - measured) / sigma` with
//! `sigma^2 = sigma_measured^2 + sigma_model^2` (`sigma_model`: spread over [`ENSEMBLE`] seeded
//! runs with the model's thrust fluctuation on), then fit every physics candidate of the
//! effect library ([`effects::LIBRARY`]) with Levenberg-Marquardt on `z`, rank by
//! `delta_BIC = chi2_0 - chi2_1 - k ln(n)` and add the winner greedily.
//!
//! Significance with few numbers (the guards of each candidate): a candidate is named only when (1) the data hold
//! more observations than it has parameters, (2) `delta_BIC > fit::BIC_MARGIN`, and (3) at
//! least `fit::SIGNATURE_MIN_SHARE` of its chi-square reduction comes from the observations it
//! should move ([`signature_kinds`]), and (4) its parameters lie strictly inside their
//! physical bounds with finite 95 % intervals, one clear of zero, and the joint refit leaves
//! the effects accepted before it inside theirs. With fewer than [`FEW_OBSERVATIONS`] observations the
//! report says that the BIC's large-sample footing is weak there and the verdict is a lead,
//! not a proof. After fitting, the remaining chi-square is compared with the chi-square 95 %
//! point for `n - k` degrees of freedom: above it, the model still disagrees beyond the stated
//! uncertainties and the report lists the observations the library could not explain.

mod fitting;
mod predict;
mod report;

pub use fitting::{ObservationResult, Prior, SummaryAnalysis, analyse};
pub use predict::{predict, quantity};
pub use report::{by_name, json, markdown, plot, write_all};

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::config::Document;
use crate::gap::GapError;
use crate::gap::effects::Effect;
use crate::gap::model::read_ref;
use crate::physics::experiment::Experiment;

/// The file name `gap --measured DIR` looks for.
pub const FILE_NAME: &str = "summary.toml";
/// Seeded runs with thrust fluctuation on, for the model's own spread.
pub const ENSEMBLE: u64 = 4;
/// Below this many observations the report warns that the BIC is a rough guide.
pub const FEW_OBSERVATIONS: usize = 10;
/// Default start of the top-speed average (s): the vehicle has settled (as `validate`).
pub const TOP_SPEED_FROM_S: f64 = crate::thesis::physics::TOP_SPEED_AVERAGE_FROM_S;

/// What an observation measured. Speeds are read like the thesis's pool-side camera (200 ms
/// progress samples along the experiment's initial heading, thesis 4.5); turns like its
/// overhead camera (thesis 4.7).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Quantity {
    /// Mean of the 200 ms samples in `from_s..until_s` (default 25 s .. end), m/s.
    TopSpeedMps,
    /// From `from_s` (default 0) to the first crossing of 85 % of the run's top speed (mean
    /// of the samples from 25 s on), interpolated between samples, s.
    TimeToTopSpeedS,
    /// From `from_s` (default 0) to the first crossing below 1.5 cm/s, interpolated between
    /// samples; a run that never comes to rest gives its end (censored), s.
    TimeToRestS,
    /// Spot turn: diameter of the centre's path over the last full turn, m.
    TurnDiameterM,
    /// Spot turn: mean time per 360 degrees over the full turns after the first, s.
    TurnPeriodS,
    /// Largest increase between consecutive 200 ms samples per sample period in
    /// `from_s..until_s`, m/s^2 (thesis 4.6 reads its bound this way).
    PeakAccelerationMps2,
}

/// Whether a value is a measurement or only a bound (thesis 4.6: the peak acceleration "can be
/// regarded as an upper bound"). A bound is met at no cost; beyond it the miss counts as
/// `(sim - value) / sigma`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum Bound {
    Value,
    Upper,
    Lower,
}

pub use crate::gap::effects::Behaviour;

impl Quantity {
    pub const ALL: [Quantity; 6] = [
        Quantity::TopSpeedMps,
        Quantity::TimeToTopSpeedS,
        Quantity::TimeToRestS,
        Quantity::TurnDiameterM,
        Quantity::TurnPeriodS,
        Quantity::PeakAccelerationMps2,
    ];

    pub fn name(self) -> &'static str {
        match self {
            Quantity::TopSpeedMps => "top_speed_mps",
            Quantity::TimeToTopSpeedS => "time_to_top_speed_s",
            Quantity::TimeToRestS => "time_to_rest_s",
            Quantity::TurnDiameterM => "turn_diameter_m",
            Quantity::TurnPeriodS => "turn_period_s",
            Quantity::PeakAccelerationMps2 => "peak_acceleration_mps2",
        }
    }

    pub fn unit(self) -> &'static str {
        match self {
            Quantity::TopSpeedMps => "m/s",
            Quantity::TurnDiameterM => "m",
            Quantity::PeakAccelerationMps2 => "m/s^2",
            _ => "s",
        }
    }

    pub fn behaviour(self) -> Behaviour {
        match self {
            Quantity::TopSpeedMps
            | Quantity::TimeToTopSpeedS
            | Quantity::TimeToRestS
            | Quantity::PeakAccelerationMps2 => Behaviour::Speed,
            Quantity::TurnDiameterM | Quantity::TurnPeriodS => Behaviour::Turn,
        }
    }

    fn parse(s: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|q| q.name() == s)
    }
}

/// The behaviours a physics candidate is expected to change (its summary-level signature,
/// [`Effect::summary`]). Effects that only change sensors move none.
pub fn signature_kinds(effect: &Effect) -> &'static [Behaviour] {
    effect.summary
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSummary {
    name: String,
    #[serde(default)]
    description: String,
    #[serde(rename = "observation")]
    observations: Vec<RawObservation>,
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawObservation {
    name: String,
    experiment: String,
    quantity: String,
    value: f64,
    sigma: f64,
    source: String,
    from_s: Option<f64>,
    until_s: Option<f64>,
    #[serde(default)]
    bound: Option<String>,
}

/// One observation, resolved.
#[derive(Debug, Clone, PartialEq)]
pub struct Observation {
    pub name: String,
    /// The experiment reference as written (for the report).
    pub experiment_ref: String,
    /// Index into [`Summary::experiments`].
    pub experiment: usize,
    pub quantity: Quantity,
    pub value: f64,
    /// 1 sigma, in the quantity's unit.
    pub sigma: f64,
    pub source: String,
    pub from_s: f64,
    pub until_s: Option<f64>,
    pub bound: Bound,
}

impl Observation {
    /// The normalised miss of a simulated value `v` (see [`Bound`]).
    pub fn z(&self, v: f64, sigma: f64) -> f64 {
        let d = v - self.value;
        match self.bound {
            Bound::Value => d / sigma,
            Bound::Upper => d.max(0.0) / sigma,
            Bound::Lower => d.min(0.0) / sigma,
        }
    }
}

/// A summary file, resolved: the experiments it refers to (each loaded once) and the
/// observations.
#[derive(Debug, Clone, PartialEq)]
pub struct Summary {
    pub name: String,
    pub description: String,
    pub experiments: Vec<Experiment>,
    pub observations: Vec<Observation>,
}

impl Summary {
    /// `path` is a summary file, or a directory holding [`FILE_NAME`].
    pub fn load(path: &Path) -> Result<Self, GapError> {
        let file = summary_file(path).unwrap_or_else(|| path.to_path_buf());
        let text = std::fs::read_to_string(&file).map_err(|source| GapError::Io {
            path: file.clone(),
            source,
        })?;
        let base = file.parent().map(Path::to_path_buf).unwrap_or_default();
        Self::from_text(&file.display().to_string(), &text, &base)
    }

    /// Parses a summary file's text; experiment references resolve against `base` first, then
    /// the embedded configs.
    pub fn from_text(origin: &str, text: &str, base: &Path) -> Result<Self, GapError> {
        let doc = Document::new(origin, text);
        let raw: RawSummary = doc.parse()?;
        if raw.observations.is_empty() {
            return Err(doc
                .invalid("observation", "at least one [[observation]] is required")
                .into());
        }
        let mut refs: Vec<String> = Vec::new();
        let mut experiments = Vec::new();
        let mut observations = Vec::new();
        for (i, o) in raw.observations.iter().enumerate() {
            let key = format!("observation.{i}");
            let quantity = Quantity::parse(&o.quantity).ok_or_else(|| {
                doc.invalid(
                    &format!("{key}.quantity"),
                    format!(
                        "unknown quantity `{}`; known: {}",
                        o.quantity,
                        Quantity::ALL.map(Quantity::name).join(", ")
                    ),
                )
            })?;
            if !o.value.is_finite() {
                return Err(doc
                    .invalid(&format!("{key}.value"), "must be a finite number")
                    .into());
            }
            let sigma =
                doc.check_range(&format!("{key}.sigma"), o.sigma, 1e-9, 1e9, quantity.unit())?;
            let experiment = match refs.iter().position(|r| *r == o.experiment) {
                Some(k) => k,
                None => {
                    let (eo, et) = read_ref(base, &o.experiment)?;
                    experiments.push(Experiment::from_document(&Document::new(eo, &et))?);
                    refs.push(o.experiment.clone());
                    refs.len() - 1
                }
            };
            let duration = experiments[experiment].duration_s;
            let from_s = match o.from_s {
                Some(f) => doc.check_range(&format!("{key}.from_s"), f, 0.0, duration, "s")?,
                None if quantity == Quantity::TopSpeedMps => TOP_SPEED_FROM_S.min(duration),
                None => 0.0,
            };
            let bound = match o.bound.as_deref() {
                None | Some("value") => Bound::Value,
                Some("upper") => Bound::Upper,
                Some("lower") => Bound::Lower,
                Some(other) => {
                    return Err(doc
                        .invalid(
                            &format!("{key}.bound"),
                            format!("unknown bound `{other}`; known: value, upper, lower"),
                        )
                        .into());
                }
            };
            let until_s = match o.until_s {
                Some(u) => {
                    Some(doc.check_range(&format!("{key}.until_s"), u, from_s, duration, "s")?)
                }
                None => None,
            };
            observations.push(Observation {
                name: o.name.clone(),
                experiment_ref: o.experiment.clone(),
                experiment,
                quantity,
                value: o.value,
                sigma,
                source: o.source.clone(),
                from_s,
                until_s,
                bound,
            });
        }
        Ok(Self {
            name: raw.name,
            description: raw.description,
            experiments,
            observations,
        })
    }
}

/// The summary file `path` stands for, if it is one: a `.toml` file, or a directory holding
/// [`FILE_NAME`].
pub fn summary_file(path: &Path) -> Option<PathBuf> {
    if path.is_dir() {
        let f = path.join(FILE_NAME);
        f.is_file().then_some(f)
    } else {
        (path.extension().is_some_and(|e| e == "toml") && path.is_file())
            .then(|| path.to_path_buf())
    }
}

/// Linear interpolation of the time at which `v` crosses `level` between two samples.
#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::effects;

    const ONE: &str = r#"name = "t"
[[observation]]
name = "top speed"
experiment = "experiments/acceleration.toml"
quantity = "top_speed_mps"
value = 0.44
sigma = 0.02
source = "thesis 4.5"
"#;

    #[test]
    fn parses_and_defaults_the_top_speed_window() {
        let s = Summary::from_text("s.toml", ONE, Path::new("/nonexistent")).unwrap();
        assert_eq!(s.observations.len(), 1);
        assert_eq!(s.observations[0].quantity, Quantity::TopSpeedMps);
        assert_eq!(s.observations[0].from_s, TOP_SPEED_FROM_S);
        assert_eq!(s.experiments[0].name, "acceleration");
    }

    #[test]
    fn unknown_quantity_names_the_file_line_and_choices() {
        let text = ONE.replace("top_speed_mps", "speed");
        let err = Summary::from_text("s.toml", &text, Path::new("/nonexistent"))
            .unwrap_err()
            .to_string();
        assert!(err.starts_with("s.toml:5:"), "{err}");
        assert!(err.contains("turn_diameter_m"), "{err}");
    }

    #[test]
    fn a_zero_sigma_is_rejected() {
        let text = ONE.replace("sigma = 0.02", "sigma = 0.0");
        let err = Summary::from_text("s.toml", &text, Path::new("/nonexistent"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("sigma"), "{err}");
    }

    #[test]
    fn an_unknown_experiment_is_an_error_not_a_panic() {
        let text = ONE.replace("experiments/acceleration.toml", "experiments/nope.toml");
        assert!(Summary::from_text("s.toml", &text, Path::new("/nonexistent")).is_err());
    }

    #[test]
    fn an_upper_bound_costs_nothing_inside_and_counts_beyond() {
        let text = ONE.replace("source =", "bound = \"upper\"\nsource =");
        let s = Summary::from_text("s.toml", &text, Path::new("/nonexistent")).unwrap();
        let o = &s.observations[0];
        assert_eq!(o.bound, Bound::Upper);
        assert_eq!(o.z(0.30, 0.02), 0.0);
        assert!((o.z(0.48, 0.02) - 2.0).abs() < 1e-9);
        let bad = ONE.replace("source =", "bound = \"above\"\nsource =");
        let err = Summary::from_text("s.toml", &bad, Path::new("/nonexistent"))
            .unwrap_err()
            .to_string();
        assert!(err.contains("unknown bound `above`"), "{err}");
    }

    /// Every physics candidate moves at least one summary behaviour, and no sensor-only one
    /// claims to (else the summary fit would credit an effect with nothing it can change).
    #[test]
    fn signature_kinds_follow_the_physics_flag() {
        for e in effects::candidates() {
            assert_eq!(!signature_kinds(e).is_empty(), e.physics, "{}", e.name);
        }
    }
}

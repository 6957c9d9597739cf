//! The model file `gap` compares against (`--model MODEL.toml`): which vehicle, world and
//! sensor configurations make up the model, plus any effects already added (what `gap` writes
//! into `MODEL.fitted.toml`).
//!
//! ```toml
//! name = "mako"
//! vehicle = "vehicles/mako.toml"      # embedded name, or a path relative to this file
//! world = "worlds/pool.toml"          # optional: default = the experiment's world
//! sensors = "sensors/mako-2008.toml"  # optional: default = the experiment's sensors
//!
//! [[effect]]
//! name = "water_current"
//! parameters = { north_mps = 0.02, east_mps = -0.01 }
//! ci95 = { north_mps = [0.018, 0.022], east_mps = [-0.012, -0.008] }   # informational
//! ```

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use serde::Deserialize;

use crate::config::{BesideOrEmbedded, ConfigError, ConfigSource, Directory, Document};
use crate::gap::GapError;
use crate::gap::effects::{self, Configs, Effect};
use crate::gap::format::ExperimentInfo;
use crate::physics::{VehicleConfig, WorldConfig};
use crate::sensors::SensorsConfig;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawModel {
    name: String,
    vehicle: String,
    world: Option<String>,
    sensors: Option<String>,
    #[serde(default, rename = "calibration")]
    calibration: Vec<RawEffect>,
    #[serde(default, rename = "effect")]
    effects: Vec<RawEffect>,
    #[serde(default, rename = "spread")]
    spread: Vec<RawEffect>,
    #[serde(default)]
    spread_dof: Option<u32>,
    #[serde(default)]
    discrepancy: BTreeMap<String, f64>,
    #[serde(default)]
    discrepancy_bound: BTreeMap<String, f64>,
    #[serde(default)]
    discrepancy_scatter: BTreeMap<String, RunScatter>,
    #[serde(default)]
    prior: BTreeMap<String, BTreeMap<String, f64>>,
}

/// Family-wise level of the run bounds: a run with nothing new exceeds one of the bounds of
/// the channels judged together with at most this probability.
pub const RUN_BOUND_LEVEL: f64 = 0.05;

/// How one channel's chi-square per sample scatters over the calibration's runs with nothing
/// new: the mean and standard deviation of the runs' logarithms (a log-normal sample) and how
/// many runs there were. A model's error is not the same on every run: the same programme
/// from another start, or with other noise, meets it otherwise, and runs of the calibrated
/// Mako with nothing new scatter by a factor of two and more in one channel.
#[derive(Debug, Clone, Copy, PartialEq, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RunScatter {
    pub log_mean: f64,
    pub log_sd: f64,
    pub runs: u32,
}

impl RunScatter {
    /// The scatter of `values` (chi-squares per sample, one per run); `None` with fewer than
    /// two, or with one not a positive number.
    pub fn of(values: &[f64]) -> Option<Self> {
        use statrs::statistics::Statistics;
        if values.len() < 2 || !values.iter().all(|c| c.is_finite() && *c > 0.0) {
            return None;
        }
        let logs: Vec<f64> = values.iter().map(|x| x.ln()).collect();
        Some(Self {
            log_mean: logs.iter().mean(),
            log_sd: logs.iter().std_dev(),
            runs: u32::try_from(values.len()).ok()?,
        })
    }

    /// The chi-square per sample one more run with nothing new stays under in this channel
    /// when `channels` channels are judged together: the upper prediction bound of a
    /// log-normal sample, `exp(m + t * s * sqrt(1 + 1/k))` with `m` and `s` the mean and
    /// standard deviation of the `k` runs' log chi-squares and `t` Student's t quantile with
    /// `k - 1` degrees of freedom at `1 - RUN_BOUND_LEVEL / channels` (Bonferroni: the run
    /// disagrees when any of the channels does).
    pub fn bound(&self, channels: usize) -> Option<f64> {
        use statrs::distribution::{ContinuousCDF, StudentsT};
        let k = f64::from(self.runs);
        let q = 1.0 - RUN_BOUND_LEVEL / channels.max(1) as f64;
        let t = StudentsT::new(0.0, 1.0, k - 1.0).ok()?.inverse_cdf(q);
        Some((self.log_mean + t * self.log_sd * (1.0 + 1.0 / k).sqrt()).exp())
    }

    /// The two-sided prediction interval of one more run with nothing new in this channel
    /// when `channels` channels are judged together: `exp(m -+ t * s * sqrt(1 + 1/k))` with
    /// `t` at `1 - RUN_BOUND_LEVEL / (2 channels)`. A run outside it in any channel is unlike
    /// the runs, above or below them.
    pub fn interval(&self, channels: usize) -> Option<[f64; 2]> {
        use statrs::distribution::{ContinuousCDF, StudentsT};
        let k = f64::from(self.runs);
        let q = 1.0 - RUN_BOUND_LEVEL / (2.0 * channels.max(1) as f64);
        let t = StudentsT::new(0.0, 1.0, k - 1.0).ok()?.inverse_cdf(q);
        let half = t * self.log_sd * (1.0 + 1.0 / k).sqrt();
        Some([(self.log_mean - half).exp(), (self.log_mean + half).exp()])
    }
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct RawEffect {
    name: String,
    parameters: BTreeMap<String, f64>,
    #[serde(default)]
    ci95: BTreeMap<String, [f64; 2]>,
    #[serde(default)]
    delta_bic: Option<f64>,
}

/// An effect enabled in a model, with its values.
#[derive(Debug, Clone, PartialEq)]
pub struct EnabledEffect {
    pub effect: &'static Effect,
    pub values: Vec<f64>,
    pub ci95: Vec<[f64; 2]>,
    pub delta_bic: Option<f64>,
}

/// A model file, resolved.
#[derive(Debug, Clone)]
pub struct GapModel {
    pub name: String,
    pub vehicle_ref: String,
    pub world_ref: Option<String>,
    pub sensors_ref: Option<String>,
    /// Where relative references resolve (the model file's directory).
    pub base: PathBuf,
    /// Parameters fitted by `gap calibrate` on baseline runs: part of the model, applied
    /// before the effects, and still free to be found again as a change by `gap`.
    pub calibration: Vec<EnabledEffect>,
    pub effects: Vec<EnabledEffect>,
    /// How far each effect's apparent value strays between baseline runs of the calibrated
    /// model with nothing changed (1 sigma per parameter, written by `gap calibrate` from
    /// two or more runs): model error that looks like the effect. `gap` adds it to the fit's
    /// own uncertainty before deciding an effect is there.
    pub spread: Vec<EnabledEffect>,
    /// The degrees of freedom of the spread's estimate: the number of null runs it was
    /// measured on, one fewer when those were the runs the calibration was fitted to. `None`
    /// (a hand-written spread) takes the spread as known.
    pub spread_dof: Option<u32>,
    /// The calibrated model's known disagreement per channel: its chi-square per independent
    /// sample on baseline runs (written by `gap calibrate`; 1 = as the noise floor expects).
    /// `gap` measures what is new against it: a channel's gap is its chi-square over this.
    pub discrepancy: BTreeMap<String, f64>,
    /// Per channel, the chi-square per sample one more run with nothing new stays under (the
    /// upper 95 % prediction bound from how the calibration's runs with nothing new scatter
    /// from run to run, written by `gap calibrate` from two or more such runs). A run's
    /// channel disagrees only above it: the model's error is not the same on every run.
    pub discrepancy_bound: BTreeMap<String, f64>,
    /// Per channel, how the calibration's runs with nothing new scatter (written by `gap
    /// calibrate` beside the bounds): a question about fewer channels than the report judges
    /// together takes its bound from here ([`Self::run_bound_among`]).
    pub discrepancy_scatter: BTreeMap<String, RunScatter>,
    /// How sure the model as given is of a calibrated parameter: per effect and parameter,
    /// one standard deviation in the parameter's unit (`[prior]`). `gap calibrate` holds the
    /// parameter to it; one not listed gets the weak prior
    /// ([`crate::gap::calibrate::PRIOR_WIDTH`] typical sizes).
    pub prior: BTreeMap<String, BTreeMap<String, f64>>,
}

/// Reads `name` relative to `base` if such a file exists, else from the embedded configs
/// ([`BesideOrEmbedded`], the rule of every command).
pub fn read_ref(base: &Path, name: &str) -> Result<(String, String), ConfigError> {
    let source = BesideOrEmbedded::new(Directory::new(base));
    Ok((source.describe(name), source.read(name)?.into_owned()))
}

impl GapModel {
    pub fn load(path: &Path) -> Result<Self, GapError> {
        let text = std::fs::read_to_string(path).map_err(|source| GapError::Io {
            path: path.to_path_buf(),
            source,
        })?;
        let base = path.parent().map(Path::to_path_buf).unwrap_or_default();
        Self::from_text(&path.display().to_string(), &text, base)
    }

    pub fn from_text(origin: &str, text: &str, base: PathBuf) -> Result<Self, GapError> {
        let doc = Document::new(origin, text);
        let raw: RawModel = doc.parse()?;
        let calibration = enabled(&doc, "calibration", &raw.calibration)?;
        let effects = enabled(&doc, "effect", &raw.effects)?;
        let spread = enabled(&doc, "spread", &raw.spread)?;
        if raw.spread_dof == Some(0) {
            return Err(doc
                .invalid(
                    "spread_dof",
                    "expected the degrees of freedom of the [[spread]] estimate, 1 or more \
                     (the number of spread runs, or the baseline runs less one); got 0"
                        .to_string(),
                )
                .into());
        }
        let levels = raw.discrepancy.iter().map(|e| ("discrepancy", e));
        let bounds = raw
            .discrepancy_bound
            .iter()
            .map(|e| ("discrepancy_bound", e));
        let scatter_names = raw
            .discrepancy_scatter
            .keys()
            .map(|c| ("discrepancy_scatter", c));
        for (table, channel) in levels
            .clone()
            .chain(bounds.clone())
            .map(|(t, (c, _))| (t, c))
            .chain(scatter_names)
        {
            if !crate::gap::resim::MODELLED.contains(&channel.as_str())
                && crate::gap::sonar::index(channel).is_none()
            {
                return Err(doc
                    .invalid(
                        &format!("{table}.{channel}"),
                        format!(
                            "`{channel}` is not a re-simulated channel; they are {} and sonar1_m..sonar4_m",
                            crate::gap::resim::MODELLED.join(", ")
                        ),
                    )
                    .into());
            }
        }
        for (channel, sc) in &raw.discrepancy_scatter {
            if !sc.log_mean.is_finite() || !sc.log_sd.is_finite() || sc.log_sd < 0.0 || sc.runs < 2
            {
                return Err(doc
                    .invalid(
                        &format!("discrepancy_scatter.{channel}"),
                        format!(
                            "expected a finite log_mean, a finite log_sd >= 0 and runs >= 2, got \
                             log_mean = {}, log_sd = {}, runs = {}",
                            sc.log_mean, sc.log_sd, sc.runs
                        ),
                    )
                    .into());
            }
        }
        for (table, (channel, v)) in levels.chain(bounds) {
            if !v.is_finite() || *v <= 0.0 {
                return Err(doc
                    .invalid(
                        &format!("{table}.{channel}"),
                        format!("expected a chi-square per sample > 0, got {v}"),
                    )
                    .into());
            }
        }
        check_prior(&doc, &raw.prior)?;
        Ok(Self {
            name: raw.name,
            vehicle_ref: raw.vehicle,
            world_ref: raw.world,
            sensors_ref: raw.sensors,
            base,
            calibration,
            effects,
            spread,
            spread_dof: raw.spread_dof,
            discrepancy: raw.discrepancy,
            discrepancy_bound: raw.discrepancy_bound,
            discrepancy_scatter: raw.discrepancy_scatter,
            prior: raw.prior,
        })
    }

    /// The standard deviation `[prior]` gives `parameter` of `effect`, if any.
    pub fn prior_sd(&self, effect: &str, parameter: &str) -> Option<f64> {
        self.prior.get(effect)?.get(parameter).copied()
    }

    /// What a calibrated model cannot say of how runs with nothing new stray, for `gap` to
    /// print beside its verdict: a model with a known disagreement (`[discrepancy]`) but no
    /// `[[spread]]` takes each candidate's interval from its own fit alone, and one without
    /// `[discrepancy_bound]` judges a channel against its known level alone. Calibrated on one
    /// run, a model has neither, and what `gap` names may then be the analysed run's own model
    /// error. `None` for a model as given (no known disagreement) or one with both.
    pub fn caution(&self) -> Option<String> {
        if self.discrepancy.is_empty() {
            return None;
        }
        let missing: Vec<&str> = [
            (self.spread.is_empty(), "no between-run spread ([[spread]])"),
            (
                self.discrepancy_bound.is_empty(),
                "no bound a run with nothing new stays under ([discrepancy_bound])",
            ),
        ]
        .into_iter()
        .filter_map(|(gone, what)| gone.then_some(what))
        .collect();
        if missing.is_empty() {
            return None;
        }
        Some(format!(
            "the model holds {}: how far a run with nothing new strays from it is not known, so \
             an effect named here may be this run's own model error; calibrate with two or more \
             --spread-from null runs of the programme you analyse (`gap calibrate`)",
            missing.join(" and ")
        ))
    }

    /// The spread as a fit's interval takes it: each value times `t / z`, the 97.5 %
    /// quantiles of Student's t with [`Self::spread_dof`] degrees of freedom and of the
    /// normal. A scatter measured on a few runs is itself uncertain, and a new run's apparent
    /// value over that estimate follows t, not the normal: with three runs the 95 % interval
    /// is 1.6 times wider than 1.96 estimated sigmas would make it.
    pub fn predictive_spread(&self) -> Vec<EnabledEffect> {
        let factor = self.spread_dof.map_or(1.0, spread_factor);
        self.spread
            .iter()
            .map(|e| EnabledEffect {
                values: e.values.iter().map(|v| v * factor).collect(),
                ..e.clone()
            })
            .collect()
    }

    /// The known chi-square per sample of `channel` (at least 1: the noise floor).
    pub fn known_chi2(&self, channel: &str) -> f64 {
        self.discrepancy
            .get(channel)
            .copied()
            .unwrap_or(1.0)
            .max(1.0)
    }

    /// What `channel`'s disagreement is judged against: its known level and the bound a run
    /// with nothing new stays under.
    pub fn known(&self, channel: &str) -> crate::gap::residuals::Known {
        crate::gap::residuals::Known {
            level: self.known_chi2(channel),
            run_bound: self.discrepancy_bound.get(channel).copied(),
        }
    }

    /// The bound a run with nothing new stays under in `channel` when `channels` channels are
    /// judged together: from the runs' scatter where the calibration wrote it, else the bound
    /// written for all channels together (no narrower for fewer).
    pub fn run_bound_among(&self, channel: &str, channels: usize) -> Option<f64> {
        self.discrepancy_scatter
            .get(channel)
            .and_then(|s| s.bound(channels))
            .or_else(|| self.discrepancy_bound.get(channel).copied())
    }

    /// The base configurations (no effects), with the experiment's world and sensors unless
    /// the model names its own, and the camera marker where the experiment states it.
    pub fn base_configs(
        &self,
        experiment: &ExperimentInfo,
        exp_dir: &Path,
    ) -> Result<Configs, GapError> {
        let (o, t) = read_ref(&self.base, &self.vehicle_ref)?;
        let vehicle = VehicleConfig::from_document(&Document::new(o, &t))?;
        let (o, t) = match &self.world_ref {
            Some(w) => read_ref(&self.base, w)?,
            None => read_ref(exp_dir, &experiment.world)?,
        };
        let world = WorldConfig::from_document(&Document::new(o, &t))?;
        let (o, t) = match &self.sensors_ref {
            Some(s) => read_ref(&self.base, s)?,
            None => read_ref(exp_dir, &experiment.sensors)?,
        };
        let sensors = SensorsConfig::from_text(o, &t)?;
        let mut configs = Configs::new(vehicle, world, sensors);
        configs.camera_marker_body_m = experiment.camera_marker_body_m;
        Ok(configs)
    }

    /// The configurations with every enabled effect applied.
    pub fn configs(
        &self,
        experiment: &ExperimentInfo,
        exp_dir: &Path,
    ) -> Result<Configs, GapError> {
        let mut c = self.base_configs(experiment, exp_dir)?;
        for e in self.calibration.iter().chain(&self.effects) {
            effects::apply(e.effect, &e.values, &mut c);
        }
        Ok(c)
    }

    /// The model file text, with a provenance comment on top. References are written so they
    /// resolve from `out_dir`.
    pub fn to_toml(&self, provenance: &str, out_dir: &Path) -> String {
        let rel = |r: &str| -> String {
            let candidate = self.base.join(r);
            if candidate.is_file() {
                std::path::absolute(&candidate)
                    .ok()
                    .and_then(|abs| {
                        let out = std::path::absolute(out_dir).ok()?;
                        relative(&abs, &out)
                    })
                    .unwrap_or_else(|| candidate.display().to_string())
            } else {
                r.to_string()
            }
        };
        let mut s = String::new();
        for line in provenance.lines() {
            let _ = writeln!(s, "# {line}");
        }
        let _ = writeln!(s, "name = {:?}", self.name);
        let _ = writeln!(s, "vehicle = {:?}", rel(&self.vehicle_ref));
        if let Some(w) = &self.world_ref {
            let _ = writeln!(s, "world = {:?}", rel(w));
        }
        if let Some(x) = &self.sensors_ref {
            let _ = writeln!(s, "sensors = {:?}", rel(x));
        }
        if let (Some(dof), false) = (self.spread_dof, self.spread.is_empty()) {
            let _ = writeln!(
                s,
                "spread_dof = {dof}   # degrees of freedom of the [[spread]] estimate"
            );
        }
        if !self.prior.is_empty() {
            let _ = writeln!(
                s,
                "\n[prior]   # one standard deviation per parameter: how sure the model as given is"
            );
            for (effect, parameters) in &self.prior {
                let sd: Vec<String> = parameters
                    .iter()
                    .map(|(p, v)| format!("{p} = {}", exact(*v)))
                    .collect();
                let _ = writeln!(s, "{effect} = {{ {} }}", sd.join(", "));
            }
        }
        for (table, e) in self
            .calibration
            .iter()
            .map(|e| ("calibration", e))
            .chain(self.effects.iter().map(|e| ("effect", e)))
            .chain(self.spread.iter().map(|e| ("spread", e)))
        {
            let _ = writeln!(s, "\n[[{table}]]\nname = {:?}", e.effect.name);
            let params: Vec<String> = e
                .effect
                .parameters
                .iter()
                .zip(&e.values)
                .map(|(p, v)| format!("{p} = {}", exact(*v)))
                .collect();
            let _ = writeln!(s, "parameters = {{ {} }}", params.join(", "));
            if table == "spread" {
                continue;
            }
            let ci: Vec<String> = e
                .effect
                .parameters
                .iter()
                .zip(&e.ci95)
                .map(|(p, c)| format!("{p} = [{:.6}, {:.6}]", c[0], c[1]))
                .collect();
            let _ = writeln!(s, "ci95 = {{ {} }}   # 95 % intervals", ci.join(", "));
            if let Some(d) = e.delta_bic {
                let _ = writeln!(s, "delta_bic = {d:.1}");
            }
        }
        if !self.discrepancy.is_empty() {
            let _ = writeln!(
                s,
                "\n[discrepancy]   # chi-square per sample by channel on runs with nothing new"
            );
            for (channel, v) in &self.discrepancy {
                let _ = writeln!(s, "{channel} = {}", exact(*v));
            }
        }
        if !self.discrepancy_bound.is_empty() {
            let _ = writeln!(
                s,
                "\n[discrepancy_bound]   # chi-square per sample one more such run stays under \
                 (95 %, all channels together)"
            );
            for (channel, v) in &self.discrepancy_bound {
                let _ = writeln!(s, "{channel} = {}", exact(*v));
            }
        }
        if !self.discrepancy_scatter.is_empty() {
            let _ = writeln!(
                s,
                "\n[discrepancy_scatter]   # log chi-square per sample over those runs: mean, \
                 standard deviation, runs"
            );
            for (channel, v) in &self.discrepancy_scatter {
                let _ = writeln!(
                    s,
                    "{channel} = {{ log_mean = {}, log_sd = {}, runs = {} }}",
                    exact(v.log_mean),
                    exact(v.log_sd),
                    v.runs
                );
            }
        }
        s
    }
}

/// `t(0.975, dof) / z(0.975)`: how much wider a 95 % interval is when its sigma is
/// estimated with `dof` degrees of freedom.
pub fn spread_factor(dof: u32) -> f64 {
    use statrs::distribution::{ContinuousCDF, Normal, StudentsT};
    let (Ok(t), Ok(z)) = (
        StudentsT::new(0.0, 1.0, f64::from(dof.max(1))),
        Normal::new(0.0, 1.0),
    ) else {
        return 1.0;
    };
    t.inverse_cdf(0.975) / z.inverse_cdf(0.975)
}

/// Resolves the `[[effect]]` or `[[calibration]]` entries of a model file.
/// Every `[prior]` entry names an effect `gap calibrate` fits and one of its parameters, with
/// a finite standard deviation above zero.
fn check_prior(
    doc: &Document,
    prior: &BTreeMap<String, BTreeMap<String, f64>>,
) -> Result<(), GapError> {
    for (name, parameters) in prior {
        let effect = effects::by_name(name)
            .filter(|e| e.calibration.is_jointly_fitted())
            .ok_or_else(|| {
                doc.invalid(
                    &format!("prior.{name}"),
                    format!(
                        "`{name}` is not an effect `gap calibrate` fits jointly; they are {}",
                        effects::LIBRARY
                            .iter()
                            .filter(|e| e.calibration.is_jointly_fitted())
                            .map(|e| e.name)
                            .collect::<Vec<_>>()
                            .join(", ")
                    ),
                )
            })?;
        for (p, sd) in parameters {
            if !effect.parameters.contains(&p.as_str()) {
                return Err(doc
                    .invalid(
                        &format!("prior.{name}.{p}"),
                        format!(
                            "`{name}` has no parameter `{p}`; it has {}",
                            effect.parameters.join(", ")
                        ),
                    )
                    .into());
            }
            if !sd.is_finite() || *sd <= 0.0 {
                return Err(doc
                    .invalid(
                        &format!("prior.{name}.{p}"),
                        format!(
                            "expected a standard deviation > 0 in the parameter's unit, got {sd}"
                        ),
                    )
                    .into());
            }
        }
    }
    Ok(())
}

fn enabled(doc: &Document, table: &str, raw: &[RawEffect]) -> Result<Vec<EnabledEffect>, GapError> {
    let mut out = Vec::new();
    for (i, e) in raw.iter().enumerate() {
        let key = format!("{table}.{i}");
        let effect = effects::by_name(&e.name).ok_or_else(|| {
            doc.invalid(
                &format!("{key}.name"),
                format!(
                    "unknown effect `{}`; known: {}",
                    e.name,
                    effects::LIBRARY
                        .iter()
                        .map(|e| e.name)
                        .collect::<Vec<_>>()
                        .join(", ")
                ),
            )
        })?;
        if let Some(k) = e
            .parameters
            .keys()
            .find(|k| !effect.parameters.contains(&k.as_str()))
        {
            return Err(doc
                .invalid(
                    &format!("{key}.parameters"),
                    format!(
                        "`{}` has no parameter `{k}`; it has {}",
                        effect.name,
                        effect.parameters.join(", ")
                    ),
                )
                .into());
        }
        let values = effect
            .parameters
            .iter()
            .map(|p| e.parameters.get(*p).copied().unwrap_or(0.0))
            .collect::<Vec<_>>();
        if values.iter().any(|v| !v.is_finite()) {
            return Err(doc
                .invalid(&format!("{key}.parameters"), "values must be finite")
                .into());
        }
        let ci95 = effect
            .parameters
            .iter()
            .zip(&values)
            .map(|(p, v)| e.ci95.get(*p).copied().unwrap_or([*v, *v]))
            .collect();
        out.push(EnabledEffect {
            effect,
            values,
            ci95,
            delta_bic: e.delta_bic,
        });
    }
    Ok(out)
}

/// `v` as a TOML float that reads back as the same `f64` (the `toml` crate's own writer):
/// what the file holds is what was calibrated and validated, so an analysis with the written
/// model equals one with the model in memory.
fn exact(v: f64) -> String {
    toml::Value::Float(v).to_string()
}

/// `target` relative to `from` (both absolute), if they share a root.
fn relative(target: &Path, from: &Path) -> Option<String> {
    let t: Vec<_> = target.components().collect();
    let f: Vec<_> = from.components().collect();
    let common = t.iter().zip(&f).take_while(|(a, b)| a == b).count();
    if common == 0 {
        return None;
    }
    let mut p = PathBuf::new();
    for _ in common..f.len() {
        p.push("..");
    }
    for c in &t[common..] {
        p.push(c);
    }
    Some(p.to_string_lossy().replace('\\', "/"))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn model(extra: &str) -> Result<GapModel, GapError> {
        let text = format!("name = \"m\"\nvehicle = \"vehicles/mako.toml\"\n{extra}");
        GapModel::from_text("test.toml", &text, PathBuf::new())
    }

    /// The calibrated model's known disagreement is read, floored at the noise floor (1),
    /// written back unchanged, and a channel `gap` cannot re-simulate or a level that is not
    /// a positive number is refused with the key named.
    #[test]
    fn the_known_disagreement_round_trips_and_rejects_bad_entries() {
        let m = model("[discrepancy]\nx_m = 2.5\ncompass_deg = 0.8\n").expect("loads");
        assert_eq!(m.known_chi2("x_m"), 2.5);
        assert_eq!(m.known_chi2("compass_deg"), 1.0);
        assert_eq!(m.known_chi2("depth_adc"), 1.0);
        let again = GapModel::from_text(
            "again.toml",
            &m.to_toml("test", Path::new(".")),
            PathBuf::new(),
        )
        .expect("written model loads");
        assert_eq!(again.discrepancy, m.discrepancy);

        let e = model("[discrepancy]\nspeed = 2.0\n").expect_err("unknown channel");
        assert!(
            e.to_string().contains("discrepancy.speed") && e.to_string().contains("x_m"),
            "{e}"
        );
        let e = model("[discrepancy]\ny_m = -1.0\n").expect_err("negative level");
        assert!(
            e.to_string().contains("discrepancy.y_m") && e.to_string().contains("> 0"),
            "{e}"
        );
        assert!(model("[discrepancy]\ny_m = nan\n").is_err());
    }

    /// A prior is read per effect and parameter, written back unchanged (so a calibrated
    /// model calibrates again under it), and refused, with the key named, for an effect
    /// `gap calibrate` does not fit, a parameter the effect lacks or a width that is not a
    /// positive number.
    #[test]
    fn the_prior_round_trips_and_rejects_bad_entries() {
        let m = model("[prior]\ndepth_gain = { scale_factor = 0.05 }\n").expect("loads");
        assert_eq!(m.prior_sd("depth_gain", "scale_factor"), Some(0.05));
        assert_eq!(m.prior_sd("depth_offset", "offset_m"), None);
        let again = GapModel::from_text(
            "again.toml",
            &m.to_toml("test", Path::new(".")),
            PathBuf::new(),
        )
        .expect("written model loads");
        assert_eq!(again.prior, m.prior);

        for (text, key, expected) in [
            (
                "depth_pwm_emi = { rms_v = 0.1 }",
                "prior.depth_pwm_emi",
                "fits jointly",
            ),
            (
                "sonar_gain = { x = 0.1 }",
                "prior.sonar_gain",
                "fits jointly",
            ),
            (
                "depth_gain = { offset_m = 0.1 }",
                "prior.depth_gain.offset_m",
                "scale_factor",
            ),
            (
                "depth_gain = { scale_factor = 0.0 }",
                "prior.depth_gain.scale_factor",
                "> 0",
            ),
            (
                "depth_gain = { scale_factor = inf }",
                "prior.depth_gain.scale_factor",
                "> 0",
            ),
        ] {
            let e = model(&format!("[prior]\n{text}\n")).expect_err(text);
            assert!(
                e.to_string().contains(key) && e.to_string().contains(expected),
                "{text}: {e}"
            );
        }
    }

    /// The bound a run with nothing new stays under is read per channel, written back
    /// unchanged and refused, with the key named, for a channel `gap` cannot re-simulate or a
    /// value that is not a positive number; a channel without one has none.
    #[test]
    fn the_run_bound_round_trips_and_rejects_bad_entries() {
        let m =
            model("[discrepancy]\nx_m = 2.5\n[discrepancy_bound]\nx_m = 6.25\n").expect("loads");
        assert_eq!(m.known("x_m").run_bound, Some(6.25));
        assert_eq!(m.known("x_m").level, 2.5);
        assert_eq!(m.known("y_m").run_bound, None);
        let again = GapModel::from_text(
            "again.toml",
            &m.to_toml("test", Path::new(".")),
            PathBuf::new(),
        )
        .expect("written model loads");
        assert_eq!(again.discrepancy_bound, m.discrepancy_bound);
        let e = model("[discrepancy_bound]\nspeed = 2.0\n").expect_err("unknown channel");
        assert!(e.to_string().contains("discrepancy_bound.speed"), "{e}");
        let e = model("[discrepancy_bound]\ny_m = 0.0\n").expect_err("zero bound");
        assert!(
            e.to_string().contains("discrepancy_bound.y_m") && e.to_string().contains("> 0"),
            "{e}"
        );
    }

    /// How the runs with nothing new scatter is read per channel and written back bit for
    /// bit; its bound is the log-normal prediction bound at 1 - 0.05 / channels judged
    /// together (three runs: t(0.975; 2) = 4.303 for two channels, from tables), narrower
    /// for fewer channels; without a scatter a channel's bound is the one written for all
    /// channels together; a scatter of one run or a negative spread is refused, with the key
    /// named.
    #[test]
    fn the_run_scatter_round_trips_and_bounds_the_channels_judged_together() {
        let m = model(
            "[discrepancy_bound]\nx_m = 9.0\ny_m = 7.5\n\
             [discrepancy_scatter]\nx_m = { log_mean = 0.5, log_sd = 0.2, runs = 3 }\n",
        )
        .expect("loads");
        let want = (0.5 + 4.303 * 0.2 * (4.0_f64 / 3.0).sqrt()).exp();
        let two = m.run_bound_among("x_m", 2).unwrap();
        assert!((two - want).abs() < 1e-3 * want, "{two} against {want}");
        assert!(m.run_bound_among("x_m", 1).unwrap() < two);
        assert!(m.run_bound_among("x_m", 8).unwrap() > two);
        assert_eq!(m.run_bound_among("y_m", 1), Some(7.5));
        assert_eq!(m.run_bound_among("depth_adc", 1), None);
        let again = GapModel::from_text(
            "again.toml",
            &m.to_toml("test", Path::new(".")),
            PathBuf::new(),
        )
        .expect("written model loads");
        assert_eq!(again.discrepancy_scatter, m.discrepancy_scatter);

        let e = model("[discrepancy_scatter]\nx_m = { log_mean = 0.5, log_sd = 0.2, runs = 1 }\n")
            .expect_err("one run");
        assert!(
            e.to_string().contains("discrepancy_scatter.x_m")
                && e.to_string().contains("runs >= 2"),
            "{e}"
        );
        let e = model("[discrepancy_scatter]\nx_m = { log_mean = 0.5, log_sd = -0.2, runs = 3 }\n")
            .expect_err("negative spread");
        assert!(e.to_string().contains("discrepancy_scatter.x_m"), "{e}");
        let e =
            model("[discrepancy_scatter]\nspeed = { log_mean = 0.5, log_sd = 0.2, runs = 3 }\n")
                .expect_err("unknown channel");
        assert!(e.to_string().contains("discrepancy_scatter.speed"), "{e}");
    }

    /// Every number the analysis reads back from a written model (calibrated and effect
    /// values, the spread, the known disagreement) is written so it reads back bit for bit:
    /// re-analysing with a kept `calibrated.toml` is the analysis the benchmark made.
    #[test]
    fn written_values_read_back_bit_for_bit() {
        let m = model(
            "[[calibration]]\nname = \"thrust_gain\"\nparameters = { gain_scale = -0.055612345678901234 }\n\
             ci95 = { gain_scale = [-0.06, -0.05] }\n\
             [[effect]]\nname = \"water_current\"\nparameters = { north_mps = 1.0e-7, east_mps = -0.03333333333333333 }\n\
             ci95 = { north_mps = [-0.01, 0.01], east_mps = [-0.04, -0.02] }\n\
             [[spread]]\nname = \"yaw_damping\"\nparameters = { scale = 0.06482712345678912 }\n\
             [discrepancy]\nx_m = 2.7123456789012345\n",
        )
        .expect("loads");
        let text = m.to_toml("test", Path::new("."));
        let again = GapModel::from_text("again.toml", &text, PathBuf::new()).expect(&text);
        let values = |g: &GapModel| -> Vec<u64> {
            g.calibration
                .iter()
                .chain(&g.effects)
                .chain(&g.spread)
                .flat_map(|e| e.values.iter().map(|v| v.to_bits()))
                .collect()
        };
        assert_eq!(values(&again), values(&m), "{text}");
        assert_eq!(values(&m).len(), 4);
        assert_eq!(
            again.known_chi2("x_m").to_bits(),
            m.known_chi2("x_m").to_bits(),
            "{text}"
        );
    }

    /// A spread measured on few runs widens a fit's interval by Student's t: with the
    /// degrees of freedom written, each value is scaled by t(0.975, dof) / 1.96 (3.182 / 1.96
    /// for three runs), the written values stay as measured, and `spread_dof` reads back; a
    /// spread without it is taken as known.
    #[test]
    fn the_spread_widens_by_student_t_for_its_degrees_of_freedom() {
        let spread = "[[spread]]\nname = \"yaw_damping\"\nparameters = { scale = 0.1 }\n";
        let known = model(spread).expect("loads");
        assert_eq!(known.spread_dof, None);
        assert_eq!(known.predictive_spread()[0].values, vec![0.1]);

        let m = model(&format!("spread_dof = 3\n{spread}")).expect("loads");
        let widened = m.predictive_spread()[0].values[0];
        assert!(
            (widened / 0.1 - 3.182_446 / 1.959_964).abs() < 1e-5,
            "{widened}"
        );
        assert_eq!(m.spread[0].values, vec![0.1]);
        let again = GapModel::from_text(
            "again.toml",
            &m.to_toml("t", Path::new(".")),
            PathBuf::new(),
        )
        .expect("written model loads");
        assert_eq!(again.spread_dof, Some(3));
        let e = model(&format!("spread_dof = 0\n{spread}")).expect_err("no degrees of freedom");
        assert!(e.to_string().contains("spread_dof"), "{e}");
        // Many runs: the normal's interval.
        assert!((spread_factor(10_000) - 1.0).abs() < 1e-3);
        assert!(spread_factor(1) > 6.0);
    }

    /// A model calibrated on one run (a known disagreement, no spread, no run bound) carries a
    /// caution naming both and the way to measure them; a model as given carries none, nor
    /// does one with both.
    #[test]
    fn a_model_without_spread_or_run_bound_carries_a_caution() {
        let one_run = model("[discrepancy]\nx_m = 2.0\n").expect("loads");
        let why = one_run.caution().expect("a caution");
        assert!(
            why.contains("[[spread]]") && why.contains("[discrepancy_bound]"),
            "{why}"
        );
        assert!(why.contains("--spread-from"), "{why}");
        assert_eq!(model("").expect("loads").caution(), None);
        let spread = "[[spread]]\nname = \"yaw_damping\"\nparameters = { scale = 0.1 }\n";
        let no_bound = model(&format!(
            "spread_dof = 3\n[discrepancy]\nx_m = 2.0\n{spread}"
        ))
        .expect("loads");
        let why = no_bound.caution().expect("no run bound");
        assert!(
            !why.contains("[[spread]]") && why.contains("[discrepancy_bound]"),
            "{why}"
        );
        let both = model(&format!(
            "spread_dof = 3\n[discrepancy]\nx_m = 2.0\n[discrepancy_bound]\nx_m = 3.0\n{spread}"
        ))
        .expect("loads");
        assert_eq!(both.caution(), None);
    }
}

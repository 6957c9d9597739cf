//! The benchmark on data from the independent vehicle model
//! (`pty-tests/independent/mako_independent.py`): a different model form, closed-loop
//! programs on measured sensors, its own sensors and noise. The truth stays here, used only
//! to score.
//!
//! For a seed S: four null runs (`--program mixed --hidden none`, seeds drawn from S); the
//! embedded model is calibrated on the first three ([`crate::gap::calibrate::calibrate`], with
//! the between-run spread) and its gap before and after is reported on the fourth. Then, per
//! effect of the independent model, N runs with the effect hidden, each analysed with the
//! calibrated model and the default options (re-anchored re-simulation), and N null runs.
//!
//! **Sizes.** A case's physical size is drawn uniformly between 1x and 3x the model's
//! default size (its `--list`), with a random sign where the effect allows one (not for a
//! delay or an amplitude; a 2-vector keeps its direction). A scale (`yaw_damping`, default
//! 1.5) grows its deviation from 1: `1 + f (d - 1)`, or its reciprocal for the other sign,
//! so it stays positive.
//!
//! **Size in sigma** (post hoc, for the >= 3 sigma split): |truth| in the library effect's
//! parameters over the standard error (95 % half-width / 1.96) of the candidate of the right
//! name in round 1, accepted or not; for two parameters the norm of the per-parameter ratios.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Instant;

use rand::RngExt;

use crate::config::{ConfigSource, Embedded};
use crate::gap::bench::{BenchOptions, CalibrationGap, CaseResult, MODEL, Outcome, Shard};
use crate::gap::calibrate::{self, Run};
use crate::gap::format::Measurement;
use crate::gap::model::GapModel;
use crate::gap::{GapError, Options};

/// Baseline runs the model is calibrated on (a further null run validates it).
pub const BASELINE_RUNS: usize = 3;
/// Length of every run (s).
pub const DURATION_S: f64 = 180.0;
/// The program every run drives.
pub const PROGRAM: &str = "mixed";
/// Case sizes are drawn uniformly from this range, in multiples of the default size.
pub const SIZE_FACTOR: (f64, f64) = (1.0, 3.0);

/// An effect the independent model can hide, and the library effect that is its right
/// answer.
#[derive(Debug)]
pub struct Hidden {
    /// The independent model's name (`--hidden`).
    pub name: &'static str,
    /// The library effect (`None`: nothing in the library; the right answer is no name).
    pub library: Option<&'static str>,
    /// Whether the size may take either sign.
    pub signed: bool,
    /// A multiplicative scale (no effect at 1; the library parameters are `size - 1`).
    pub scale: bool,
}

const fn hidden(name: &'static str, library: Option<&'static str>, signed: bool) -> Hidden {
    Hidden {
        name,
        library,
        signed,
        scale: false,
    }
}

/// The independent model's effects the benchmark runs, in the default order.
pub const HIDDEN: [Hidden; 13] = [
    hidden("water_current", Some("water_current"), false),
    hidden("compass_hard_iron", Some("compass_hard_iron"), false),
    hidden("compass_latency", Some("sensor_latency"), false),
    hidden("compass_offset", Some("compass_offset"), true),
    hidden("thruster_imbalance", Some("thruster_imbalance"), true),
    hidden("depth_emi", Some("depth_pwm_emi"), false),
    hidden("depth_offset", Some("depth_offset"), true),
    hidden("depth_gain", Some("depth_gain"), true),
    hidden("velocity_sensor_scale", Some("velocity_sensor_scale"), true),
    hidden("thrust_gain", Some("thrust_gain"), true),
    hidden("thruster_lag", Some("thruster_lag"), false),
    Hidden {
        name: "yaw_damping",
        library: Some("yaw_damping"),
        signed: true,
        scale: true,
    },
    hidden("sway_yaw_coupling", Some("sway_yaw_coupling"), true),
];

/// The effect the independent model calls `name`.
pub fn by_name(name: &str) -> Result<&'static Hidden, GapError> {
    HIDDEN.iter().find(|h| h.name == name).ok_or_else(|| {
        GapError::Data(format!(
            "--effects: `{name}` is not an effect of the independent model the benchmark \
             runs; known: {}",
            HIDDEN.iter().map(|h| h.name).collect::<Vec<_>>().join(", ")
        ))
    })
}

/// The program shipped with the crate.
pub fn default_path() -> PathBuf {
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/pty-tests/independent/mako_independent.py"
    ))
}

/// Runs `python3 program args`, returning its standard output; errors name the program.
fn python(program: &Path, args: &[String]) -> Result<String, GapError> {
    let out = Command::new("python3")
        .arg(program)
        .args(args)
        .output()
        .map_err(|e| {
            GapError::Data(format!(
                "cannot run `python3` (needed for the independent model {}): {e}",
                program.display()
            ))
        })?;
    if !out.status.success() {
        return Err(GapError::Data(format!(
            "python3 {} {}: {}: {}",
            program.display(),
            args.join(" "),
            out.status,
            String::from_utf8_lossy(&out.stderr).trim()
        )));
    }
    Ok(String::from_utf8_lossy(&out.stdout).into_owned())
}

/// The default size of every hidden effect, from the program's `--list`.
pub fn default_sizes(program: &Path) -> Result<Vec<(String, Vec<f64>)>, GapError> {
    let text = python(program, &["--list".to_string()])?;
    let mut out = Vec::new();
    let mut in_effects = false;
    for line in text.lines() {
        if line.starts_with("hidden effects") {
            in_effects = true;
            continue;
        }
        if !in_effects || !line.starts_with(' ') {
            continue;
        }
        let mut words = line.split_whitespace();
        let (Some(name), Some(size)) = (words.next(), words.next()) else {
            continue;
        };
        if size == "-" {
            continue;
        }
        let values: Result<Vec<f64>, _> = size.split(',').map(str::parse::<f64>).collect();
        let values = values.map_err(|_| {
            GapError::Data(format!(
                "{} --list: effect `{name}`: default size `{size}` is not a number list",
                program.display()
            ))
        })?;
        out.push((name.to_string(), values));
    }
    Ok(out)
}

/// A scratch directory removed when dropped.
struct Scratch(PathBuf);

impl Scratch {
    fn new(seed: u64) -> Result<Self, GapError> {
        let path =
            std::env::temp_dir().join(format!("eyebot-gap-bench-{}-{seed}", std::process::id()));
        std::fs::create_dir_all(&path).map_err(|source| GapError::Io {
            path: path.clone(),
            source,
        })?;
        Ok(Self(path))
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

/// Writes one run of the independent model to `out`.
fn generate(
    program: &Path,
    seed: u64,
    hidden: Option<(&str, &[f64])>,
    out: &Path,
) -> Result<(), GapError> {
    let mut args: Vec<String> = [
        "--program",
        PROGRAM,
        "--seed",
        &seed.to_string(),
        "--duration",
        &DURATION_S.to_string(),
        "--out",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    args.push(out.display().to_string());
    match hidden {
        None => args.extend(["--hidden".to_string(), "none".to_string()]),
        Some((name, size)) => {
            let size: Vec<String> = size.iter().map(|v| format!("{v}")).collect();
            args.extend([
                "--hidden".to_string(),
                name.to_string(),
                "--size".to_string(),
                size.join(","),
            ]);
        }
    }
    python(program, &args).map(|_| ())
}

/// One planned case: its draws, fixed whichever shard runs it.
struct Planned {
    index: usize,
    hidden: Option<&'static Hidden>,
    seed: u64,
    /// Physical size in the independent model's unit (empty for a null).
    size: Vec<f64>,
}

/// The physical size of a case: `factor` times the default, with `sign`.
pub fn physical_size(h: &Hidden, default: &[f64], factor: f64, positive: bool) -> Vec<f64> {
    if h.scale {
        let grown = 1.0 + factor * (default[0] - 1.0);
        return vec![if positive { grown } else { 1.0 / grown }];
    }
    let sign = if positive { 1.0 } else { -1.0 };
    default.iter().map(|d| sign * factor * d).collect()
}

/// The size in the library effect's parameters.
pub fn library_truth(h: &Hidden, size: &[f64]) -> Vec<f64> {
    if h.scale {
        // yaw_damping: linear and quadratic scaled together.
        vec![size[0] - 1.0, size[0] - 1.0]
    } else {
        size.to_vec()
    }
}

/// Post-hoc size in sigma of `truth` against 95 % intervals `ci95` (see the module doc).
pub fn post_hoc_sigma(truth: &[f64], ci95: &[[f64; 2]]) -> Option<f64> {
    if truth.len() != ci95.len() || truth.is_empty() {
        return None;
    }
    let mut sum = 0.0;
    for (t, c) in truth.iter().zip(ci95) {
        let se = (c[1] - c[0]) / 2.0 / 1.96;
        if se.is_nan() || se <= 0.0 {
            return None;
        }
        // An infinite interval: the data do not inform the parameter, size 0.
        sum += (t / se).powi(2);
    }
    Some(sum.sqrt())
}

fn io(path: &Path) -> impl FnOnce(std::io::Error) -> GapError + '_ {
    move |source| GapError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Runs the cases of `shard` (calibration is done by every shard: it is deterministic).
pub fn run(
    opts: &BenchOptions,
    shard: Shard,
    progress: &mut dyn FnMut(usize, usize, &str),
) -> Result<Outcome, GapError> {
    let program = opts.independent_path.as_path();
    if !program.is_file() {
        return Err(GapError::Data(format!(
            "the independent model {} does not exist (--independent PATH)",
            program.display()
        )));
    }
    let defaults = default_sizes(program)?;
    let mut rng = crate::sensors::rng::stream(opts.seed, "gap-bench-independent");
    let mut draw_seed = || rng.random_range(1_000..1_000_000_000u64);
    let baseline_seeds: Vec<u64> = (0..=BASELINE_RUNS).map(|_| draw_seed()).collect();
    let mut plan = Vec::new();
    for h in &opts.independent_effects {
        let default = defaults
            .iter()
            .find(|(n, _)| n == h.name)
            .map(|(_, v)| v.clone())
            .ok_or_else(|| {
                GapError::Data(format!(
                    "{} --list does not offer the effect `{}`",
                    program.display(),
                    h.name
                ))
            })?;
        for _ in 0..opts.cases {
            let seed = rng.random_range(1_000..1_000_000_000u64);
            let factor = rng.random_range(SIZE_FACTOR.0..SIZE_FACTOR.1);
            let positive = !h.signed || rng.random::<bool>();
            plan.push(Planned {
                index: plan.len(),
                hidden: Some(*h),
                seed,
                size: physical_size(h, &default, factor, positive),
            });
        }
    }
    for _ in 0..opts.cases {
        let seed = rng.random_range(1_000..1_000_000_000u64);
        plan.push(Planned {
            index: plan.len(),
            hidden: None,
            seed,
            size: Vec::new(),
        });
    }
    let total = shard.count(plan.len());

    let scratch = Scratch::new(opts.seed)?;
    progress(0, total, "calibrating");
    let mut runs = Vec::new();
    for (i, seed) in baseline_seeds.iter().enumerate() {
        let dir = scratch.0.join(format!("baseline-{i}"));
        generate(program, *seed, None, &dir)?;
        runs.push(Run::load(&dir)?);
    }
    let validate = runs.split_off(BASELINE_RUNS);
    let model_text = Embedded.read(MODEL)?;
    let model = GapModel::from_text(&Embedded.describe(MODEL), &model_text, ".".into())?;
    let t0 = Instant::now();
    let cal = calibrate::calibrate(&model, &runs, &validate, &mut |_| {})?;
    let seconds = t0.elapsed().as_secs_f64();
    let calibration = cal.runs.iter().find(|r| !r.fitted).map(|r| CalibrationGap {
        gap_before: r.gap_before,
        gap_after: r.gap_after,
        reduction_pct: r.reduction_pct,
        seconds,
    });
    for r in runs.iter().chain(&validate) {
        std::fs::remove_dir_all(&r.dir).map_err(io(&r.dir))?;
    }

    let mut out = Vec::new();
    for p in plan.into_iter().filter(|p| shard.contains(p.index)) {
        let dir = scratch.0.join(format!("case-{}", p.index));
        generate(
            program,
            p.seed,
            p.hidden.map(|h| (h.name, p.size.as_slice())),
            &dir,
        )?;
        let m = Measurement::load(&dir)?;
        let t0 = Instant::now();
        let a = crate::gap::analyse_with(&cal.model, &m, &dir, Options::default(), &mut |_, _| {})?;
        let seconds = t0.elapsed().as_secs_f64();
        std::fs::remove_dir_all(&dir).map_err(io(&dir))?;

        let first = a.accepted.first();
        let named = first.map(|w| w.name.clone());
        let expected = p.hidden.and_then(|h| h.library);
        let truth = p.hidden.map_or(Vec::new(), |h| library_truth(h, &p.size));
        // The right candidate's interval in round 1, accepted or not.
        let size_sigma = expected.and_then(|name| {
            let c = a.rounds.first()?.iter().find(|c| c.name == name)?;
            let ci: Vec<[f64; 2]> = c.ci95.iter().map(|(_, c)| *c).collect();
            post_hoc_sigma(&truth, &ci)
        });
        let label = p.hidden.map_or("null", |h| h.name);
        out.push(CaseResult {
            index: p.index,
            effect: p.hidden.map(|h| h.name.to_string()),
            expected: expected.map(str::to_string),
            label: label.to_string(),
            seed: p.seed,
            truth,
            size_sigma,
            fitted: first
                .map(|w| w.parameters.iter().map(|(_, v)| *v).collect())
                .unwrap_or_default(),
            ci95: first
                .map(|w| w.ci95.iter().map(|(_, c)| *c).collect())
                .unwrap_or_default(),
            named,
            parameter_error: None,
            ci_covers: None,
            held_out_reduction_pct: first.map(|_| a.heldout_reduction_pct),
            held_out_truth_reduction_pct: None,
            held_out_grew: Some(first.is_some() && a.heldout_gap_after > a.heldout_gap_before),
            seconds,
        });
        progress(out.len(), total, label);
    }
    Ok(Outcome {
        results: out,
        calibration,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scale grows its deviation from 1 and stays positive for either sign; a vector keeps
    /// its direction; the library sees a scale as its deviation on both parameters.
    #[test]
    fn sizes_scale_from_the_default() {
        let yaw = HIDDEN.iter().find(|h| h.name == "yaw_damping").unwrap();
        let up = physical_size(yaw, &[1.5], 3.0, true);
        assert!((up[0] - 2.5).abs() < 1e-12);
        let down = physical_size(yaw, &[1.5], 3.0, false);
        assert!((down[0] - 0.4).abs() < 1e-12);
        assert_eq!(library_truth(yaw, &up), vec![1.5, 1.5]);
        let wc = HIDDEN.iter().find(|h| h.name == "water_current").unwrap();
        assert_eq!(
            physical_size(wc, &[0.02, -0.015], 2.0, true),
            vec![0.04, -0.03]
        );
    }

    /// The post-hoc size is |truth| over the standard error, the norm over two parameters,
    /// and zero for an interval the data do not bound.
    #[test]
    fn post_hoc_sigma_uses_the_interval_half_width() {
        let s = post_hoc_sigma(&[0.3], &[[-1.96, 1.96]]).unwrap();
        assert!((s - 0.3).abs() < 1e-12);
        let s = post_hoc_sigma(&[3.0, 4.0], &[[-1.96, 1.96], [0.0, 3.92]]).unwrap();
        assert!((s - 5.0).abs() < 1e-12);
        assert_eq!(
            post_hoc_sigma(&[1.0], &[[f64::NEG_INFINITY, f64::INFINITY]]),
            Some(0.0)
        );
    }
}

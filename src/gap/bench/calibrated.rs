//! The benchmark loop for data whose truth is not the model that analyses it: calibrate
//! first, then find what is new (the thesis's order). A [`Truth`] writes measurement
//! directories; this module plans the cases, calibrates, analyses and scores. The truth stays
//! here, used only to score.
//!
//! For a seed S: [`BASELINE_RUNS`] null baseline runs and one more null run (seeds drawn from
//! S); the embedded model is calibrated on the first [`BenchOptions::baselines`] of the
//! baselines (every seed is drawn whichever are used, so the cases stay the same) ([`crate::gap::calibrate::calibrate`],
//! with the between-run spread, measured on [`Truth::spread_runs`] null cases when the source
//! has them) and its gap before and after is reported on the further run.
//! Then, per hidden effect, N runs with the effect hidden, each analysed with the calibrated
//! model and the default options (re-anchored re-simulation), and N null runs. The
//! calibration can run on its own ([`calibrate`]) and be handed to every shard ([`run`]).
//!
//! **Sizes.** A case's physical size is drawn uniformly between 1x and 3x the truth's default
//! size, with a random sign where the effect allows one (not for a delay or an amplitude; a
//! 2-vector keeps its direction). A scale (default 1.5 for `yaw_damping` of the independent
//! model) grows its deviation from 1: `1 + f (d - 1)`, or its reciprocal for the other sign,
//! so it stays positive.
//!
//! **Size in sigma** (post hoc, for the >= 3 sigma split): |truth| in the library effect's
//! parameters over the standard error (95 % half-width / 1.96) of the candidate of the right
//! name in round 1, accepted or not; for two parameters the norm of the per-parameter ratios;
//! for a case with two hidden effects the smaller of the two effects' sizes.

use std::path::{Path, PathBuf};
use std::time::Instant;

use rand::RngExt;

use crate::config::{ConfigSource, Embedded};
use crate::gap::bench::{
    BenchOptions, CalibrationGap, CaseResult, MODEL, Outcome, Progress, Shard,
};
use crate::gap::calibrate::{self, Run};
use crate::gap::candidate::Candidate;
use crate::gap::effects::Effect;
use crate::gap::format::Measurement;
use crate::gap::model::GapModel;
use crate::gap::{GapError, Options};

/// Baseline runs the model is calibrated on (a further null run validates it).
pub const BASELINE_RUNS: usize = 3;
/// Case sizes are drawn uniformly from this range, in multiples of the default size.
pub const SIZE_FACTOR: (f64, f64) = (1.0, 3.0);

/// An effect a truth source can hide, and the library effect that is its right answer.
#[derive(Debug)]
pub struct Hidden {
    /// The source's name for it.
    pub name: &'static str,
    /// The library effect (`None`: nothing in the library; the right answer is no name).
    pub library: Option<&'static str>,
    /// Whether the size may take either sign.
    pub signed: bool,
    /// A multiplicative scale (no effect at 1; the library parameters are `size - 1`).
    pub scale: bool,
}

impl Hidden {
    /// The library effect `effect` as a source hides it under `name`: signed unless its
    /// parameter takes one sign only or it is a vector (which keeps its direction).
    pub fn of(effect: &'static Effect, name: &'static str, factor: bool) -> Hidden {
        Hidden {
            name,
            library: Some(effect.name),
            signed: !effect.positive && effect.parameters.len() == 1,
            scale: factor,
        }
    }
}

/// Where a calibrated benchmark's measurements come from.
pub trait Truth {
    /// Every hidden effect's default size, in the source's units, by name.
    fn default_sizes(&self) -> Result<Vec<(String, Vec<f64>)>, GapError>;
    /// Writes null run `index` of the calibration set (`index == BASELINE_RUNS`: the run it
    /// is scored on) as a measurement directory `out`.
    fn baseline(&self, index: usize, seed: u64, out: &Path) -> Result<(), GapError>;
    /// Null runs of the case programme the between-run spread is measured on (none: on the
    /// baseline runs, which then must be runs of that programme).
    fn spread_runs(&self) -> usize {
        0
    }
    /// Writes one case as a measurement directory `out`: the `hidden` effects (none, one or
    /// two) with their physical sizes.
    fn case(&self, seed: u64, hidden: &[(&Hidden, &[f64])], out: &Path) -> Result<(), GapError>;
}

/// A scratch directory removed when dropped, unless it is one the user asked to keep.
pub struct Scratch(pub PathBuf, bool);

impl Scratch {
    pub fn new(label: &str, seed: u64) -> Result<Self, GapError> {
        let path = std::env::temp_dir().join(format!(
            "eyebot-gap-bench-{label}-{}-{seed}",
            std::process::id()
        ));
        std::fs::create_dir_all(&path).map_err(io(&path))?;
        Ok(Self(path, false))
    }

    /// The user's directory `path`: created if missing, and it and what is written into it
    /// stay. A directory that already holds something is refused: a campaign writes runs
    /// under fixed names, so it would overwrite an earlier one's runs and leave their other
    /// files (another source's `truth.json`) beside its own.
    pub fn kept(path: &Path) -> Result<Self, GapError> {
        std::fs::create_dir_all(path).map_err(io(path))?;
        let first = std::fs::read_dir(path).map_err(io(path))?.next();
        if let Some(entry) = first {
            let entry = entry.map_err(io(path))?;
            return Err(GapError::Data(format!(
                "gap-bench --keep {}: the directory is not empty (it holds `{}`); expected a new \
                 or empty directory, so no kept run is overwritten",
                path.display(),
                entry.file_name().to_string_lossy()
            )));
        }
        Ok(Self(path.to_path_buf(), true))
    }

    /// Done with `dir`, a directory inside: removed unless kept.
    pub fn done(&self, dir: &Path) -> Result<(), GapError> {
        if self.1 {
            return Ok(());
        }
        std::fs::remove_dir_all(dir).map_err(io(dir))
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        if !self.1 {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

/// One planned case: its draws, fixed whichever shard runs it.
struct Planned {
    index: usize,
    /// The hidden effects with their physical sizes in the source's unit: none (a null), one,
    /// or two (a pair case).
    hidden: Vec<(&'static Hidden, Vec<f64>)>,
    seed: u64,
}

impl Planned {
    /// The case's table row and directory label.
    fn label(&self) -> String {
        match self.hidden.as_slice() {
            [] => "null".to_string(),
            [(h, _)] => h.name.to_string(),
            more => more
                .iter()
                .map(|(h, _)| h.name)
                .collect::<Vec<_>>()
                .join("+"),
        }
    }
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
        // A scale of the whole term, linear and quadratic parts together, as the library's
        // `yaw_damping` scales it.
        vec![size[0] - 1.0]
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

/// A case's size in sigma: each hidden effect's truth against the interval of the candidate
/// of its name in `round` (the first round, accepted or not), the smallest of them; `None`
/// when an effect has no such candidate or no size.
pub fn case_size(round: &[Candidate], hidden: &[(&Hidden, Vec<f64>)]) -> Option<f64> {
    let sizes: Option<Vec<f64>> = hidden
        .iter()
        .map(|(h, size)| {
            let c = round.iter().find(|c| Some(c.name.as_str()) == h.library)?;
            let ci: Vec<[f64; 2]> = c.ci95.iter().map(|(_, c)| *c).collect();
            post_hoc_sigma(&library_truth(h, size), &ci)
        })
        .collect();
    sizes?.into_iter().reduce(f64::min)
}

pub fn io(path: &Path) -> impl FnOnce(std::io::Error) -> GapError + '_ {
    move |source| GapError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// A campaign's calibrated model as its file text, and how it did on the null run it was not
/// fitted to. Every case is analysed with the model read back from this text, whether the
/// calibration ran in the same process or came from `gap-bench calibrate`, so a shard given
/// the file analyses exactly as an unsharded run does.
#[derive(Debug, Clone, PartialEq)]
pub struct Calibrated {
    /// The calibrated model file ([`GapModel::to_toml`]).
    pub model_toml: String,
    pub gap: Option<CalibrationGap>,
}

impl Calibrated {
    /// The model the cases are analysed with: the text read back, its references resolving
    /// as the embedded base model's do.
    pub fn model(&self, origin: &str) -> Result<GapModel, GapError> {
        GapModel::from_text(origin, &self.model_toml, ".".into())
    }
}

/// A campaign's draws: the calibration's seeds and every case, in the fixed case order.
struct Plan {
    baseline_seeds: Vec<u64>,
    spread_seeds: Vec<u64>,
    cases: Vec<Planned>,
}

/// Draws the campaign of `opts` (the same whichever shard or step asks).
fn plan(opts: &BenchOptions, truth: &dyn Truth) -> Result<Plan, GapError> {
    let defaults = truth.default_sizes()?;
    let mut rng = crate::sensors::rng::stream(opts.seed, opts.source.rng_stream());
    let mut draw_seed = || rng.random_range(1_000..1_000_000_000u64);
    let baseline_seeds: Vec<u64> = (0..=BASELINE_RUNS).map(|_| draw_seed()).collect();
    let default_of = |h: &Hidden| {
        defaults
            .iter()
            .find(|(n, _)| n == h.name)
            .map(|(_, v)| v.clone())
            .ok_or_else(|| {
                GapError::Data(format!(
                    "the {} source offers no default size for the effect `{}`",
                    opts.source.name(),
                    h.name
                ))
            })
    };
    // A size drawn as the module doc says.
    let sized = |rng: &mut crate::sensors::rng::SensorRng, h: &'static Hidden| {
        let factor = rng.random_range(SIZE_FACTOR.0..SIZE_FACTOR.1);
        let positive = !h.signed || rng.random::<bool>();
        default_of(h).map(|d| (h, physical_size(h, &d, factor, positive)))
    };
    let mut plan = Vec::new();
    for h in &opts.hidden {
        for _ in 0..opts.cases {
            let seed = rng.random_range(1_000..1_000_000_000u64);
            let hidden = vec![sized(&mut rng, h)?];
            plan.push(Planned {
                index: plan.len(),
                hidden,
                seed,
            });
        }
    }
    for _ in 0..opts.cases {
        let seed = rng.random_range(1_000..1_000_000_000u64);
        plan.push(Planned {
            index: plan.len(),
            hidden: Vec::new(),
            seed,
        });
    }
    if opts.pairs > 0 && opts.hidden.len() < 2 {
        return Err(GapError::Data(format!(
            "--pairs {} needs at least two effects to draw from; --effects gives {}",
            opts.pairs,
            opts.hidden.len()
        )));
    }
    for _ in 0..opts.pairs {
        let seed = rng.random_range(1_000..1_000_000_000u64);
        let a = rng.random_range(0..opts.hidden.len());
        let b = (a + rng.random_range(1..opts.hidden.len())) % opts.hidden.len();
        let hidden = vec![
            sized(&mut rng, opts.hidden[a])?,
            sized(&mut rng, opts.hidden[b])?,
        ];
        plan.push(Planned {
            index: plan.len(),
            hidden,
            seed,
        });
    }
    // Drawn after the plan, so a source without spread runs keeps its cases.
    let spread_seeds: Vec<u64> = (0..truth.spread_runs())
        .map(|_| rng.random_range(1_000..1_000_000_000u64))
        .collect();
    Ok(Plan {
        baseline_seeds,
        spread_seeds,
        cases: plan,
    })
}

/// Calibrates the embedded model on the baseline runs of `plan`, written into `scratch`.
fn calibrate_on(
    opts: &BenchOptions,
    truth: &dyn Truth,
    plan: &Plan,
    scratch: &Scratch,
) -> Result<Calibrated, GapError> {
    let used = opts.baselines_used();
    let mut runs = Vec::new();
    for (i, seed) in plan.baseline_seeds.iter().enumerate() {
        if i >= used && i < BASELINE_RUNS {
            continue;
        }
        let dir = scratch.0.join(format!("baseline-{i}"));
        truth.baseline(i, *seed, &dir)?;
        runs.push(Run::load(&dir)?);
    }
    let validate = runs.split_off(used);
    let mut spread_from = Vec::new();
    for (i, seed) in plan.spread_seeds.iter().enumerate() {
        let dir = scratch.0.join(format!("spread-{i}"));
        truth.case(*seed, &[], &dir)?;
        spread_from.push(Run::load(&dir)?);
    }
    let model_text = Embedded.read(MODEL)?;
    let model = GapModel::from_text(&Embedded.describe(MODEL), &model_text, ".".into())?;
    let t0 = Instant::now();
    let cal = calibrate::calibrate(&model, &runs, &validate, &spread_from, &mut |_| {})?;
    let seconds = t0.elapsed().as_secs_f64();
    let spread: Vec<&calibrate::RunGap> = cal
        .runs
        .iter()
        .filter(|r| r.role == calibrate::RunRole::Spread)
        .collect();
    let mean = |f: fn(&calibrate::RunGap) -> f64| {
        spread.iter().map(|r| f(r)).sum::<f64>() / spread.len() as f64
    };
    let spread_gap = (!spread.is_empty()).then(|| [mean(|r| r.gap_before), mean(|r| r.gap_after)]);
    let gap = cal
        .runs
        .iter()
        .find(|r| r.role == calibrate::RunRole::Validation)
        .map(|r| CalibrationGap {
            gap_before: r.gap_before,
            gap_after: r.gap_after,
            reduction_pct: r.reduction_pct,
            seconds,
            spread: spread_gap,
            baselines: used,
        });
    let provenance = format!(
        "calibrated by `eyebot-hil gap-bench --source {} --seed {}` on baseline-0..{}",
        opts.source.name(),
        opts.seed,
        used - 1
    );
    for r in runs.iter().chain(&validate).chain(&spread_from) {
        scratch.done(&r.dir)?;
    }
    Ok(Calibrated {
        model_toml: cal.model.to_toml(&provenance, Path::new(".")),
        gap,
    })
}

/// The scratch directory of a run: the user's `--keep` directory or a temporary one.
fn scratch(opts: &BenchOptions) -> Result<Scratch, GapError> {
    match &opts.keep {
        Some(dir) => Scratch::kept(dir),
        None => Scratch::new(opts.source.name(), opts.seed),
    }
}

/// The calibration of the campaign `opts` on data from `truth`, on its own: what
/// `gap-bench calibrate` writes for the shards to share.
pub fn calibrate(opts: &BenchOptions, truth: &dyn Truth) -> Result<Calibrated, GapError> {
    let plan = plan(opts, truth)?;
    let scratch = scratch(opts)?;
    let calibrated = calibrate_on(opts, truth, &plan, &scratch)?;
    write_kept(opts, &scratch, &calibrated)?;
    Ok(calibrated)
}

/// With `--keep`, the calibrated model beside the kept runs (`calibrated.toml`).
fn write_kept(opts: &BenchOptions, scratch: &Scratch, cal: &Calibrated) -> Result<(), GapError> {
    if opts.keep.is_some() {
        let path = scratch.0.join("calibrated.toml");
        std::fs::write(&path, &cal.model_toml).map_err(io(&path))?;
    }
    Ok(())
}

/// Runs the cases of `shard` on data from `truth`, analysed with `calibrated` (the campaign's
/// shared calibration) or, when none is given, with a calibration made here first (it is
/// deterministic: the same for every shard of a campaign).
pub fn run(
    opts: &BenchOptions,
    shard: Shard,
    calibrated: Option<&Calibrated>,
    progress: &mut Progress<'_>,
    truth: &dyn Truth,
) -> Result<Outcome, GapError> {
    let plan = plan(opts, truth)?;
    let total = shard.count(plan.cases.len());
    let scratch = scratch(opts)?;
    let own;
    let calibrated = match calibrated {
        Some(c) => c,
        None => {
            progress(0, total, "calibrating", None);
            own = calibrate_on(opts, truth, &plan, &scratch)?;
            &own
        }
    };
    write_kept(opts, &scratch, calibrated)?;
    let model = calibrated.model("the campaign's calibrated model")?;
    let calibration = calibrated.gap.clone();

    let mut out = Vec::new();
    for p in plan.cases.into_iter().filter(|p| shard.contains(p.index)) {
        let label = p.label();
        let dir = scratch.0.join(format!("case-{}-{label}", p.index));
        let hidden: Vec<(&Hidden, &[f64])> =
            p.hidden.iter().map(|(h, s)| (*h, s.as_slice())).collect();
        truth.case(p.seed, &hidden, &dir)?;
        let m = Measurement::load(&dir)?;
        let t0 = Instant::now();
        let a = crate::gap::analyse_with(&model, &m, &dir, Options::default(), &mut |_, _| {})?;
        let seconds = t0.elapsed().as_secs_f64();
        scratch.done(&dir)?;

        let first = a.accepted.first();
        let named = first.map(|w| w.name.clone());
        // A pair case is scored on both names; its truth and fit are the first effect's, its
        // size the smaller of the two effects' sizes: a pair is named whole only where its
        // weaker effect shows.
        let main = p.hidden.first();
        let expected = main.and_then(|(h, _)| h.library);
        let expected_second = p.hidden.get(1).and_then(|(h, _)| h.library);
        let truth = main.map_or(Vec::new(), |(h, size)| library_truth(h, size));
        let size_sigma = case_size(a.rounds.first().map_or(&[][..], Vec::as_slice), &p.hidden);
        out.push(CaseResult {
            index: p.index,
            effect: main.map(|_| label.clone()),
            expected: expected.map(str::to_string),
            expected_second: expected_second.map(str::to_string),
            named_all: a.accepted.iter().map(|w| w.name.clone()).collect(),
            label: if p.hidden.len() > 1 {
                crate::gap::bench::table::PAIRS_ROW.to_string()
            } else {
                label.clone()
            },
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
            held_out_raw_reduction_pct: first.map(|_| a.raw.heldout_reduction_pct()),
            held_out_grew: Some(first.is_some() && a.heldout_gap_after > a.heldout_gap_before),
            ambiguous: a.ambiguous.clone(),
            tie: a.tie.as_ref().map(|t| t.pair.clone()),
            runner_up: super::runner_up(&a),
            verdict: Some(a.verdict.word().to_string()),
            seconds,
        });
        progress(out.len(), total, &label, out.last());
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
    /// its direction; the library sees a scale as its deviation.
    #[test]
    fn sizes_scale_from_the_default() {
        let yaw = Hidden {
            name: "yaw_damping",
            library: Some("yaw_damping"),
            signed: true,
            scale: true,
        };
        let up = physical_size(&yaw, &[1.5], 3.0, true);
        assert!((up[0] - 2.5).abs() < 1e-12);
        let down = physical_size(&yaw, &[1.5], 3.0, false);
        assert!((down[0] - 0.4).abs() < 1e-12);
        assert_eq!(library_truth(&yaw, &up), vec![1.5]);
        let wc = Hidden {
            name: "water_current",
            library: Some("water_current"),
            signed: false,
            scale: false,
        };
        assert_eq!(
            physical_size(&wc, &[0.02, -0.015], 2.0, true),
            vec![0.04, -0.03]
        );
    }

    /// A case with two hidden effects is as large as its weaker effect: the smaller of the two
    /// sizes, each read from its own candidate's interval; an effect without a candidate
    /// leaves the case without a size.
    #[test]
    fn a_pair_is_as_large_as_its_weaker_effect() {
        let hidden = |name: &'static str| Hidden {
            name,
            library: Some(name),
            signed: true,
            scale: false,
        };
        let (current, offset) = (hidden("water_current"), hidden("compass_offset"));
        let candidate = |name: &str, half: f64| {
            let mut c = Candidate::untestable(
                crate::gap::effects::by_name(name).expect("a library effect"),
                0.0,
                "",
            );
            c.ci95 = c
                .ci95
                .iter()
                .map(|(n, _)| (n.clone(), [-half, half]))
                .collect();
            c
        };
        // 1.96 / 1.96 = 1 per unit of truth: the current 10 sigma, the offset 1 sigma.
        let round = [
            candidate("water_current", 1.96),
            candidate("compass_offset", 1.96),
        ];
        let pair = [(&current, vec![10.0, 0.0]), (&offset, vec![1.0])];
        let size = case_size(&round, &pair).expect("both have candidates");
        assert!(
            (size - 1.0).abs() < 1e-12,
            "the weaker effect's size, got {size}"
        );
        let one = [(&current, vec![10.0, 0.0])];
        let size = case_size(&round, &one).expect("a candidate");
        assert!(
            (size - 10.0).abs() < 1e-12,
            "one effect's own size, got {size}"
        );
        assert_eq!(
            case_size(&round[..1], &pair),
            None,
            "the offset has no candidate"
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

    /// A kept directory is made when missing and used when empty; one holding an earlier
    /// campaign is refused, naming the directory and what it holds, and left as it was.
    #[test]
    fn a_kept_directory_must_be_new_or_empty() {
        let root = std::env::temp_dir().join(format!("eyebot-keep-test-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let fresh = root.join("fresh");
        assert!(Scratch::kept(&fresh).is_ok());
        assert!(fresh.is_dir());
        assert!(
            Scratch::kept(&fresh).is_ok(),
            "an empty directory is accepted"
        );

        let earlier = root.join("earlier");
        std::fs::create_dir_all(earlier.join("case-0-water_current")).unwrap();
        let err = match Scratch::kept(&earlier) {
            Ok(_) => panic!("a directory holding a run was accepted"),
            Err(e) => e.to_string(),
        };
        assert!(err.contains("earlier"), "{err}");
        assert!(err.contains("case-0-water_current"), "{err}");
        assert!(err.contains("not empty"), "{err}");
        assert!(earlier.join("case-0-water_current").is_dir());
        std::fs::remove_dir_all(&root).unwrap();
    }
}

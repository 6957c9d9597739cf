//! The hidden-effect benchmark (`eyebot-hil gap-bench`): for each effect of
//! the library, N randomised cases in which the effect is hidden in generated data, sized at
//! random from 1 to 10 times the noise floor and generated with random seeds, plus N null
//! cases with nothing hidden. Each case runs the whole workflow ([`crate::gap::analyse`]) on
//! the generated measurement only: the truth stays in this module and is used only to score.
//!
//! **Size.** A case's size in noise-floor units is the RMS, over the samples of the effect's
//! signature channels, of the change the effect makes to the noise-free prediction divided by
//! the model's noise floor at that sample (for the variance effect, depth EMI: the RMS of the
//! extra standard deviation over the floor). The parameter is first set from a one-point
//! calibration (the effect's size at one typical step, assumed linear) and kept within 80 % of
//! the effect's physical bounds, then the case's real size is measured and reported, so the
//! ">= 3 sigma" split uses measured sizes.
//!
//! **Held out.** The fitted model is scored on a second measurement of the same truth that the
//! fit never saw: another seed and another manoeuvre (the training schedule mirrored: the
//! turns go the other way, started from the mirrored point across the pool). The figure is the
//! reduction of the excess of the normalised residual over the noise floor (the same measure
//! as `gap_reduction_pct`), from the shipped model to the fitted one.
//!
//! **Sonar.** An effect that shows only in the sonar channels (`sonar_incidence_dropout`)
//! runs the sonar wall-sweep ([`SONAR_SCHEDULE`], the sonar fixtures' schedule) with the four
//! transducers pinged. Its size
//! is the RMS over pings of `sqrt(2 KL(p_truth || p_model))` of the echo probabilities (the
//! Gaussian `|difference| / sigma` for a Bernoulli reading), reached by bisection on the cut
//! (kept inside 0..90 deg), over the pings at a wall; its held-out run is the same
//! wall-sweep with another seed (only the port pair sees the wall, so a mirror image would
//! see nothing); its held-out figures are the sonar `-2 ln L` over the truth's (data) and
//! that KL distance (vs truth). Null cases then also run on the wall-sweep, in a
//! row `null (sonar)` of their own.

use std::time::Instant;

use rand::RngExt;

use crate::config::{ConfigSource, Document, Embedded};
use crate::gap::bench::{BenchOptions, CaseResult, Shard};
use crate::gap::effects::{self, Configs, Effect, Kind};
use crate::gap::format::Measurement;
use crate::gap::model::GapModel;
use crate::gap::resim::{self, Floor};
use crate::gap::{GapError, generate};
use crate::physics::experiment::Experiment;

/// The model the benchmark hides effects from (embedded `configs/models/mako.toml`).
pub const MODEL: &str = "models/mako.toml";
/// The training manoeuvre (embedded `configs/experiments/gap-manoeuvres.toml`).
pub const SCHEDULE: &str = "experiments/gap-manoeuvres.toml";
/// The sonar cases' manoeuvre (embedded `configs/experiments/gap-sonar-wall-sweep.toml`, the
/// schedule of the sonar fixtures): parked beside the west wall, slow spot turns both ways.
pub const SONAR_SCHEDULE: &str = "experiments/gap-sonar-wall-sweep.toml";
/// Camera position noise of the generated measurements (m, 1 sigma).
pub const CAMERA_STD_M: f64 = 0.01;
/// Case sizes are drawn uniformly from this range (noise-floor units).
pub const SIZE_RANGE: (f64, f64) = (1.0, 10.0);

fn embedded_schedule(path: &str) -> Result<Experiment, GapError> {
    let text = Embedded.read(path)?;
    Ok(Experiment::from_document(&Document::new(
        Embedded.describe(path),
        &text,
    ))?)
}

/// True for an effect that shows only in the sonar channels: its cases run the sonar
/// wall-sweep ([`SONAR_SCHEDULE`]) with the four transducers pinged, since the training
/// manoeuvre stays about 3 m off the walls and never gives an echo.
pub fn sonar_only(effect: &Effect) -> bool {
    effect
        .channels
        .iter()
        .all(|c| crate::gap::sonar::index(c).is_some())
}

/// The per-ping echo probabilities of every sonar channel of `m` under configs `c` on `run`
/// (one vector per sonar channel, in the order of `m.channels`).
fn sonar_probabilities(c: &Configs, run: &resim::Run, m: &Measurement) -> Vec<Vec<f64>> {
    use crate::gap::sonar;
    let s = &c.sensors.sonar;
    let world = crate::physics::world::Pool::new(&c.world);
    let times = sonar::ping_times(s, m.experiment.duration_s);
    m.channels
        .iter()
        .filter_map(|ch| sonar::index(&ch.name).and_then(|k| s.transducers.get(k)))
        .map(|t| {
            let tr = crate::sensors::sonar::Transducer::new(t, s, 0);
            times
                .iter()
                .map(|t| sonar::expected(s, &world, &tr, run.at(*t)).p)
                .collect()
        })
        .collect()
}

/// `2 KL(p_a || p_b)` of two echo probabilities (clamped as the likelihood clamps them): the
/// expected gain in `-2 ln L` per ping of the right model over the wrong one, the Bernoulli
/// counterpart of `(difference / sigma)^2` for a Gaussian channel.
fn two_kl(a: f64, b: f64) -> f64 {
    let lo = crate::gap::sonar::P_MIN;
    let (a, b) = (a.clamp(lo, 1.0 - lo), b.clamp(lo, 1.0 - lo));
    2.0 * (a * (a / b).ln() + (1.0 - a) * ((1.0 - a) / (1.0 - b)).ln())
}

/// Distance of model `c` from the truth `t` in the sonar channels of `m`: the RMS over pings
/// of `sqrt(2 KL(p_truth || p_model))` (noise-free, as [`truth_gap`] for the other channels).
pub fn sonar_truth_gap(c: &Configs, t: &Configs, m: &Measurement) -> Result<f64, GapError> {
    let (rc, rt) = (resim::simulate(c, m, None)?, resim::simulate(t, m, None)?);
    let (pc, pt) = (
        sonar_probabilities(c, &rc, m),
        sonar_probabilities(t, &rt, m),
    );
    let (mut sum, mut n) = (0.0, 0usize);
    for (a, b) in pt.iter().zip(&pc) {
        for (x, y) in a.iter().zip(b) {
            sum += two_kl(*x, *y);
            n += 1;
        }
    }
    Ok(if n == 0 { 0.0 } else { (sum / n as f64).sqrt() })
}

/// The sonar `-2 ln L` (presence deviance and range residuals, the fit's own objective) of
/// every sonar channel of `m` under configs `c`.
pub fn sonar_deviance(c: &Configs, m: &Measurement) -> Result<f64, GapError> {
    let run = resim::simulate(c, m, None)?;
    Ok(m.channels
        .iter()
        .filter_map(|ch| crate::gap::sonar::residuals(c, &run, m.experiment.duration_s, ch))
        .flatten()
        .map(|r| r * r)
        .sum())
}

/// Where the benchmark starts the training manoeuvre: the file's schedule turned to start
/// heading east from the pool's north-west quarter, which keeps the whole track (and the
/// drift of the largest currents) about 3 m clear of every wall. Contact with a wall would
/// hide a drift. `pty-tests/fixtures/gap/schedule.toml` is the same schedule written out.
pub const START: (f64, f64, f64) = (18.0, 3.0, 90.0);

/// The training manoeuvre: the file's commands from [`START`].
pub fn training(s: &Experiment) -> Experiment {
    let mut m = s.clone();
    m.start.north_m = START.0;
    m.start.east_m = START.1;
    m.start.heading_rad = START.2.to_radians();
    m
}

/// The held-out manoeuvre: the training schedule mirrored across the pool's long axis.
pub fn mirrored(s: &Experiment, pool_width_m: f64) -> Experiment {
    let mut m = s.clone();
    m.name = format!("{}-mirrored", s.name);
    m.start.east_m = pool_width_m - s.start.east_m;
    m.start.heading_rad = -s.start.heading_rad;
    for c in &mut m.schedule {
        c.percent.swap(0, 1);
    }
    m
}

/// Excess of the normalised residual over the noise floor (as `Analysis::excess_*`).
pub fn excess(c: &Configs, m: &Measurement, floors: &[Option<Floor>]) -> Result<f64, GapError> {
    let run = resim::simulate(c, m, None)?;
    let mut chi2 = Vec::new();
    for (ch, f) in m.channels.iter().zip(floors) {
        let (Some(f), Some(p)) = (f, resim::predict(c, &run, ch, 0.0)) else {
            continue;
        };
        let r = resim::residuals(ch, &p);
        let n = r.len().max(1) as f64;
        chi2.push(
            r.iter()
                .zip(&f.sigma)
                .map(|(a, s)| (a / s).powi(2))
                .sum::<f64>()
                / n,
        );
    }
    if chi2.is_empty() {
        return Ok(0.0);
    }
    let mean = chi2.iter().sum::<f64>() / chi2.len() as f64;
    Ok((mean - 1.0).max(0.0).sqrt())
}

/// Distance of model `c` from the truth `t` on measurement `m`, in noise-floor units: the RMS
/// over each channel's samples of the difference of the noise-free predictions and of the
/// predicted white-noise spreads, divided by the floor; averaged over channels.
pub fn truth_gap(
    c: &Configs,
    t: &Configs,
    m: &Measurement,
    floors: &[Option<Floor>],
) -> Result<f64, GapError> {
    let (rc, rt) = (resim::simulate(c, m, None)?, resim::simulate(t, m, None)?);
    let mut per_channel = Vec::new();
    for (ch, f) in m.channels.iter().zip(floors) {
        let Some(f) = f else { continue };
        let (Some(pc), Some(pt)) = (
            resim::predict(c, &rc, ch, 0.0),
            resim::predict(t, &rt, ch, 0.0),
        ) else {
            continue;
        };
        let sc = resim::measurement_std(c, m, &rc, ch);
        let st = resim::measurement_std(t, m, &rt, ch);
        let mut sum = 0.0;
        for i in 0..pc.len() {
            let d = if ch.name == "compass_deg" {
                resim::wrap_deg(pc[i] - pt[i])
            } else {
                pc[i] - pt[i]
            };
            sum += (d / f.sigma[i]).powi(2) + ((sc[i] - st[i]) / f.sigma[i]).powi(2);
        }
        per_channel.push(sum / pc.len().max(1) as f64);
    }
    if per_channel.is_empty() {
        return Ok(0.0);
    }
    Ok((per_channel.iter().sum::<f64>() / per_channel.len() as f64).sqrt())
}

/// Size of `effect` at `params` in noise-floor units on measurement `m` (see the module doc).
pub fn size_sigma(
    base: &Configs,
    effect: &Effect,
    params: &[f64],
    m: &Measurement,
    floors: &[Option<Floor>],
    base_run: &resim::Run,
) -> Result<f64, GapError> {
    let mut truth = base.clone();
    effects::apply(effect, params, &mut truth);
    let run = if effect.physics {
        resim::simulate(&truth, m, None)?
    } else {
        base_run.clone()
    };
    if sonar_only(effect) {
        // Presence of an echo is Bernoulli: the size is the RMS over pings of
        // sqrt(2 KL(p_truth || p_model)), which is |difference| / sigma for a Gaussian.
        let (p0, p1) = (
            sonar_probabilities(base, base_run, m),
            sonar_probabilities(&truth, &run, m),
        );
        // Over the pings at a wall (an echo possible under either model): a ping with no
        // wall in reach carries no sonar signal at all, unlike a Gaussian sample.
        let (mut sum, mut n) = (0.0, 0usize);
        for (a, b) in p1.iter().zip(&p0) {
            for (x, y) in a.iter().zip(b) {
                if x.max(*y) > crate::gap::sonar::P_MIN {
                    sum += two_kl(*x, *y);
                    n += 1;
                }
            }
        }
        return Ok(if n == 0 { 0.0 } else { (sum / n as f64).sqrt() });
    }
    let (mut sum, mut n) = (0.0, 0usize);
    for (ch, f) in m.channels.iter().zip(floors) {
        let Some(f) = f else { continue };
        if !effect.channels.contains(&ch.name.as_str()) {
            continue;
        }
        if effect.kind == Kind::Variance {
            let a = resim::measurement_std(base, m, base_run, ch);
            let b = resim::measurement_std(&truth, m, base_run, ch);
            for ((sa, sb), s) in a.iter().zip(&b).zip(&f.sigma) {
                sum += (sb * sb - sa * sa).max(0.0) / (s * s);
                n += 1;
            }
            continue;
        }
        let (Some(p0), Some(p1)) = (
            resim::predict(base, base_run, ch, 0.0),
            resim::predict(&truth, &run, ch, 0.0),
        ) else {
            continue;
        };
        for ((a, b), s) in p0.iter().zip(&p1).zip(&f.sigma) {
            let d = if ch.name == "compass_deg" {
                resim::wrap_deg(b - a)
            } else {
                b - a
            };
            sum += (d / s).powi(2);
            n += 1;
        }
    }
    Ok(if n == 0 { 0.0 } else { (sum / n as f64).sqrt() })
}

/// One manoeuvre the cases run: the training schedule, its mirrored held-out schedule,
/// whether the sonar is pinged, and the shipped model's prediction and floor on it.
struct Scene {
    train: Experiment,
    hold: Experiment,
    sonar: bool,
    probe: Measurement,
    base: Configs,
    base_run: resim::Run,
    floors: Vec<Option<Floor>>,
}

impl Scene {
    fn new(
        model: &GapModel,
        train: Experiment,
        sonar: bool,
        seed: u64,
    ) -> Result<(Scene, String, String), GapError> {
        let exp_dir = std::path::Path::new(".");
        // A null measurement fixes the channel sample times for the size calibration.
        let info = generate::setup(model, &train, CAMERA_STD_M);
        let (world, sensors) = (info.world.clone(), info.sensors.clone());
        let probe = generate::generate_with(
            &model.configs(&info, exp_dir)?,
            &train,
            &world,
            &sensors,
            CAMERA_STD_M,
            seed,
            sonar,
        )?;
        let base = model.configs(&probe.experiment, exp_dir)?;
        // The wall-sweep's transducers that see the wall are the port pair, so its mirror
        // image (the east wall to starboard) would give no echo at all: the sonar held-out
        // run is the same wall-sweep with another seed, as the sonar fixtures' held-out is.
        let hold = if sonar {
            train.clone()
        } else {
            mirrored(&train, base.world.pool_m.y)
        };
        let base_run = resim::simulate(&base, &probe, None)?;
        let floors = resim::noise_floor(&base, &probe, &base_run)?;
        Ok((
            Scene {
                train,
                hold,
                sonar,
                probe,
                base,
                base_run,
                floors,
            },
            world,
            sensors,
        ))
    }
}

/// The parameter of a sonar-only case (a one-parameter effect) whose measured size is
/// `target`, by bisection along `dir` up to `max_abs` (the presence probability is far from
/// linear in the cut, so the one-point calibration of the other effects would miss). A
/// binary reading caps the size (an echo rate falling from 90 % to none is
/// `sqrt(2 KL)` = 2.1): when `target` is out of reach, the parameter where the size first
/// reaches 95 % of its largest value, so the truth does not sit where the cut no longer
/// changes anything (a wider cut than any ray's incidence) and cannot be identified.
fn sonar_calibration(
    scene: &Scene,
    effect: &Effect,
    dir: f64,
    max_abs: f64,
    target: f64,
) -> Result<f64, GapError> {
    let size = |a: f64| {
        size_sigma(
            &scene.base,
            effect,
            &[dir * a],
            &scene.probe,
            &scene.floors,
            &scene.base_run,
        )
    };
    let (mut lo, mut hi) = (0.0, max_abs);
    let largest = size(hi)?;
    let target = if largest <= target {
        0.95 * largest
    } else {
        target
    };
    for _ in 0..20 {
        let mid = 0.5 * (lo + hi);
        if size(mid)? < target {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Ok(dir * 0.5 * (lo + hi))
}

/// Runs the benchmark; `progress(done, total, label, case)` after each case.
pub fn run(
    opts: &BenchOptions,
    shard: Shard,
    progress: &mut super::Progress<'_>,
) -> Result<Vec<CaseResult>, GapError> {
    let model_text = Embedded.read(MODEL)?;
    let model = GapModel::from_text(&Embedded.describe(MODEL), &model_text, ".".into())?;
    let mut rng = crate::sensors::rng::stream(opts.seed, "gap-bench");
    let (main, world, sensors) = Scene::new(
        &model,
        training(&embedded_schedule(SCHEDULE)?),
        false,
        opts.seed,
    )?;
    // The sonar wall-sweep, only when a sonar-only effect is benchmarked; its null cases then
    // run too (a row of their own), so a sonar candidate that fires on plain data shows.
    let sonar_scene = if opts.effects.iter().any(|e| sonar_only(e)) {
        Some(Scene::new(&model, embedded_schedule(SONAR_SCHEDULE)?, true, opts.seed)?.0)
    } else {
        None
    };
    let kinds = case_kinds(opts, &main, sonar_scene.as_ref());
    let plan = plan_cases(kinds, opts.cases, &mut rng);
    let env = CaseEnv {
        model: &model,
        world: &world,
        sensors: &sensors,
    };
    let total = shard.count(plan.len());
    let mut done = 0;
    let mut out = Vec::new();
    for case in plan {
        if !shard.contains(case.index) {
            continue;
        }
        let label = case_label(case.kind, case.scene);
        out.push(run_case(&env, case)?);
        done += 1;
        progress(done, total, label, out.last());
    }
    Ok(out)
}

/// What each case is: an effect hidden in its scene (a sonar-only effect on the sonar
/// wall-sweep when there is one), then the null cases on the main scene and on the sonar
/// scene if any.
fn case_kinds<'a>(
    opts: &BenchOptions,
    main: &'a Scene,
    sonar_scene: Option<&'a Scene>,
) -> Vec<(Option<&'static Effect>, &'a Scene)> {
    let mut kinds: Vec<(Option<&'static Effect>, &Scene)> = opts
        .effects
        .iter()
        .map(|e| {
            let scene = match sonar_scene {
                Some(s) if sonar_only(e) => s,
                _ => main,
            };
            (Some(*e), scene)
        })
        .collect();
    kinds.push((None, main));
    if let Some(s) = sonar_scene {
        kinds.push((None, s));
    }
    kinds
}

/// One case's draws, fixed before any case runs.
struct PlannedCase<'a> {
    /// Position in the fixed case order (the shards split by it).
    index: usize,
    /// The hidden effect; `None` for a null case.
    kind: Option<&'static Effect>,
    scene: &'a Scene,
    /// Seed of the training measurement.
    seed: u64,
    /// Seed of the held-out measurement.
    hold_seed: u64,
    /// Direction of the truth in parameter space (empty for a null case).
    dir: Vec<f64>,
    /// The size aimed at, in noise-floor units (0 for a null case).
    target: f64,
}

/// Every case's draws, in the fixed case order, whichever shard runs it: `cases` cases per
/// kind, each drawing its seeds, then (with an effect) its direction and target size.
fn plan_cases<'a>(
    kinds: Vec<(Option<&'static Effect>, &'a Scene)>,
    cases: usize,
    rng: &mut crate::sensors::rng::SensorRng,
) -> Vec<PlannedCase<'a>> {
    let mut plan = Vec::new();
    for (kind, scene) in kinds {
        for _ in 0..cases {
            let seed: u64 = rng.random();
            let hold_seed: u64 = rng.random();
            let (mut dir, mut target) = (Vec::new(), 0.0);
            if let Some(effect) = kind {
                dir = if effect.parameters.len() == 1 {
                    vec![if effect.positive || rng.random::<bool>() {
                        1.0
                    } else {
                        -1.0
                    }]
                } else {
                    let a = rng.random_range(0.0..std::f64::consts::TAU);
                    vec![a.cos(), a.sin()]
                };
                target = rng.random_range(SIZE_RANGE.0..SIZE_RANGE.1);
            }
            plan.push(PlannedCase {
                index: plan.len(),
                kind,
                scene,
                seed,
                hold_seed,
                dir,
                target,
            });
        }
    }
    plan
}

/// The row a case is counted in: its effect's name, or the null row of its scene.
fn case_label(kind: Option<&'static Effect>, scene: &Scene) -> &'static str {
    match kind {
        Some(e) => e.name,
        None if scene.sonar => "null (sonar)",
        None => "null",
    }
}

/// What every case shares: the model analysed and the world and sensor files the generated
/// measurements name.
struct CaseEnv<'a> {
    model: &'a GapModel,
    world: &'a str,
    sensors: &'a str,
}

/// Runs one case: hides the truth in a generated measurement, runs the whole workflow on it
/// and scores what it names, and how well, against the truth.
fn run_case(env: &CaseEnv<'_>, case: PlannedCase<'_>) -> Result<CaseResult, GapError> {
    let PlannedCase {
        index,
        kind,
        scene,
        seed,
        hold_seed,
        dir,
        target,
    } = case;
    let base = &scene.base;
    let mut truth_cfg = base.clone();
    let mut truth = Vec::new();
    let mut size = 0.0;
    if let Some(effect) = kind {
        truth = calibrated_truth(scene, effect, &dir, target)?;
        size = size_sigma(
            base,
            effect,
            &truth,
            &scene.probe,
            &scene.floors,
            &scene.base_run,
        )?;
        effects::apply(effect, &truth, &mut truth_cfg);
    }
    let m = generate::generate_with(
        &truth_cfg,
        &scene.train,
        env.world,
        env.sensors,
        CAMERA_STD_M,
        seed,
        scene.sonar,
    )?;
    let t0 = Instant::now();
    // Generated cases are open-loop schedules of the model's own form: replayed whole.
    let options = crate::gap::Options {
        shooting: crate::gap::anchor::Shooting::OPEN_LOOP,
        ..crate::gap::Options::default()
    };
    let exp_dir = std::path::Path::new(".");
    let a = crate::gap::analyse_with(env.model, &m, exp_dir, options, &mut |_, _| {})?;
    let seconds = t0.elapsed().as_secs_f64();
    let first = a.accepted.first();
    let named = first.map(|w| w.name.clone());
    let named_all: Vec<String> = a.accepted.iter().map(|w| w.name.clone()).collect();
    let fitted: Vec<f64> = first
        .map(|w| w.parameters.iter().map(|(_, v)| *v).collect())
        .unwrap_or_default();
    let ci95: Vec<[f64; 2]> = first
        .map(|w| w.ci95.iter().map(|(_, c)| *c).collect())
        .unwrap_or_default();
    let correct = kind.is_some() && named.as_deref() == kind.map(|e| e.name);
    let (parameter_error, ci_covers) = if correct {
        parameter_accuracy(&truth, &fitted, &ci95)
    } else {
        (None, None)
    };
    let (held_out_reduction_pct, held_out_truth_reduction_pct) = match kind {
        None => (None, None),
        Some(effect) => {
            let held = HeldOut {
                env,
                scene,
                effect,
                truth_cfg: &truth_cfg,
                fitted: &a.configs_after,
                seed: hold_seed,
            };
            held.reductions()?
        }
    };
    let label = case_label(kind, scene);
    Ok(CaseResult {
        index,
        effect: kind.map(|e| e.name.to_string()),
        expected: kind.map(|e| e.name.to_string()),
        label: label.to_string(),
        seed,
        truth,
        size_sigma: Some(size),
        named,
        expected_second: None,
        named_all,
        fitted,
        ci95,
        parameter_error,
        ci_covers,
        held_out_reduction_pct,
        held_out_truth_reduction_pct,
        held_out_raw_reduction_pct: None,
        held_out_grew: None,
        ambiguous: a.ambiguous.clone(),
        tie: a.tie.as_ref().map(|t| t.pair.clone()),
        runner_up: super::runner_up(&a),
        verdict: Some(a.verdict.word().to_string()),
        seconds,
    })
}

/// The truth's parameters for a case of `effect` along `dir` aimed at size `target`: by
/// bisection for a sonar-only one-parameter case, else by one-point calibration.
fn calibrated_truth(
    scene: &Scene,
    effect: &Effect,
    dir: &[f64],
    target: f64,
) -> Result<Vec<f64>, GapError> {
    let k = effect.parameters.len();
    if scene.sonar && k == 1 {
        // The cut stays inside its physical range 0..90 deg (apply clamps it,
        // which would make the truth's parameter a lie).
        let cut = scene.base.sensors.sonar.max_incidence_deg;
        let max_abs = if dir[0] < 0.0 { cut - 0.5 } else { 89.5 - cut };
        Ok(vec![sonar_calibration(
            scene, effect, dir[0], max_abs, target,
        )?])
    } else {
        one_point_truth(scene, effect, dir, target)
    }
}

/// One-point calibration: the size of one typical step along `dir`, scaled linearly to
/// `target`. A truth outside the effect's physical bounds is not a case `gap` may name (its
/// fit would end on the bound): it is shrunk along its direction to at most 80 % of the way to
/// a bound; the measured size says how big the case then is.
fn one_point_truth(
    scene: &Scene,
    effect: &Effect,
    dir: &[f64],
    target: f64,
) -> Result<Vec<f64>, GapError> {
    let unit: Vec<f64> = dir.iter().zip(effect.scales).map(|(d, s)| d * s).collect();
    let s1 = size_sigma(
        &scene.base,
        effect,
        &unit,
        &scene.probe,
        &scene.floors,
        &scene.base_run,
    )?;
    let factor = if s1 > 0.0 { target / s1 } else { 1.0 };
    let mut truth: Vec<f64> = unit.iter().map(|u| u * factor).collect();
    let reach = truth
        .iter()
        .zip(effect.bounds)
        .map(|(v, (lo, hi))| {
            let edge = if *v < 0.0 { -lo } else { *hi };
            if v.abs() > 0.0 && edge > 0.0 {
                v.abs() / (0.8 * edge)
            } else {
                0.0
            }
        })
        .fold(0.0, f64::max);
    if reach > 1.0 {
        for v in &mut truth {
            *v /= reach;
        }
    }
    Ok(truth)
}

/// How far the fitted parameters lie from the truth, relative to its length (`None` for a
/// zero truth), and whether every 95 % interval covers the truth's value.
fn parameter_accuracy(
    truth: &[f64],
    fitted: &[f64],
    ci95: &[[f64; 2]],
) -> (Option<f64>, Option<bool>) {
    let norm = truth.iter().map(|v| v * v).sum::<f64>().sqrt();
    let err = truth
        .iter()
        .zip(fitted)
        .map(|(t, f)| (t - f).powi(2))
        .sum::<f64>()
        .sqrt();
    let covers = truth
        .iter()
        .zip(ci95)
        .all(|(t, c)| c[0] <= *t && *t <= c[1]);
    ((norm > 0.0).then(|| err / norm), Some(covers))
}

/// The held-out scoring of one case with a hidden effect: a second measurement of the same
/// truth the fit never saw.
struct HeldOut<'a> {
    env: &'a CaseEnv<'a>,
    scene: &'a Scene,
    effect: &'static Effect,
    truth_cfg: &'a Configs,
    /// The configs of the model with the fitted effects.
    fitted: &'a Configs,
    seed: u64,
}

impl HeldOut<'_> {
    /// The held-out reductions (%), from the shipped model to the fitted one: of the data
    /// figure, and of the distance to the truth (`None` when the shipped model has none).
    fn reductions(&self) -> Result<(Option<f64>, Option<f64>), GapError> {
        let (scene, truth_cfg) = (self.scene, self.truth_cfg);
        let base = &scene.base;
        let h = generate::generate_with(
            truth_cfg,
            &scene.hold,
            self.env.world,
            self.env.sensors,
            CAMERA_STD_M,
            self.seed,
            scene.sonar,
        )?;
        let (before, after, tb, ta) = if scene.sonar && sonar_only(self.effect) {
            // The all-channel excess does not cover the sonar: the data figure is the sonar -2 ln L over the truth's on the held-out
            // data, the truth figure the KL distance of the echo probabilities.
            let d_truth = sonar_deviance(truth_cfg, &h)?;
            (
                sonar_deviance(base, &h)? - d_truth,
                sonar_deviance(self.fitted, &h)? - d_truth,
                sonar_truth_gap(base, truth_cfg, &h)?,
                sonar_truth_gap(self.fitted, truth_cfg, &h)?,
            )
        } else {
            let hb = resim::simulate(base, &h, None)?;
            let hf = resim::noise_floor(base, &h, &hb)?;
            // The fitted model's own floor: a fitted noise source (depth EMI)
            // is judged by the spread it predicts.
            let ha = resim::simulate(self.fitted, &h, None)?;
            let hfa = resim::noise_floor(self.fitted, &h, &ha)?;
            (
                excess(base, &h, &hf)?,
                excess(self.fitted, &h, &hfa)?,
                truth_gap(base, truth_cfg, &h, &hf)?,
                truth_gap(self.fitted, truth_cfg, &h, &hf)?,
            )
        };
        let held_out_truth_reduction_pct = (tb > 0.0).then(|| 100.0 * (1.0 - ta / tb));
        let held_out_reduction_pct = Some(if before > 0.0 {
            100.0 * (1.0 - after / before)
        } else {
            0.0
        });
        Ok((held_out_reduction_pct, held_out_truth_reduction_pct))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The sonar size must reduce to the Gaussian `(difference / sigma)^2` for a small change
    /// of the echo probability (sigma^2 = p (1 - p)), be zero for no change and grow with it.
    #[test]
    fn two_kl_is_the_bernoulli_counterpart_of_a_squared_z() {
        assert_eq!(two_kl(0.3, 0.3), 0.0);
        let (p, d) = (0.3, 1e-3);
        let z2 = d * d / (p * (1.0 - p));
        assert!((two_kl(p + d, p) / z2 - 1.0).abs() < 1e-2);
        assert!(two_kl(0.9, 0.3) > two_kl(0.6, 0.3));
        // Clamped like the likelihood: a certain echo the model rules out is finite.
        assert!(two_kl(1.0, 0.0).is_finite());
    }

    /// Only the sonar effect needs the wall-sweep; every other effect keeps the manoeuvre.
    #[test]
    fn only_the_sonar_effect_runs_the_wall_sweep() {
        let sonar: Vec<&str> = effects::LIBRARY
            .iter()
            .filter(|e| sonar_only(e))
            .map(|e| e.name)
            .collect();
        assert_eq!(sonar, ["sonar_incidence_dropout"]);
    }

    /// The embedded wall-sweep is the sonar fixtures' schedule (same start and commands).
    #[test]
    fn embedded_wall_sweep_is_the_sonar_fixture_schedule() {
        let embedded = embedded_schedule(SONAR_SCHEDULE).unwrap();
        let path = concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/pty-tests/fixtures/gap/sonar-schedule.toml"
        );
        let text = std::fs::read_to_string(path).unwrap();
        let fixture = Experiment::from_document(&Document::new(path.to_string(), &text)).unwrap();
        assert_eq!(embedded.schedule, fixture.schedule);
        assert_eq!(embedded.start, fixture.start);
        assert_eq!(embedded.duration_s, fixture.duration_s);
    }
}

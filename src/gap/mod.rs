//! The reality-gap workflow (`eyebot-hil gap`, `docs/gap.md`): given measured data, find where
//! the model disagrees, name the missing effect, add it with fitted parameters and show the
//! gap shrink.
//!
//! ```text
//! measurement dir ──format──▶ Measurement ──resim──▶ predictions + noise floor
//!     ──residuals──▶ where the gap is ──fit (effects library, LM, BIC)──▶ named effect
//!     ──report──▶ MODEL.fitted.toml, report.md, report.json, SVG plots
//! ```
//!
//! - [`convert`]: a daemon recording (`--record`) turned into a measurement (`gap convert`).
//! - [`format`]: `experiment.toml`, `commands.csv`, `measured.csv`.
//! - [`model`]: the model file `gap` compares against (and writes back, fitted).
//! - [`effects`]: the candidate library.
//! - [`resim`]: open-loop re-simulation, channel predictions, noise floor.
//! - [`residuals`]: statistics, whiteness, correlations, regimes.
//! - [`fit`]: Levenberg-Marquardt fits, BIC ranking, greedy selection.
//! - [`generate`]: hidden-effect data from a truth model (for tests and the benchmark).
//! - [`report`]: the output files.
//! - [`summary`]: summary observations (a quantity per experiment, with its uncertainty), the
//!   form the thesis reports Mako's measurements in.
//! - [`bench`]: the hidden-effect benchmark (`eyebot-hil gap-bench`).
//! - [`anchor`]: multiple shooting, the re-anchoring of the re-simulation to measurements.
//! - [`lsq`]: the one bounded Levenberg-Marquardt engine every fit uses.
//! - [`calibrate`]: `gap calibrate`, the base model's parameters fitted on baseline runs.
//! - [`analysis`]: what `gap` found, as [`analyse_with`] returns it.

pub mod analysis;
pub mod anchor;
pub mod bench;
pub mod calibrate;
pub mod candidate;
pub mod convert;
pub mod edit;
pub mod effects;
pub mod fit;
pub mod format;
pub mod generate;
pub mod later;
pub mod lsq;
pub mod model;
pub mod outliers;
pub mod redundant;
pub mod report;
pub mod residuals;
pub mod resim;
pub mod run;
pub mod sonar;
pub mod summary;

use std::path::{Path, PathBuf};

use crate::gap::candidate::Candidate;
use crate::gap::effects::Configs;
use crate::gap::format::Measurement;
use crate::gap::model::{EnabledEffect, GapModel};
use crate::gap::residuals::ChannelStats;
pub use analysis::{Analysis, RawGap, Tie, Unexplained, Verdict};
use later::nothing_off_that_it_moves;
pub use later::{LATER_NAME_FLOOR_SHARE, LATER_NAME_MIN_SHARE};

/// Errors of the gap workflow; each names its input.
#[derive(Debug, thiserror::Error)]
pub enum GapError {
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        source: std::io::Error,
    },
    #[error("{origin}:{line}: column `{column}`: {message}")]
    Csv {
        origin: String,
        line: usize,
        column: String,
        message: String,
    },
    #[error(transparent)]
    Config(#[from] crate::config::ConfigError),
    #[error("re-simulating `{experiment}`: {source}")]
    Physics {
        experiment: String,
        source: crate::physics::PhysicsError,
    },
    #[error("{0}")]
    Data(String),
    #[error("cannot write plot `{path}`: {message}")]
    Plot { path: String, message: String },
}

/// Which of the samples at times `t` lie where `run` is free of the pool: the samples every
/// fit leaves out ([`resim::Run::in_contact`]) are left out of the statistics the verdict and
/// the known levels read too, so a wall contact, which no effect's fit may see, is no
/// disagreement of its own.
fn free_of_contact(run: &resim::Run, t: &[f64], channel: &str) -> Vec<bool> {
    t.iter().map(|t| !run.in_contact(*t, channel)).collect()
}

/// The entries of `v` that `keep` keeps (`v` as it is when it is not one per sample).
fn kept(v: &[f64], keep: &[bool]) -> Vec<f64> {
    if v.len() != keep.len() {
        return v.to_vec();
    }
    v.iter()
        .zip(keep)
        .filter(|(_, k)| **k)
        .map(|(x, _)| *x)
        .collect()
}

/// `floor` at the samples `keep` keeps.
fn floor_kept<'a>(floor: &'a resim::Floor, keep: &[bool]) -> std::borrow::Cow<'a, resim::Floor> {
    if keep.iter().all(|k| *k) {
        return std::borrow::Cow::Borrowed(floor);
    }
    let (sigma, measurement_std) = (kept(&floor.sigma, keep), kept(&floor.measurement_std, keep));
    let null: Vec<Vec<f64>> = floor.null.iter().map(|n| kept(n, keep)).collect();
    std::borrow::Cow::Owned(resim::Floor {
        sigma,
        tau: floor.tau,
        measurement_std,
        null,
        chi2_tau_once: Default::default(),
    })
}

/// Each channel's statistics of `run` against `floors`, judged against the model's known
/// levels with their excess over the floor scaled by `weights` (by channel index,
/// [`fit::known_weights`]: 1 where no named noise source raised the floor; empty: 1 for all).
fn stats_for(
    model: &GapModel,
    m: &Measurement,
    c: &Configs,
    run: &resim::Run,
    floors: &[Option<resim::Floor>],
    weights: &[f64],
) -> Vec<ChannelStats> {
    let mut out = Vec::new();
    for (i, ch) in m.channels.iter().enumerate() {
        let Some(floor) = &floors[i] else { continue };
        let known = model
            .known(&ch.name)
            .under(weights.get(i).copied().unwrap_or(1.0));
        if let Some((t, r)) = sonar::stats_residuals(c, run, m.experiment.duration_s, ch) {
            let keep = free_of_contact(run, &t, &ch.name);
            let (t, r) = (kept(&t, &keep), kept(&r, &keep));
            let unit = resim::Floor {
                sigma: vec![1.0; r.len()],
                tau: 1.0,
                measurement_std: vec![1.0; r.len()],
                null: Vec::new(),
                chi2_tau_once: Default::default(),
            };
            let rms = (r.iter().map(|v| v * v).sum::<f64>() / r.len().max(1) as f64).sqrt();
            out.push(residuals::channel_stats(
                &ch.name,
                &t,
                &r,
                &unit,
                run,
                (0.0, rms),
                known,
            ));
            continue;
        }
        let Some(p) = resim::predict(c, run, ch, 0.0) else {
            continue;
        };
        let t: Vec<f64> = ch.samples.iter().map(|(t, _)| *t).collect();
        let keep = free_of_contact(run, &t, &ch.name);
        let r = kept(&resim::residuals(ch, &p), &keep);
        // Constant lag: the shift in -1..1 s (50 ms steps) with the smallest RMS.
        let mut best = (0.0, f64::INFINITY);
        for k in -20..=20 {
            let lag = f64::from(k) * 0.05;
            if let Some(pl) = resim::predict(c, run, ch, lag) {
                let rl = kept(&resim::residuals(ch, &pl), &keep);
                let rms = (rl.iter().map(|v| v * v).sum::<f64>() / rl.len().max(1) as f64).sqrt();
                if rms < best.1 - 1e-12 {
                    best = (lag, rms);
                }
            }
        }
        out.push(residuals::channel_stats(
            &ch.name,
            &kept(&t, &keep),
            &r,
            &floor_kept(floor, &keep),
            run,
            best,
            known,
        ));
    }
    out
}

fn track_distance(m: &Measurement, run: &resim::Run) -> Option<f64> {
    let x = m.channel("x_m")?;
    let y = m.channel("y_m")?;
    let mut sum = 0.0;
    let mut n = 0usize;
    for ((tx, vx), (ty, vy)) in x.samples.iter().zip(&y.samples) {
        if (tx - ty).abs() > 1e-6 {
            continue;
        }
        let s = run.at(*tx);
        sum += ((vx - s.position_m.x).powi(2) + (vy - s.position_m.y).powi(2)).sqrt();
        n += 1;
    }
    (n > 0).then(|| sum / n as f64)
}

/// The gap measure: `sqrt(max(0, q - 1))`, `q` the mean over channels of each channel's
/// chi-square per sample over its known level (`known`: the calibrated model's on baseline
/// runs, or 1, the noise floor alone). Each channel counts once, whatever its sample rate.
pub(crate) fn excess(per_channel: impl Iterator<Item = (f64, f64)>) -> f64 {
    channel_mean(per_channel).map_or(0.0, |q| (q - 1.0).max(0.0).sqrt())
}

/// The gap measure's `q` before its floor at 1: the mean over channels of chi2 per sample over
/// the known level (`None` without channels).
pub(crate) fn channel_mean(per_channel: impl Iterator<Item = (f64, f64)>) -> Option<f64> {
    let (mut sum, mut n) = (0.0, 0usize);
    for (chi2, known) in per_channel {
        sum += chi2 / known.max(1.0);
        n += 1;
    }
    (n > 0).then(|| sum / n as f64)
}

/// The whole run's gap from channel statistics, against each channel's known level (`raw`:
/// against the noise floor alone).
fn stats_excess(stats: &[ChannelStats], raw: bool) -> f64 {
    excess(stats.iter().map(|s| {
        let known = if raw { 1.0 } else { s.known_chi2_per_sample };
        (s.chi2_per_sample, known)
    }))
}

/// The held-out gap: [`excess`] of the held-out blocks' chi-square per independent sample,
/// channel by channel, against the model's known levels (`raw`: the noise floor alone).
fn heldout_excess(setup: &fit::Setup<'_>, c: &Configs, run: &resim::Run, raw: bool) -> f64 {
    excess(part_channels(setup, c, run, raw, Some(false)).into_iter())
}

/// Channel by channel, the chi-square per independent sample of `setup`'s residuals of
/// `run` (the samples its fits see: wall contacts left out) on `part` (the training blocks,
/// the held-out blocks, or all of them), with the setup's known level (`raw`: 1).
fn part_channels(
    setup: &fit::Setup<'_>,
    c: &Configs,
    run: &resim::Run,
    raw: bool,
    part: Option<bool>,
) -> Vec<(f64, f64)> {
    let r = setup.residuals(c, run);
    setup
        .part_levels(&r, part)
        .into_iter()
        .map(|(i, chi2)| {
            let known = if raw { 1.0 } else { setup.known[i] };
            (chi2, known)
        })
        .collect()
}

/// How much smaller `after` is than `before`, in percent (0 when there was no gap).
pub(crate) fn reduction_pct(before: f64, after: f64) -> f64 {
    if before > 0.0 {
        100.0 * (1.0 - after / before)
    } else {
        0.0
    }
}

/// Each accepted effect's share of the shrink, in percent: the gap of the model with every
/// other accepted effect, less the gap `after` with all of them, over the sum of those
/// growths. One effect has all of it; effects that each explain the same part share it.
fn shares(
    model: &GapModel,
    m: &Measurement,
    start: &Configs,
    accepted: &[Candidate],
    floors: &[Option<resim::Floor>],
    after: f64,
) -> Result<Vec<f64>, GapError> {
    if accepted.len() < 2 {
        return Ok(vec![100.0; accepted.len()]);
    }
    let mut growth = Vec::new();
    for left_out in 0..accepted.len() {
        let mut c = start.clone();
        for (k, a) in accepted.iter().enumerate() {
            if k != left_out
                && let Some(e) = effects::by_name(&a.name)
            {
                effects::apply(e, &a.values(), &mut c);
            }
        }
        let run = resim::simulate(&c, m, None)?;
        let without = stats_excess(&stats_for(model, m, &c, &run, floors, &[]), false);
        growth.push((without - after).max(0.0));
    }
    let total: f64 = growth.iter().sum();
    Ok(growth
        .iter()
        .map(|g| {
            if total > 0.0 {
                100.0 * g / total
            } else {
                100.0 / accepted.len() as f64
            }
        })
        .collect())
}

/// Options of one analysis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Options {
    pub shooting: anchor::Shooting,
    pub split: fit::Split,
}

impl Default for Options {
    fn default() -> Self {
        Self {
            shooting: anchor::Shooting::DEFAULT,
            split: fit::Split::DEFAULT,
        }
    }
}

/// Runs the whole workflow on a measurement with the default options. `exp_dir` resolves the
/// experiment's relative references; `progress(round, effect)` is called before each
/// candidate fit.
pub fn analyse(
    model: &GapModel,
    m: &Measurement,
    exp_dir: &Path,
    progress: &mut dyn FnMut(usize, &str),
) -> Result<Analysis, GapError> {
    analyse_with(model, m, exp_dir, Options::default(), progress)
}

/// `model` with the named effects enabled at their (joint) values and intervals.
fn with_named(model: &GapModel, accepted: &[Candidate]) -> Result<GapModel, GapError> {
    let mut with = model.clone();
    for a in accepted {
        let effect = effects::by_name(&a.name)
            .ok_or_else(|| GapError::Data(format!("`{}` is not in the effect library", a.name)))?;
        with.effects.push(EnabledEffect {
            effect,
            values: a.values(),
            ci95: a.ci95.iter().map(|(_, c)| *c).collect(),
            delta_bic: Some(a.delta_bic),
        });
    }
    Ok(with)
}

/// As [`analyse`], with explicit options.
pub fn analyse_with(
    model: &GapModel,
    m: &Measurement,
    exp_dir: &Path,
    options: Options,
    progress: &mut dyn FnMut(usize, &str),
) -> Result<Analysis, GapError> {
    let mut start = model.configs(&m.experiment, exp_dir)?;
    start.shooting = options.shooting;
    let clean0 = resim::simulate(&start, m, None)?;
    let floors = resim::noise_floor(&start, m, &clean0)?;
    if floors.iter().all(Option::is_none) {
        return Err(GapError::Data(format!(
            "no measured channel can be re-simulated; modelled channels are {}",
            resim::MODELLED.join(", ")
        )));
    }
    let unmodelled = m
        .channels
        .iter()
        .zip(&floors)
        .filter(|(_, f)| f.is_none())
        .map(|(c, _)| c.name.clone())
        .collect();
    let before = stats_for(model, m, &start, &clean0, &floors, &[]);
    // Each channel's known level read against the floor the named noise sources give
    // (`fit::known_weights`): the model's own floor until one is named.
    let noise_weights = |now: &[Option<resim::Floor>]| fit::known_weights(&floors, now);

    let spread = model.predictive_spread();
    let first =
        fit::setup(m, start.clone(), &floors, options.split, &spread)?.with_known(model, &[]);
    let heldout_before = heldout_excess(&first, &start, &clean0, false);
    let heldout_raw_before = heldout_excess(&first, &start, &clean0, true);
    // The model with the accepted effects: what each round fits against, and its gap
    // measure's channel mean on the samples the fits see.
    let configs = std::cell::RefCell::new(start.clone());
    let fitted = std::cell::RefCell::new(model.clone());
    // The noise floor every round is judged against: the model's, and once a noise source
    // (depth EMI) is named, the model's with it. Against the old floor, the named noise would
    // stay in the residuals as disagreement for the next round's candidates to fit.
    let current_floors = std::cell::RefCell::new(floors.clone());
    // The configuration `current_floors` is the floor of.
    let floors_of = std::cell::RefCell::new(start.clone());
    // Each channel's chi-square over its known level, the terms of the gap measure's mean.
    let levels_of = |c: &Configs, run: &resim::Run| -> Vec<f64> {
        let floors = current_floors.borrow();
        let judged = fit::Setup {
            floors: &floors,
            base: first.base.clone(),
            clean: first.clean.clone(),
            spread: first.spread.clone(),
            known: Vec::new(),
            ..first
        }
        .with_known(model, &noise_weights(&floors));
        part_channels(&judged, c, run, false, None)
            .into_iter()
            .map(|(chi2, known)| chi2 / known.max(1.0))
            .collect()
    };
    // The channels `levels_of` reads, in its order.
    let first_setup_channels: Vec<String> = first
        .modelled()
        .into_iter()
        .map(|i| m.channels[i].name.clone())
        .collect();
    let mean_of = |levels: &[f64]| channel_mean(levels.iter().map(|&q| (q, 1.0))).unwrap_or(0.0);
    let current = std::cell::RefCell::new(levels_of(&start, &clean0));
    // The configurations with the effects accepted so far, which each round's setup fits
    // against.
    let round_configs = || configs.borrow().clone();
    // Each round's candidates warm-start the next round's fits.
    let mut previous: Vec<Candidate> = Vec::new();
    // The structural terms fitted against a round's model, for every winner judged in it.
    let rival_fits = std::cell::RefCell::new(fit::RivalFits::default());
    let candidate::Selection {
        rounds,
        accepted,
        ambiguous,
        carried,
        outranked_by,
        refused,
    } = candidate::select_past_ties(
        fit::MAX_EFFECTS,
        &mut |round, accepted, refused| {
            let floors = current_floors.borrow();
            let setup = fit::setup(m, round_configs(), &floors, options.split, &spread)?
                .with_known(model, &noise_weights(&floors));
            let mut skip: Vec<&str> = accepted.iter().map(|a| a.name.as_str()).collect();
            skip.extend(refused.iter().map(|r| r.name.as_str()));
            skip.extend(model.effects.iter().map(|e| e.effect.name));
            let mut results =
                fit::fit_candidates(&setup, &skip, &previous, &mut |name| progress(round, name));
            later::rescore_with_earlier_free(&mut results, &previous, accepted, || {
                Ok(
                    fit::setup(m, start.clone(), &floors, options.split, &spread)?
                        .with_known(model, &noise_weights(&floors)),
                )
            })?;
            previous.clone_from(&results);
            Ok(Some(results))
        },
        &mut |accepted, refused_before| {
            let named = fit::named(accepted)?;
            // With two or more named, each is refitted alongside the others.
            let mut joint: Vec<(Vec<f64>, Vec<[f64; 2]>)> = accepted
                .iter()
                .map(|a| (a.values(), a.ci95.iter().map(|(_, c)| *c).collect()))
                .collect();
            // A newly named noise source moves the floor the fits are judged against; refused,
            // it leaves the floor as it was.
            let mut floor_before = None;
            if named
                .last()
                .is_some_and(|n| n.0.kind == effects::Kind::Variance)
            {
                floor_before = Some((current_floors.borrow().clone(), floors_of.borrow().clone()));
                let mut noisy = start.clone();
                for (effect, values, _) in named.iter().filter(|n| n.0.kind != effects::Kind::Mean)
                {
                    effects::apply(effect, values, &mut noisy);
                }
                let clean = resim::simulate(&noisy, m, None)?;
                *current_floors.borrow_mut() = resim::noise_floor(&noisy, m, &clean)?;
                *floors_of.borrow_mut() = noisy;
            }
            if named.len() > 1 {
                let floors = current_floors.borrow();
                let setup = fit::setup(m, start.clone(), &floors, options.split, &spread)?
                    .with_known(model, &noise_weights(&floors));
                if let Some(refit) = fit::refit_jointly(&setup, &named) {
                    for ((values, ci), (new_values, new_ci)) in joint.iter_mut().zip(refit) {
                        *values = new_values;
                        if !new_ci.is_empty() {
                            *ci = new_ci;
                        }
                    }
                }
            }
            let mut c = start.clone();
            for ((effect, _, _), (values, _)) in named.iter().zip(&joint) {
                effects::apply(effect, values, &mut c);
            }
            // The earlier names as the joint fit has them beside the newest: what a later
            // name is judged against. Held at their own rounds' values they keep the share of
            // its disagreement they took before it was in the model (a thruster lag fitted
            // 2.7 s long where it stood in for a compass latency), and the newest then looks
            // like a stand-in for what they lack.
            let mut earlier = start.clone();
            let earlier_count = named.len().saturating_sub(1);
            for ((effect, _, _), (values, _)) in named.iter().zip(&joint).take(earlier_count) {
                effects::apply(effect, values, &mut earlier);
            }
            let newest_values = joint.last().map(|(v, _)| v.clone()).unwrap_or_default();
            tracing::debug!(
                joint = ?joint.iter().map(|(v, _)| v).collect::<Vec<_>>(),
                "the named effects' values, refitted together"
            );
            // A mean effect must bring the model closer to the data by the measure the gap is
            // reported in, every channel counted once: a fit that buys chi-square in a channel
            // of many samples with a worse fit of others trades disagreement, as a stand-in for
            // a term the library lacks does.
            let run = resim::simulate(&c, m, None)?;
            let levels = levels_of(&c, &run);
            let mean = mean_of(&levels);
            let without = mean_of(&current.borrow());
            tracing::debug!(
                effect = named.last().map(|n| n.0.name),
                mean,
                without,
                ?levels,
                before = ?current.borrow(),
                "the gap's channel mean with the newest effect"
            );
            if let Some((effect, _, _)) = named.last()
                && effect.kind == effects::Kind::Mean
                && mean >= without
            {
                let why = format!(
                    "with it, the channels' mean chi-square over their known levels is \
                     {mean:.3}, against {without:.3} without it: it does not shrink the gap"
                );
                return Ok(Some(why.into()));
            }
            // An effect named after others is refused as a stand-in when it explains only a
            // small part of what the earlier names left and its value follows them: where they
            // act strongly they drive the model where the calibration did not take it, and
            // what their form lacks shows as a disagreement another effect can take in part.
            // Either sign alone is no proof: on a vehicle of another structure a right effect's
            // value depends on the regime too, and a right effect may be a small part of a
            // disagreement that is mostly structure.
            let channel_names: Vec<&str> =
                first_setup_channels.iter().map(String::as_str).collect();
            // A channel without samples is left out of the levels: then the whole run's alone.
            let named_in_order = channel_names.len() == levels.len();
            // The earlier names can leave the whole run at or below its known levels while the
            // channels a later name moves still hold an excess: channels the model fits better
            // than the calibration's runs hide it in the mean. Such a name is judged in the
            // channels it moves: its share there, and a channel it moves still off.
            let excess_where_it_acts = named.len() > 1
                && named.last().is_some_and(|(effect, _, _)| {
                    effect.kind == effects::Kind::Mean
                        && later::excess_only_where_it_acts(
                            effect,
                            &channel_names,
                            &current.borrow(),
                        )
                });
            let share = if without > 1.0 {
                (without - mean) / (without - 1.0)
            } else if let Some((effect, _, _)) = named.last()
                && excess_where_it_acts
            {
                later::share_where_it_acts(effect, &channel_names, &current.borrow(), &levels)
            } else {
                1.0
            };
            // A first name must find an excess where it acts, as a later one must
            // (`later::first_name_without_excess`).
            if let Some((effect, _, _)) = named.last()
                && named.len() == 1
                && effect.kind == effects::Kind::Mean
                && let Some(why) =
                    later::first_name_without_excess(effect, &channel_names, &current.borrow())
            {
                return Ok(Some(why.into()));
            }
            if let Some((effect, _, _)) = named.last()
                && named.len() == 1
                && effect.kind == effects::Kind::Mean
                && let Some(why) = later::first_name_within_the_scatter(
                    model,
                    m,
                    effect,
                    &channel_names,
                    &current.borrow(),
                    &levels,
                    &earlier,
                    &current_floors.borrow(),
                    &noise_weights(&current_floors.borrow()),
                )?
            {
                return Ok(Some(why.into()));
            }
            // An effect named after others must take at least a tenth of what they left
            // (`later::too_small_later_share`); a noise source refused there leaves the
            // floor as it was.
            if let Some((effect, _, _)) = named.last()
                && named.len() > 1
            {
                if let Some(why) = later::too_small_later_share(
                    effect,
                    named_in_order.then_some(&channel_names[..]),
                    &current.borrow(),
                    &levels,
                    excess_where_it_acts,
                ) {
                    if let Some((floors, of)) = floor_before {
                        *current_floors.borrow_mut() = floors;
                        *floors_of.borrow_mut() = of;
                    }
                    return Ok(Some(why.into()));
                }
                if excess_where_it_acts {
                    if let Some(why) = nothing_off_that_it_moves(
                        model,
                        m,
                        effect,
                        &earlier,
                        &current_floors.borrow(),
                        &noise_weights(&current_floors.borrow()),
                    )? {
                        let why = format!(
                            "the effects named before it leave the channels' mean chi-square \
                             at {without:.3}, at or below the known levels, and {why}"
                        );
                        return Ok(Some(why.into()));
                    }
                    tracing::debug!(
                        effect = effect.name,
                        without,
                        share,
                        "a later name judged in the channels it moves: the whole run at or \
                         below its known levels, those channels above theirs"
                    );
                }
            }
            // An effect named after others that explains less than most of what they left
            // must find a disagreement left that runs with nothing new do not show: a channel
            // it moves still significantly off, by the test the report's "still off" list
            // uses.
            if let Some((effect, _, _)) = named.last()
                && named.len() > 1
                && effect.kind == effects::Kind::Mean
                && share < LATER_NAME_MIN_SHARE
                && let Some(why) = nothing_off_that_it_moves(
                    model,
                    m,
                    effect,
                    &earlier,
                    &current_floors.borrow(),
                    &noise_weights(&current_floors.borrow()),
                )?
            {
                let why = format!(
                    "it explains {:.0} % of the disagreement the effects named before it left \
                     (the channels' mean chi-square over their known levels {without:.3} -> \
                     {mean:.3}), and {why}",
                    100.0 * share
                );
                return Ok(Some(why.into()));
            }
            // A winner in place of one refused in the same round must explain most of what
            // is left in the channels it moves (`later::share_where_it_acts`).
            if let Some((effect, _, _)) = named.last()
                && let Some(first) = refused_before.first()
                && effect.kind == effects::Kind::Mean
                && let Some(win) = accepted.last()
                && later::held_as_stand_in(win, first.structure.as_deref())
            {
                let share = if named_in_order {
                    later::share_where_it_acts(effect, &channel_names, &current.borrow(), &levels)
                } else {
                    share
                };
                if share < LATER_NAME_MIN_SHARE {
                    let there = if named_in_order {
                        "in the channels it moves"
                    } else {
                        "in the channels"
                    };
                    let why = format!(
                        "it takes the place of `{}`, refused in the same round, and explains \
                         only {:.0} % of the disagreement left {there} (their mean chi-square \
                         over their known levels); in place of a refused winner an effect must \
                         explain most of it ({:.0} %)",
                        first.name,
                        100.0 * share,
                        100.0 * LATER_NAME_MIN_SHARE
                    );
                    return Ok(Some(why.into()));
                }
            }
            // The effects named before the newest, the latest first.
            let before_it: Vec<&effects::Effect> =
                named.iter().rev().skip(1).map(|n| n.0).collect();
            if let Some((effect, _, noise_factor)) = named.last()
                && named.len() > 1
                && effect.kind == effects::Kind::Mean
                && share < LATER_NAME_MIN_SHARE
            {
                let unnamed_floors = &floors;
                let floors = current_floors.borrow();
                let setup = fit::setup(m, earlier.clone(), &floors, options.split, &spread)?
                    .with_known(model, &noise_weights(&floors));
                let now = setup.residuals(&setup.base, &setup.clean);
                // Where the earlier names change the fit most against where they change it
                // least; and, after a noise source, where it widens the floor against where it
                // leaves it as it was: it changes no mean, and a stand-in for what it drives (a
                // depth hold chattering on a noisy reading) differs there, not where the means
                // moved least.
                let by_change = fit::strong_blocks(
                    &first.residuals(&start, &clean0),
                    &now,
                    options.split.block_s,
                );
                let mut splits = vec![(
                    by_change,
                    "blocks where they change the fit most",
                    "where they change it least",
                )];
                if before_it.iter().any(|e| e.kind != effects::Kind::Mean) {
                    splits.push((
                        fit::noise_source_blocks(
                            &now,
                            unnamed_floors,
                            &floors,
                            options.split.block_s,
                        ),
                        "blocks where the noise source named before it widens the floor",
                        "where it leaves the floor as it was",
                    ));
                }
                for (strong, there, elsewhere) in splits {
                    let test =
                        fit::constancy(&setup, effect, &newest_values, *noise_factor, &strong);
                    tracing::debug!(
                        effect = effect.name,
                        share,
                        split = there,
                        ?test,
                        "a later name's constancy"
                    );
                    if let Some(t) = test
                        && !t.holds()
                    {
                        let show = |v: &[f64]| {
                            v.iter()
                                .map(|x| format!("{x:.4}"))
                                .collect::<Vec<_>>()
                                .join(", ")
                        };
                        let why = format!(
                            "it explains {:.0} % of the disagreement the effects named before it \
                             left (the channels' mean chi-square over their known levels \
                             {without:.3} -> {mean:.3}), and its value follows them: [{}] in the \
                             {} s {there}, [{}] {elsewhere} (Wald statistic {:.1} > {:.1}, its \
                             {:.0} % point). Read it as what the earlier names' form lacks",
                            100.0 * share,
                            show(&t.strong),
                            options.split.block_s,
                            show(&t.weak),
                            t.statistic,
                            t.critical,
                            100.0 * fit::CONSTANCY_LEVEL
                        );
                        return Ok(Some(why.into()));
                    }
                }
            }
            // A later name is refused when the earlier names changed the vehicle's dynamics
            // (`fit::earlier_change_dynamics`), moved its channels somewhere new, and a term of
            // the base model's structure explains the same disagreement as well or better
            // there (`fit::structural_rival`).
            if let Some((effect, _, _)) = named.last()
                && named.len() > 1
                && effect.kind == effects::Kind::Mean
                && fit::earlier_change_dynamics(&before_it)
                && let Some(win) = accepted.last()
            {
                let floors = current_floors.borrow();
                let setup = fit::setup(m, round_configs(), &floors, options.split, &spread)?
                    .with_known(model, &noise_weights(&floors));
                let unnamed = setup.residuals(&start, &clean0);
                if fit::moved_to_new_regime(&setup, &before_it, &unnamed, win)
                    && let Some(rival) = rival_fits.borrow_mut().rival_of(&setup, win)
                {
                    let why = format!(
                        "`{}`, a term of the base model's structure, explains the same \
                         disagreement as well or better (delta BIC {:.1} \
                         against {:.1}): the earlier names take the vehicle where the baseline \
                         runs did not, and the data do not tell a new effect from structure \
                         those runs left unpinned there",
                        rival.name, rival.delta_bic_uncalibrated, win.delta_bic_uncalibrated
                    );
                    return Ok(Some(candidate::Refusal::of_its_form(why, rival)));
                }
            }
            *current.borrow_mut() = levels;
            for (a, (values, ci)) in accepted.iter_mut().zip(joint) {
                for ((_, v), new) in a.parameters.iter_mut().zip(&values) {
                    *v = *new;
                }
                for ((_, old), new) in a.ci95.iter_mut().zip(&ci) {
                    *old = *new;
                }
            }
            *configs.borrow_mut() = c;
            *fitted.borrow_mut() = with_named(model, accepted)?;
            Ok(None)
        },
    )?;
    // After the rounds, against the model without any name: an earlier name the later ones show
    // to be its look-alike's place is exchanged for it, then one the later ones (or the
    // look-alike the selection stopped on) leave without an effect of its own is dropped.
    let (mut accepted, mut refused) = (accepted, refused);
    if !accepted.is_empty() {
        let floors = current_floors.borrow();
        let setup = fit::setup(m, start.clone(), &floors, options.split, &spread)?
            .with_known(model, &noise_weights(&floors));
        if let Some(ex) = later::exchange_lookalikes(&setup, &rounds, &accepted) {
            *fitted.borrow_mut() = with_named(model, &ex.accepted)?;
            *configs.borrow_mut() = ex.configs;
            accepted = ex.accepted;
        }
        if let Some(kept) = redundant::after_rounds(&setup, &rounds, &accepted, ambiguous.as_ref())?
        {
            *fitted.borrow_mut() = with_named(model, &kept.accepted)?;
            *configs.borrow_mut() = kept.configs;
            accepted = kept.accepted;
            refused.extend(kept.dropped);
        }
    }
    let (configs, fitted) = (configs.into_inner(), fitted.into_inner());
    let clean1 = resim::simulate(&configs, m, None)?;
    // A fitted noise source (depth EMI) changes the floor the "after" residuals are judged by.
    // The floor is a function of the configuration: one already made is not made again.
    let floors_after = if configs == start {
        floors.clone()
    } else if configs == *floors_of.borrow() {
        current_floors.borrow().clone()
    } else {
        resim::noise_floor(&configs, m, &clean1)?
    };
    let weights_after = noise_weights(&current_floors.borrow());
    let after = stats_for(model, m, &configs, &clean1, &floors_after, &weights_after);
    // Judged against the floor the model's named noise sources give, as the whole run is.
    let judged = fit::Setup {
        floors: &floors_after,
        ..first
    }
    .with_known(model, &weights_after);
    let heldout_after = heldout_excess(&judged, &configs, &clean1, false);
    let heldout_raw_after = heldout_excess(&judged, &configs, &clean1, true);
    let (eb, ea) = (stats_excess(&before, false), stats_excess(&after, false));
    let shares_pct = shares(model, m, &start, &accepted, &floors, ea)?;
    let (rb, ra) = (stats_excess(&before, true), stats_excess(&after, true));
    let unexplained: Vec<Unexplained> = after
        .iter()
        .filter(|s| s.significant)
        .map(|s| Unexplained {
            channel: s.channel.clone(),
            chi2_per_sample: s.chi2_per_sample,
            regimes: s
                .regimes
                .iter()
                .filter(|r| r.significant)
                .map(|r| r.regime.clone())
                .collect(),
            windows: s.windows.clone(),
        })
        .collect();
    // The carried tie's winner leaves the names, with its share of the shrink. The tie stands
    // while its winner does: one the later names exchanged for its look-alike, or left
    // without an effect of its own, no longer says which of two it is.
    let (mut accepted, mut shares_pct) = (accepted, shares_pct);
    let tie = carried.and_then(|c| {
        let i = accepted.iter().position(|a| a.name == c.pair[0])?;
        let share_pct = if i < shares_pct.len() {
            shares_pct.remove(i)
        } else {
            f64::NAN
        };
        Some(Tie {
            round: c.round,
            pair: c.pair,
            carried: accepted.remove(i),
            share_pct,
        })
    });
    let verdict = if !accepted.is_empty() {
        Verdict::Effect
    } else if ambiguous.is_some() || tie.is_some() {
        Verdict::Ambiguous
    } else if before.iter().any(|s| s.significant) {
        Verdict::Unexplained
    } else {
        Verdict::None
    };
    Ok(Analysis {
        verdict,
        track_distance_before_m: track_distance(m, &clean0),
        track_distance_after_m: track_distance(m, &clean1),
        excess_before: eb,
        excess_after: ea,
        gap_reduction_pct: reduction_pct(eb, ea),
        heldout_gap_before: heldout_before,
        heldout_gap_after: heldout_after,
        heldout_reduction_pct: reduction_pct(heldout_before, heldout_after),
        raw: RawGap {
            excess_before: rb,
            excess_after: ra,
            heldout_before: heldout_raw_before,
            heldout_after: heldout_raw_after,
        },
        unexplained,
        shares_pct,
        shooting: options.shooting,
        split: options.split,
        before,
        after,
        rounds,
        ambiguous,
        tie,
        outranked_by,
        refused,
        accepted,
        fitted,
        unmodelled,
        clean_before: clean0,
        clean_after: clean1,
        configs_before: start,
        configs_after: configs,
        floors,
    })
}

#[cfg(test)]
mod tests;

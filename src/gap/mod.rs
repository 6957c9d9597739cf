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
//! - [`contrast`]: where two look-alike effects predict the run differently.
//! - `naming`: the rules a round's winner is taken into the model by, or refused by.

pub mod analysis;
pub mod anchor;
pub mod bench;
pub mod calibrate;
pub mod candidate;
pub mod contrast;
pub mod convert;
pub mod edit;
pub mod effects;
pub mod fit;
pub mod format;
pub mod generate;
pub mod later;
pub mod lsq;
pub mod model;
mod naming;
pub mod outliers;
pub mod redundant;
pub mod report;
pub mod residuals;
pub mod resim;
pub mod run;
pub mod sonar;
pub mod summary;

use std::cell::RefCell;
use std::path::{Path, PathBuf};

use crate::gap::candidate::Candidate;
use crate::gap::effects::Configs;
use crate::gap::format::Measurement;
use crate::gap::model::{EnabledEffect, GapModel};
use crate::gap::residuals::ChannelStats;
pub use analysis::{Analysis, RawGap, Tie, Unexplained, Verdict};
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
pub(crate) fn part_channels(
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
pub(crate) fn with_named(model: &GapModel, accepted: &[Candidate]) -> Result<GapModel, GapError> {
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
    let naming = naming::Naming {
        model,
        m,
        options,
        spread: &spread,
        start: &start,
        clean0: &clean0,
        floors: &floors,
        first: &first,
        channel_names: first
            .modelled()
            .into_iter()
            .map(|i| m.channels[i].name.clone())
            .collect(),
        configs: RefCell::new(start.clone()),
        fitted: RefCell::new(model.clone()),
        current_floors: RefCell::new(floors.clone()),
        floors_of: RefCell::new(start.clone()),
        current: RefCell::new(Vec::new()),
        rival_fits: RefCell::new(fit::RivalFits::default()),
    };
    *naming.current.borrow_mut() = naming.levels_of(&start, &clean0);
    // Each round's candidates warm-start the next round's fits.
    let mut previous: Vec<Candidate> = Vec::new();
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
            let floors = naming.current_floors.borrow();
            let setup = naming.setup_on(naming.configs.borrow().clone(), &floors)?;
            let mut skip: Vec<&str> = accepted.iter().map(|a| a.name.as_str()).collect();
            skip.extend(refused.iter().map(|r| r.name.as_str()));
            skip.extend(model.effects.iter().map(|e| e.effect.name));
            let mut results =
                fit::fit_candidates(&setup, &skip, &previous, &mut |name| progress(round, name));
            later::rescore_with_earlier_free(&mut results, &previous, accepted, || {
                naming.setup_on(start.clone(), &floors)
            })?;
            previous.clone_from(&results);
            Ok(Some(results))
        },
        &mut |accepted, refused_before| naming.accept(accepted, refused_before),
    )?;
    let (mut configs, mut fitted) = (naming.configs.into_inner(), naming.fitted.into_inner());
    let (current_floors, floors_of) = (
        naming.current_floors.into_inner(),
        naming.floors_of.into_inner(),
    );
    // After the rounds, against the model without any name: an earlier name the later ones show
    // to be its look-alike's place is exchanged for it, then one the later ones (or the
    // look-alike the selection stopped on) leave without an effect of its own is dropped.
    let (mut accepted, mut refused) = (accepted, refused);
    if !accepted.is_empty() {
        let setup = fit::setup(m, start.clone(), &current_floors, options.split, &spread)?
            .with_known(model, &noise_weights(&current_floors));
        if let Some(ex) = later::exchange_lookalikes(&setup, &rounds, &accepted) {
            fitted = with_named(model, &ex.accepted)?;
            configs = ex.configs;
            accepted = ex.accepted;
        }
        if let Some(kept) = redundant::after_rounds(&setup, &rounds, &accepted, ambiguous.as_ref())?
        {
            fitted = with_named(model, &kept.accepted)?;
            configs = kept.configs;
            accepted = kept.accepted;
            refused.extend(kept.dropped);
        }
    }
    let clean1 = resim::simulate(&configs, m, None)?;
    // A fitted noise source (depth EMI) changes the floor the "after" residuals are judged by.
    // The floor is a function of the configuration: one already made is not made again.
    let floors_after = if configs == start {
        floors.clone()
    } else if configs == floors_of {
        current_floors.clone()
    } else {
        resim::noise_floor(&configs, m, &clean1)?
    };
    let weights_after = noise_weights(&current_floors);
    let after = stats_for(model, m, &configs, &clean1, &floors_after, &weights_after);
    // The residuals' layout (owners and times) every round's changes follow, which a tie's
    // contrast is read on: built only where the search ended on or carried a tie.
    let layout =
        (carried.is_some() || ambiguous.is_some()).then(|| first.residuals(&start, &clean0));
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
    let mut analysis = Analysis {
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
        contrasts: Vec::new(),
    };
    // Where each tie's two effects predict the run differently.
    if let Some(layout) = &layout {
        let contrasts = analysis
            .ties()
            .iter()
            .filter_map(|pair| {
                analysis.rounds.iter().rev().find_map(|round| {
                    let of = |name: &str| round.iter().find(|c| c.name == name);
                    contrast::between(
                        of(&pair[0])?,
                        of(&pair[1])?,
                        layout,
                        m,
                        &analysis.clean_before,
                    )
                })
            })
            .collect();
        analysis.contrasts = contrasts;
    }
    Ok(analysis)
}

#[cfg(test)]
mod tests;

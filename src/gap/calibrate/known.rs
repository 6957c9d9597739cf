//! The known disagreement of a calibrated model: each channel's chi-square per sample on runs
//! with nothing new, its mean (the known level `gap` reads a channel against), how the runs
//! scatter, and the bound one more such run stays under; and the warning for a validation run
//! the calibrated model fits worse than the model as given.

use std::collections::BTreeMap;

use serde::Serialize;

use super::{Run, RunGap, RunRole, channel_chi2, prepare};
use crate::gap::GapError;
use crate::gap::model::{GapModel, RunScatter};

/// The mean of each channel's chi-square per sample over the runs.
pub(super) fn discrepancy(per_run: &BTreeMap<String, Vec<f64>>) -> Vec<(String, f64)> {
    use statrs::statistics::Statistics;
    per_run
        .iter()
        .filter(|(_, v)| !v.is_empty())
        .map(|(c, v)| (c.clone(), v.iter().mean()))
        .collect()
}

/// Per channel measured on two or more runs with nothing new, how the runs scatter
/// ([`RunScatter::of`]).
pub(super) fn run_scatter(per_run: &BTreeMap<String, Vec<f64>>) -> BTreeMap<String, RunScatter> {
    per_run
        .iter()
        .filter_map(|(channel, v)| Some((channel.clone(), RunScatter::of(v)?)))
        .collect()
}

/// Per channel measured on two or more runs with nothing new, the chi-square per sample one
/// more such run stays under with every such channel judged together
/// ([`RunScatter::bound`]; a run disagrees when any of them does).
pub(super) fn run_bounds(per_run: &BTreeMap<String, Vec<f64>>) -> Vec<(String, f64)> {
    let scatter = run_scatter(per_run);
    scatter
        .iter()
        .filter_map(|(channel, s)| Some((channel.clone(), s.bound(scatter.len())?)))
        .collect()
}

/// One run's chi-square per sample by channel under the calibrated model, as `gap` will see
/// it (the calibrated model's own noise floor, re-anchored segments).
pub(super) struct RunChi2 {
    pub dir: String,
    pub channels: BTreeMap<String, f64>,
}

/// [`RunChi2`] of each of `runs`.
pub(super) fn chi2_of_runs(calibrated: &GapModel, runs: &[Run]) -> Result<Vec<RunChi2>, GapError> {
    runs.iter()
        .map(|r| {
            let p = prepare(calibrated, r)?;
            let s = p.setup()?;
            let channels = channel_chi2(&p, &s, &p.base)
                .unwrap_or_default()
                .into_iter()
                .map(|(i, chi2)| (r.m.channels[i].name.clone(), chi2))
                .collect();
            Ok(RunChi2 {
                dir: r.dir.display().to_string(),
                channels,
            })
        })
        .collect()
}

/// Each channel's chi-squares per sample over `runs`.
fn by_channel(runs: &[&RunChi2]) -> BTreeMap<String, Vec<f64>> {
    let mut out: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    for r in runs {
        for (channel, chi2) in &r.channels {
            out.entry(channel.clone()).or_default().push(*chi2);
        }
    }
    out
}

/// A validation run unlike the spread runs: the channels where its chi-square per sample lies
/// outside the spread runs' prediction interval ([`RunScatter::interval`]), each with its
/// value and that interval.
#[derive(Debug, Clone, Serialize)]
pub struct Unlike {
    pub run: String,
    pub channels: Vec<(String, f64, [f64; 2])>,
}

impl Unlike {
    /// The warning the command line prints.
    pub fn warning(&self) -> String {
        let channels: Vec<String> = self
            .channels
            .iter()
            .map(|(ch, v, [lo, hi])| format!("{ch} {v:.2} outside {lo:.2}..{hi:.2}"))
            .collect();
        format!(
            "warning: validation run {} is unlike the spread runs (chi2 per sample {}): it \
             drives the calibrated model where the programme you will analyse does not, so the \
             known disagreement and its bound come from the spread runs without it",
            self.run,
            channels.join(", ")
        )
    }
}

/// The runs with nothing new the known disagreement is read on, by channel.
pub(super) struct Known {
    /// The chi-squares the known level is the mean of.
    pub levels: BTreeMap<String, Vec<f64>>,
    /// The chi-squares the run bound and scatter come from (runs the calibration was not
    /// fitted to; empty when there are none).
    pub unfitted: BTreeMap<String, Vec<f64>>,
    /// The runs of `levels`.
    pub from: Vec<String>,
    /// Validation runs left out as unlike the spread runs.
    pub unlike: Vec<Unlike>,
}

/// Which runs the known disagreement is read on. The spread runs are, by the protocol, null
/// runs of the programme later runs use: where given, the known level and its scatter are
/// theirs, with each validation run that is like them (inside their prediction interval in
/// every channel); a validation run of another programme meets the model's error otherwise (a
/// depth hold beside runs at the surface: depth 401 per sample against their 1) and would
/// set the level a later run of the spread runs' programme is judged against. Without
/// spread runs: the validation runs, else the baseline runs (`baseline`, read only then),
/// the bound from the validation runs alone.
pub(super) fn known_runs(
    validate: &[RunChi2],
    spread: &[RunChi2],
    baseline: impl FnOnce() -> Result<Vec<RunChi2>, GapError>,
) -> Result<Known, GapError> {
    if spread.is_empty() {
        let unfitted = by_channel(&validate.iter().collect::<Vec<_>>());
        if validate.is_empty() {
            let baseline = baseline()?;
            return Ok(Known {
                levels: by_channel(&baseline.iter().collect::<Vec<_>>()),
                unfitted,
                from: baseline.iter().map(|r| r.dir.clone()).collect(),
                unlike: Vec::new(),
            });
        }
        return Ok(Known {
            levels: unfitted.clone(),
            unfitted,
            from: validate.iter().map(|r| r.dir.clone()).collect(),
            unlike: Vec::new(),
        });
    }
    let scatter = run_scatter(&by_channel(&spread.iter().collect::<Vec<_>>()));
    let mut kept: Vec<&RunChi2> = spread.iter().collect();
    let mut unlike = Vec::new();
    for v in validate {
        let off: Vec<(String, f64, [f64; 2])> = v
            .channels
            .iter()
            .filter_map(|(channel, chi2)| {
                let interval = scatter.get(channel)?.interval(scatter.len())?;
                (*chi2 < interval[0] || *chi2 > interval[1])
                    .then(|| (channel.clone(), *chi2, interval))
            })
            .collect();
        if off.is_empty() {
            kept.push(v);
        } else {
            unlike.push(Unlike {
                run: v.dir.clone(),
                channels: off,
            });
        }
    }
    let levels = by_channel(&kept);
    Ok(Known {
        unfitted: levels.clone(),
        levels,
        from: kept.iter().map(|r| r.dir.clone()).collect(),
        unlike,
    })
}

impl RunGap {
    /// For a run the calibration was not fitted to (validation or spread) that the calibrated
    /// model fits worse than the model as given: a warning naming the run, the gap before and after and the channels that grew most.
    /// The baseline runs then do not cover what this run does (another programme, depth or
    /// speed), and what was fitted on them does not carry over to it.
    pub fn grown_warning(&self) -> Option<String> {
        if self.role == RunRole::Baseline || self.gap_after <= self.gap_before {
            return None;
        }
        let mut grown: Vec<&(String, f64, f64)> =
            self.channels.iter().filter(|(_, b, a)| a > b).collect();
        grown.sort_by(|x, y| (y.2 - y.1).total_cmp(&(x.2 - x.1)));
        let channels: Vec<String> = grown
            .iter()
            .take(3)
            .map(|(ch, b, a)| format!("{ch} {b:.2} -> {a:.2}"))
            .collect();
        let carried = if self.carried_by.is_empty() {
            String::new()
        } else {
            let terms: Vec<String> = self
                .carried_by
                .iter()
                .map(|(name, gap)| format!("{name} (gap {gap:.2} with it as given)"))
                .collect();
            format!(
                "; the calibrated terms that carry it furthest: {}",
                terms.join(", ")
            )
        };
        Some(format!(
            "warning: the calibrated model fits {} {} worse than the model as given \
             (gap {:.2} -> {:.2}; chi2 per sample {}{carried}): the baseline runs do not cover \
             what it does; calibrate on runs like it, or analyse it with the model as given",
            self.role.label(),
            self.dir,
            self.gap_before,
            self.gap_after,
            channels.join(", ")
        ))
    }
}

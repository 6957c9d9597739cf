//! The known disagreement of a calibrated model: each channel's chi-square per sample on runs
//! with nothing new, its mean (the known level `gap` reads a channel against), how the runs
//! scatter, and the bound one more such run stays under; and the warning for a validation run
//! the calibrated model fits worse than the model as given.

use std::collections::BTreeMap;

use super::{Run, RunGap, channel_chi2, prepare};
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

/// The calibrated model's chi-square per sample by channel on each of `runs`, as `gap` will
/// see it (the calibrated model's own noise floor, re-anchored segments).
pub(super) fn channel_chi2_per_run(
    calibrated: &GapModel,
    runs: &[&Run],
) -> Result<BTreeMap<String, Vec<f64>>, GapError> {
    let mut out: BTreeMap<String, Vec<f64>> = BTreeMap::new();
    for r in runs {
        let p = prepare(calibrated, r)?;
        let s = p.setup()?;
        for (i, chi2) in channel_chi2(&p, &s, &p.base).unwrap_or_default() {
            out.entry(r.m.channels[i].name.clone())
                .or_default()
                .push(chi2);
        }
    }
    Ok(out)
}

impl RunGap {
    /// For a validation run the calibrated model fits worse than the model as given: a
    /// warning naming the run, the gap before and after and the channels that grew most.
    /// The baseline runs then do not cover what this run does (another programme, depth or
    /// speed), and what was fitted on them does not carry over to it.
    pub fn grown_warning(&self) -> Option<String> {
        if self.fitted || self.gap_after <= self.gap_before {
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
        Some(format!(
            "warning: the calibrated model fits validation run {} worse than the model as given \
             (gap {:.2} -> {:.2}; chi2 per sample {}): the baseline runs do not cover what it \
             does; calibrate on runs like it, or analyse it with the model as given",
            self.dir,
            self.gap_before,
            self.gap_after,
            channels.join(", ")
        ))
    }
}

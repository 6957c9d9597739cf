//! Every run's gap before and after the calibration, and the calibrated terms that carry a
//! run it fits worse.

use nalgebra::DVector;

use super::{Prepared, Run, RunGap, RunRole, channel_chi2, excess, prepare};
use crate::gap::GapError;
use crate::gap::effects::{self, Effect};
use crate::gap::fit::Setup;
use crate::gap::model::GapModel;

/// The gap of every baseline run (fitted), validation run and spread run, before and after
/// applying the calibration `x` of `chosen`, overall and per channel.
pub(super) fn score_runs(
    model: &GapModel,
    baseline: &[Run],
    validate: &[Run],
    spread_from: &[Run],
    chosen: &[&'static Effect],
    x: &DVector<f64>,
) -> Result<Vec<RunGap>, GapError> {
    let mut runs = Vec::new();
    for (role, list) in [
        (RunRole::Baseline, baseline),
        (RunRole::Validation, validate),
        (RunRole::Spread, spread_from),
    ] {
        for r in list {
            let p = prepare(model, r)?;
            let s = p.setup()?;
            let after_c = effects::apply_joint(&p.base, chosen, x);
            let before = channel_chi2(&p, &s, &p.base).unwrap_or_default();
            let after = channel_chi2(&p, &s, &after_c).unwrap_or_default();
            let (gb, ga) = (excess(&before), excess(&after));
            let carried_by = if role != RunRole::Baseline && ga > gb {
                carried_by(&p, &s, chosen, x, ga)
            } else {
                Vec::new()
            };
            runs.push(RunGap {
                dir: r.dir.display().to_string(),
                role,
                gap_before: gb,
                gap_after: ga,
                reduction_pct: crate::gap::reduction_pct(gb, ga),
                channels: before
                    .iter()
                    .map(|(i, b)| {
                        let a = after.iter().find(|(k, _)| k == i).map_or(f64::NAN, |x| x.1);
                        (r.m.channels[*i].name.clone(), *b, a)
                    })
                    .collect(),
                carried_by,
            });
        }
    }
    Ok(runs)
}

/// How many calibrated effects a grown run's warning names.
const CARRIED_BY_SHOWN: usize = 3;

/// The calibrated effects that carry a run the calibration fits worse (gap `after`) furthest
/// from the model as given: each effect set back to the model as given (its parameters 0)
/// with every other one kept, the run's gap then, for those where it shrinks, most first. A
/// term fitted where the baseline runs drove the vehicle (a thrust curve on spins and
/// cruises) and applied where they did not (the small commands of a depth hold) shows here.
fn carried_by(
    p: &Prepared<'_>,
    s: &Setup<'_>,
    chosen: &[&'static Effect],
    x: &DVector<f64>,
    after: f64,
) -> Vec<(String, f64)> {
    let mut out = Vec::new();
    let mut at = 0;
    for e in chosen {
        let n = e.parameters.len();
        let mut without = x.clone();
        without.rows_mut(at, n).fill(0.0);
        at += n;
        if without == *x {
            continue;
        }
        let c = effects::apply_joint(&p.base, chosen, &without);
        if let Some(chi2) = channel_chi2(p, s, &c) {
            let gap = excess(&chi2);
            if gap < after {
                out.push((e.name.to_string(), gap));
            }
        }
    }
    out.sort_by(|a, b| a.1.total_cmp(&b.1));
    out.truncate(CARRIED_BY_SHOWN);
    out
}

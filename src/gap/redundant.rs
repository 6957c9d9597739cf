//! Backward elimination after the greedy rounds: a name the later ones leave without an effect
//! of its own is dropped.
//!
//! Each round names the candidate that explains most of what the names before it left, with
//! those names held in the model. A first winner can be a stand-in: on a run spent afloat, a
//! hidden depth offset puts every re-anchored segment start at the wrong height, the hull
//! bobs back to its float, and a surge added mass of 30 kg that bends those transients wins the
//! first round while the offset fails its signature there (drawn structure 458399, seed
//! 403969, case 46). Once the offset is named beside it, the two refitted together
//! ([`fit::refit_jointly`]) put the added mass at 0.05 kg, its interval about zero: the offset
//! explains what it stood in for. Forward selection alone keeps it named; the stepwise
//! procedure's backward step (Efroymson 1960) drops it.
//!
//! An earlier name is dropped when, refitted jointly with the names after it, every one of its
//! parameters' 95 % intervals (the joint covariance with the between-run spread) holds zero and
//! its values have fallen to less than [`COLLAPSED`] of those it was named with (in units of
//! its parameters' scales): the one whose values lie deepest inside their intervals first, then
//! the rest refitted and asked again. An interval that holds zero alone is no proof: two right
//! names that move the readings alike widen each other's intervals while both keep their
//! values (drawn structure 474457, seed 420029, case 71: a hidden thruster lag of 0.95 s named
//! after a yaw damping came to 0.66 s [-0.04, 1.36] beside a thrust gain named third). The newest name is not asked: it passed every guard with the earlier ones in
//! the model. Where the selection stopped on two look-alikes of one round (`ambiguous`), the
//! round's winner stands in for whichever of the two it is: the earlier names are refitted with
//! it and judged the same way (it is not named). Only mean-type effects are dropped; a noise
//! source's level is not refitted jointly.

use super::GapError;
use super::candidate::{Candidate, Refused};
use super::effects::{self, Configs, Kind};
use super::fit;

/// An earlier name whose interval holds zero is dropped only where its joint values have
/// fallen below this share of the values it was named with: the later names took what it
/// explained.
pub const COLLAPSED: f64 = 0.5;

/// Whether every interval of `ci` holds zero (an effect with no intervals holds none).
fn holds_zero(ci: &[[f64; 2]]) -> bool {
    !ci.is_empty() && ci.iter().all(|c| c[0] <= 0.0 && 0.0 <= c[1])
}

/// How far inside their intervals the values lie: the largest of each value's distance from
/// zero over its interval's half width toward it (below 1 for a value whose interval holds
/// zero). The name with the smallest is the least supported.
fn support(values: &[f64], ci: &[[f64; 2]]) -> f64 {
    values
        .iter()
        .zip(ci)
        .map(|(v, c)| {
            let half = if *v >= 0.0 { v - c[0] } else { c[1] - v };
            if half > 0.0 { v.abs() / half } else { 0.0 }
        })
        .fold(0.0, f64::max)
}

/// The names kept and those dropped by [`drop_redundant`].
#[derive(Debug, Clone)]
pub(crate) struct Kept {
    /// The names kept, in order, with their values and intervals from the last joint refit.
    pub accepted: Vec<Candidate>,
    /// The names dropped, each as a refused winner of its round with the reason.
    pub dropped: Vec<Refused>,
    /// The setup's base with the names kept applied at their values.
    pub configs: Configs,
}

/// The backward step after the greedy rounds: [`drop_redundant`] of `accepted` (`rounds[i]`
/// the round that named `accepted[i]`, whose value there is the one it was named with), beside
/// the winner of the last round where the selection stopped on it as `ambiguous`.
pub(crate) fn after_rounds(
    setup: &fit::Setup<'_>,
    rounds: &[Vec<Candidate>],
    accepted: &[Candidate],
    ambiguous: Option<&[String; 2]>,
) -> Result<Option<Kept>, GapError> {
    let beside = ambiguous.and_then(|[winner, _]| {
        rounds
            .last()
            .and_then(|round| round.iter().find(|c| &c.name == winner))
    });
    let named_with: Vec<Vec<f64>> = accepted
        .iter()
        .zip(rounds)
        .map(|(a, round)| {
            round
                .iter()
                .find(|c| c.name == a.name)
                .map_or_else(|| a.values(), Candidate::values)
        })
        .collect();
    drop_redundant(setup, accepted, &named_with, beside)
}

/// Backward elimination of `accepted` (named in rounds 0, 1, ... in order, with the values and
/// intervals of their last joint refit) against `setup`, whose base holds none of them.
/// `named_with` holds each name's values in the round it was named in. `beside` is the winner
/// of an ambiguous round after them, judged with them and never kept. `None` when nothing is
/// dropped.
pub(crate) fn drop_redundant(
    setup: &fit::Setup<'_>,
    accepted: &[Candidate],
    named_with: &[Vec<f64>],
    beside: Option<&Candidate>,
) -> Result<Option<Kept>, GapError> {
    // The length of a name's values in units of its parameters' scales.
    let size = |name: &str, values: &[f64]| -> f64 {
        let scales = effects::by_name(name).map_or(&[][..], |e| e.scales);
        values
            .iter()
            .zip(scales)
            .map(|(v, s)| (v / s).powi(2))
            .sum::<f64>()
            .sqrt()
    };
    let mut named_with: Vec<&[f64]> = named_with.iter().map(Vec::as_slice).collect();
    // The names that may be dropped: every earlier one; with a look-alike beside them, the
    // newest too.
    let askable = |n: usize| {
        if beside.is_some() {
            n
        } else {
            n.saturating_sub(1)
        }
    };
    if askable(accepted.len()) == 0 {
        return Ok(None);
    }
    let mut kept: Vec<Candidate> = accepted.to_vec();
    let mut dropped = Vec::new();
    // Each name's round: its index in the names as first accepted.
    let mut rounds: Vec<usize> = (0..accepted.len()).collect();
    // The values and intervals judged: the accepted names' own joint refit, or with a
    // look-alike beside them a refit of them with it.
    let mut judged: Vec<(Vec<f64>, Vec<[f64; 2]>)> = if let Some(b) = beside {
        let mut set = kept.clone();
        set.push(b.clone());
        let Some(refit) = fit::refit_jointly(setup, &fit::named(&set)?) else {
            return Ok(None);
        };
        refit
    } else {
        kept.iter()
            .map(|a| (a.values(), a.ci95.iter().map(|(_, c)| *c).collect()))
            .collect()
    };
    loop {
        tracing::debug!(
            names = ?kept.iter().map(|c| c.name.as_str()).collect::<Vec<_>>(),
            beside = beside.map(|b| b.name.as_str()),
            ?judged,
            "the names refitted together, asked whether each holds an effect"
        );
        let weakest = (0..askable(kept.len()))
            .filter(|&i| {
                effects::by_name(&kept[i].name).is_some_and(|e| e.kind == Kind::Mean)
                    && holds_zero(&judged[i].1)
                    && named_with.get(i).is_some_and(|w| {
                        size(&kept[i].name, &judged[i].0) < COLLAPSED * size(&kept[i].name, w)
                    })
            })
            .min_by(|&a, &b| {
                support(&judged[a].0, &judged[a].1).total_cmp(&support(&judged[b].0, &judged[b].1))
            });
        let Some(i) = weakest else {
            break;
        };
        let gone = kept.remove(i);
        let was = named_with.remove(i);
        let show = |v: &[f64]| {
            v.iter()
                .map(|x| format!("{x:.4}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        let intervals = judged[i]
            .1
            .iter()
            .map(|c| format!("[{:.4}, {:.4}]", c[0], c[1]))
            .collect::<Vec<_>>()
            .join(", ");
        let later: Vec<&str> = kept[i..]
            .iter()
            .map(|c| c.name.as_str())
            .chain(beside.map(|b| b.name.as_str()))
            .collect();
        tracing::debug!(
            dropped = gone.name,
            values = ?judged[i].0,
            ci95 = ?judged[i].1,
            "an earlier name the later ones leave without an effect"
        );
        let why = format!(
            "refitted together with `{}`, named after it, its value is [{}] with 95 % interval \
             {intervals}, which holds no effect, against [{}] when it was named: what it \
             explained, they explain",
            later.join("`, `"),
            show(&judged[i].0),
            show(was)
        );
        dropped.push(Refused::of_the_disagreement(
            rounds.remove(i),
            gone.name,
            why,
        ));
        judged.remove(i);
        let mut set = kept.clone();
        set.extend(beside.cloned());
        if set.is_empty() {
            break;
        }
        match fit::refit_jointly(setup, &fit::named(&set)?) {
            Some(refit) => judged = refit,
            None => judged.truncate(set.len()),
        }
        for (a, (values, ci)) in kept.iter_mut().zip(&judged) {
            for ((_, v), new) in a.parameters.iter_mut().zip(values) {
                *v = *new;
            }
            if !ci.is_empty() {
                for ((_, old), new) in a.ci95.iter_mut().zip(ci) {
                    *old = *new;
                }
            }
        }
        if askable(kept.len()) == 0 {
            break;
        }
    }
    if dropped.is_empty() {
        return Ok(None);
    }
    let mut configs = setup.base.clone();
    for a in &kept {
        if let Some(effect) = effects::by_name(&a.name) {
            effects::apply(effect, &a.values(), &mut configs);
        }
    }
    Ok(Some(Kept {
        accepted: kept,
        dropped,
        configs,
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::effects::{self, Configs};
    use crate::gap::fit::{Split, fit_effects, setup};
    use crate::gap::resim;

    /// The simulator manoeuvre measured with `truth`, and the setup of the model without it.
    fn with_truth(truth: fn(&mut Configs), check: impl FnOnce(&fit::Setup<'_>)) {
        let (_, c, m) = crate::gap::resim::tests::manoeuvre_of(13, truth);
        let clean = resim::simulate(&c, &m, None).unwrap();
        let floors = resim::noise_floor(&c, &m, &clean).unwrap();
        check(&setup(&m, c, &floors, Split::DEFAULT, &[]).unwrap());
    }

    /// A name a later one leaves without an effect is dropped, one with an effect of its own
    /// kept. On a run with a hidden depth offset, a compass offset named at 2 degrees before the
    /// depth offset, refitted beside it, holds no effect and is dropped, with the reason; named
    /// at the value it has beside it (no collapse) it is kept, as it is beside a hidden compass
    /// offset of 4 degrees. Judged beside the winner of an ambiguous round (the depth offset,
    /// not named), the collapsed compass offset is dropped too.
    #[test]
    fn an_earlier_name_the_later_ones_leave_without_an_effect_is_dropped() {
        let by = |n| effects::by_name(n).unwrap();
        let pair = |s: &fit::Setup<'_>| -> Vec<Candidate> {
            let mut pair = fit_effects(s, &[by("compass_offset")], &mut |_| {});
            let mut c = s.base.clone();
            effects::apply(by("compass_offset"), &pair[0].values(), &mut c);
            let clean = resim::simulate(&c, s.m, None).unwrap();
            let later = fit::Setup {
                base: c,
                clean,
                spread: s.spread.clone(),
                known: s.known.clone(),
                ..*s
            };
            pair.extend(fit_effects(&later, &[by("depth_offset")], &mut |_| {}));
            let refit = fit::refit_jointly(s, &fit::named(&pair).unwrap()).unwrap();
            for (a, (values, ci)) in pair.iter_mut().zip(refit) {
                for ((_, v), new) in a.parameters.iter_mut().zip(values) {
                    *v = new;
                }
                for ((_, old), new) in a.ci95.iter_mut().zip(ci) {
                    *old = new;
                }
            }
            pair
        };
        with_truth(
            |c| c.sensors.depth.errors.bias += 0.05,
            |s| {
                let named = pair(s);
                assert!(named[1].guards.all(), "{:?}", named[1].guards);
                let named_with = [vec![2.0], named[1].values()];
                let kept = drop_redundant(s, &named, &named_with, None)
                    .unwrap()
                    .expect("a name dropped");
                assert_eq!(kept.accepted.len(), 1);
                assert_eq!(kept.accepted[0].name, "depth_offset");
                assert_eq!(kept.dropped.len(), 1);
                assert_eq!(
                    (kept.dropped[0].round, kept.dropped[0].name.as_str()),
                    (0, "compass_offset")
                );
                assert!(
                    kept.dropped[0].why.contains("`depth_offset`"),
                    "{}",
                    kept.dropped[0].why
                );
                assert!(
                    kept.dropped[0].why.contains("2.0000"),
                    "{}",
                    kept.dropped[0].why
                );
                let as_fitted: Vec<Vec<f64>> = named.iter().map(Candidate::values).collect();
                assert!(
                    drop_redundant(s, &named, &as_fitted, None)
                        .unwrap()
                        .is_none(),
                    "an interval about zero without a collapse"
                );
                let alone = drop_redundant(s, &named[..1], &named_with[..1], Some(&named[1]))
                    .unwrap()
                    .expect("dropped beside the look-alike");
                assert!(alone.accepted.is_empty());
                assert!(
                    drop_redundant(s, &named[..1], &named_with[..1], None)
                        .unwrap()
                        .is_none(),
                    "a name alone is not asked"
                );
            },
        );
        with_truth(
            |c| {
                c.sensors.depth.errors.bias += 0.05;
                c.sensors.compass.errors.bias += 4.0;
            },
            |s| {
                let named = pair(s);
                let (compass, depth) = (named[0].values()[0], named[1].values()[0]);
                assert!((3.0..5.0).contains(&compass), "{compass}");
                assert!((0.03..0.07).contains(&depth), "{depth}");
                let named_with: Vec<Vec<f64>> = named.iter().map(Candidate::values).collect();
                assert!(
                    drop_redundant(s, &named, &named_with, None)
                        .unwrap()
                        .is_none()
                );
            },
        );
    }

    /// An interval holds zero only where every parameter's does; the least supported name is
    /// the one whose values lie deepest inside their intervals.
    #[test]
    fn a_name_holds_no_effect_only_where_every_interval_holds_zero() {
        assert!(holds_zero(&[[-0.1, 0.2]]));
        assert!(holds_zero(&[[-0.1, 0.2], [0.0, 1.0]]));
        assert!(!holds_zero(&[[-0.1, 0.2], [0.1, 1.0]]));
        assert!(!holds_zero(&[]));
        assert!(support(&[0.05], &[[-0.1, 0.2]]) < support(&[0.09], &[[-0.1, 0.28]]));
        assert!(support(&[0.5], &[[0.1, 0.9]]) > 1.0);
        assert!(support(&[-0.5], &[[-0.9, -0.1]]) > 1.0);
    }
}

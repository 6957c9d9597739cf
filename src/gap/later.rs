//! The rules an effect named after others must pass before it is taken into the model.
//!
//! A hidden effect found first drives the model where the calibration's runs did not take it,
//! and what the library's form of that effect lacks shows as disagreement another effect can
//! take in part. These rules tell a second real effect from such a stand-in by what the earlier
//! names left: its share of the excess, where its drop lies against the channels' known
//! levels, and whether a channel it moves is still off.

use super::candidate::{self, Candidate};
use super::effects::{self, Configs, Kind};
use super::fit;
use super::format::Measurement;
use super::model::GapModel;
use super::residuals::{self, ChannelStats, Known};
use super::{GapError, channel_mean, resim, stats_for};

/// An effect named after others that explains less than this share of the excess of the
/// gap measure's channel mean over 1 the earlier names left is tested for constancy
/// ([`fit::constancy`]): "most" of what is left.
pub const LATER_NAME_MIN_SHARE: f64 = 0.5;

/// An effect named after others must explain at least this share of the excess of the gap
/// measure's channel mean over 1 that the earlier names left, there must be an excess, and it
/// must take the channels down more above their known levels than below them.
///
/// The gap measure counts every channel once, so a true second effect takes a large part of
/// what is left; a name that takes a sliver of it beside a larger rest left unexplained is a
/// symptom of the structure the earlier names exposed (a hull driven where the baseline runs
/// never took it), not a cause of its own.
pub const LATER_NAME_FLOOR_SHARE: f64 = 0.1;

/// A winner in place of one refused because a structural term explains the same
/// disagreement is held to [`LATER_NAME_MIN_SHARE`] where it acts only when its change of the
/// residuals is like that term's: the cosine of the two changes at least this in size, so at
/// least a quarter of the square of its change lies along the term's.
///
/// The refusal says the round's disagreement is where the model's form is loose, and a
/// stand-in for that form changes the residuals as the structural term does. A change at right
/// angles to the term's takes disagreement the structure does not explain: a water current
/// after a 2.1 s thruster lag (structure 666013, seed 611587, pair 3) took 40 % of the track's
/// excess, most of the rest the lag's form (`thruster_lag_shape` refused a `drag_mismatch`),
/// its change at cosine -0.07 to the mismatch's. Such a winner meets the rules every later
/// name meets (its share, the constancy test, its own structural rival).
pub const STAND_IN_COSINE: f64 = 0.5;

/// Whether a winner in place of a refused one is held to most of what is left where it acts:
/// always, unless the refused one gave way to a structural term (`structure`) whose change
/// of the residuals is unlike the winner's ([`STAND_IN_COSINE`]); unknown changes hold it.
pub(crate) fn held_as_stand_in(win: &Candidate, structure: Option<&Candidate>) -> bool {
    let Some(term) = structure else {
        return true;
    };
    let cosine = candidate::change_cosine(win, term);
    tracing::debug!(
        winner = win.name,
        term = term.name,
        ?cosine,
        "a winner in place of one refused for a structural term, its change against the term's"
    );
    cosine.is_none_or(|c| c.abs() >= STAND_IN_COSINE)
}

/// Whether an effect named after `before`, explaining `share` of the excess they left, is
/// asked whether its value follows them ([`fit::constancy`]): a mean effect that explains less
/// than [`LATER_NAME_MIN_SHARE`] of it, or, whatever its share, a sensor effect of a channel a
/// physics effect named before it moves (its signature channels or `also_moves`).
///
/// For a physics effect each sign alone is no proof of a stand-in: on a vehicle of another
/// structure a right effect's value depends on the regime too, and a right effect may be a
/// small part of a disagreement that is mostly structure. A sensor's reading model does not
/// change with where the vehicle goes, while a physics effect named before it drives the hull
/// where the baseline runs did not, and what the calibrated structure lacks there reaches the
/// sensors it moves as a mean error that follows the drive: on structure 746057 (seed 691627)
/// case 37 a thrust gain of -0.44 (82 sigma) left the surge accelerometer at 1.57 of its known
/// level, and an `accel_x_offset` took 66 % of what the gain left, -2.22 LSB where the gain
/// changed the fit most against -1.25 where it changed it least (Wald 15.9 > 6.6). Where the
/// physics name does not move the sensor's channel, the split by its change says nothing of
/// that channel and is not asked: a right depth offset after a yaw damping (structure 770041,
/// seed 715611, pair 5) read -0.47 m in the blocks the damping changed most and 0.14 m
/// elsewhere (Wald 22.1), a depth read at the surface against one read in dives.
pub(crate) fn asks_constancy(
    effect: &effects::Effect,
    before: &[&effects::Effect],
    share: f64,
) -> bool {
    let driven_by_physics = || {
        !effect.physics
            && before
                .iter()
                .any(|e| e.physics && effect.channels.iter().any(|c| moves(e, c)))
    };
    effect.kind == Kind::Mean && (share < LATER_NAME_MIN_SHARE || driven_by_physics())
}

/// In an exchange of an earlier name for its look-alike, each later name is also tried in
/// exchange for this many of its own round's rivals that passed every guard, the strongest
/// first ([`exchange_lookalikes`]).
pub const LATER_RIVALS: usize = 4;

/// Why an effect named after others, with each channel's chi-square over its known level
/// `without` it and `with` it (the terms the gap measure's channel mean averages, channel by
/// channel in the same order), takes too little of what the earlier names left to be named;
/// `None` when it takes enough.
///
/// With the channels' mean at or below 1 nothing is left, even where one channel is off
/// beside channels the model fits better than the calibration's runs: asking that channel
/// whether it is still off ([`nothing_off_that_it_moves`]) let a water current in beside a
/// thruster imbalance on a run of another structure, and named no hidden second effect.
pub(crate) fn too_small_a_share(without: &[f64], with: &[f64]) -> Option<String> {
    let (before, after) = (level_mean(without), level_mean(with));
    if before <= 1.0 {
        return Some(format!(
            "the effects named before it leave the channels' mean chi-square at {before:.3}, \
             at or below the known levels on the samples the fits see (wall contacts left out): \
             no disagreement is left for another effect"
        ));
    }
    // Of the drop the name makes, channel by channel, the part above that channel's known
    // level is the excess it explains; the part below it is disagreement the calibration's
    // own runs show as well. A channel far off beside channels the model fits better than
    // the calibration's runs is an excess, whatever the channels' mean.
    let n = without.len().max(1) as f64;
    let (mut above, mut below) = (0.0, 0.0);
    for (b, a) in without.iter().zip(with) {
        above += (b.max(1.0) - a.max(1.0)) / n;
        below += (b.min(1.0) - a.min(1.0)) / n;
    }
    if below > above {
        return Some(format!(
            "it takes the channels' mean chi-square over their known levels from {before:.3} \
             to {after:.3}: {below:.3} of that below the channels' known levels against \
             {above:.3} above them. It fits more of the disagreement the calibration's own \
             runs show than of what the effects named before it left"
        ));
    }
    let share = (before - after) / (before - 1.0);
    (share < LATER_NAME_FLOOR_SHARE).then(|| {
        format!(
            "it explains {:.0} % of the disagreement the effects named before it left (the \
             channels' mean chi-square over their known levels {before:.3} -> {after:.3}); an \
             effect named after others must explain at least {:.0} %: a sliver beside a larger \
             rest is the structure the earlier names exposed, not a cause of its own",
            100.0 * share,
            100.0 * LATER_NAME_FLOOR_SHARE
        )
    })
}

/// True when `effect` moves `channel`: one of its signature channels or `also_moves`.
pub(crate) fn moves(effect: &effects::Effect, channel: &str) -> bool {
    effect.channels.contains(&channel) || effect.also_moves.contains(&channel)
}

/// The entries of `levels` (named in order by `channels`) of the channels `effect` moves: its
/// signature channels and `also_moves`.
fn where_it_acts(effect: &effects::Effect, channels: &[&str], levels: &[f64]) -> Vec<f64> {
    channels
        .iter()
        .zip(levels)
        .filter(|(c, _)| moves(effect, c))
        .map(|(_, x)| *x)
        .collect()
}

/// [`too_small_a_share`] read in the channels `effect` moves alone (`channels` naming the
/// entries of `without` and `with` in order): a later name must also take a real share of what
/// is left where it acts. Read over every channel, an excess it does not touch hides that it
/// takes only what the calibration's own runs show where it does: an `accel_y_offset` after a
/// thruster imbalance, its own channel at 0.953 of its known level, or an imbalance after a
/// water current that takes 10 % of the whole run's excess and 9.8 % of its own channels'
/// (heading made worse for track). `None` when it takes enough, or moves no channel measured.
pub(crate) fn too_small_where_it_acts(
    effect: &effects::Effect,
    channels: &[&str],
    without: &[f64],
    with: &[f64],
) -> Option<String> {
    let (before, after) = (
        where_it_acts(effect, channels, without),
        where_it_acts(effect, channels, with),
    );
    if before.is_empty() {
        return None;
    }
    let moved: Vec<&str> = channels
        .iter()
        .copied()
        .filter(|c| moves(effect, c))
        .collect();
    too_small_a_share(&before, &after)
        .map(|why| format!("in the channels it moves ({}), {why}", moved.join(", ")))
}

/// The least share of what the earlier names left that a later name must explain
/// ([`LATER_NAME_FLOOR_SHARE`]), by its kind, with why it falls short; `channels` names the
/// levels' entries in order (`None`: they are not the channels one by one).
///
/// A mean effect is read over every channel ([`too_small_a_share`], unless
/// `excess_only_where_it_acts`: then the whole run holds no excess and it is judged where it
/// acts alone) and over the channels it moves ([`too_small_where_it_acts`]). A noise source is
/// read in the channel it moves alone: what it explains there is what its floor takes of that
/// channel's excess, and the whole run's mean counts channels its floor cannot reach. A hull
/// the earlier names drive harder moves its depth reading more between samples while the
/// stern thruster works, an excess that follows the duty as an EMI's does, and a noise source
/// named for it takes a sliver of what the depth channel holds (bridge seed 203381, cases
/// 35-37: 7-8 % after a thrust gain, against 20 % for a hidden EMI named after a hard iron,
/// case 72).
pub(crate) fn too_small_later_share(
    effect: &effects::Effect,
    channels: Option<&[&str]>,
    without: &[f64],
    with: &[f64],
    excess_only_where_it_acts: bool,
) -> Option<String> {
    let where_it_acts =
        || channels.and_then(|names| too_small_where_it_acts(effect, names, without, with));
    match effect.kind {
        Kind::Mean => {
            let whole = if excess_only_where_it_acts {
                None
            } else {
                too_small_a_share(without, with)
            };
            whole.or_else(where_it_acts)
        }
        Kind::Variance => where_it_acts(),
    }
}

/// The share an effect explains of the excess over the known levels left in the channels it
/// moves (its signature channels and `also_moves`): those channels' mean chi-square over their
/// known levels `without` it and `with` it, `channels` naming the entries in order. 0 where
/// nothing is left there.
///
/// A winner in place of one refused in its round is held to this share: the refusal says the
/// round's disagreement is where the model's form is loose, and a stand-in for that form takes
/// a small part of the disagreement where it acts. An effect that acts elsewhere (a paddle-wheel
/// scale beside a depth channel a thruster lag's form left off) is judged on its own channels.
pub(crate) fn share_where_it_acts(
    effect: &effects::Effect,
    channels: &[&str],
    without: &[f64],
    with: &[f64],
) -> f64 {
    let before = level_mean(&where_it_acts(effect, channels, without));
    let after = level_mean(&where_it_acts(effect, channels, with));
    if before > 1.0 {
        (before - after) / (before - 1.0)
    } else {
        0.0
    }
}

/// Why an effect named first fits only what the calibration's own runs show where it acts:
/// the channels it moves (its signature channels and `also_moves`) hold no excess, their mean
/// chi-square over their known levels `without` it at or below 1 (`channels` naming the
/// entries of `without` in order). `None` when they hold one, or it moves no re-simulated
/// channel measured (a sonar effect: a sonar channel's level is its echoes' likelihood).
///
/// The whole run's excess says nothing of the channels a first name fits: on a null run of a
/// vehicle of another structure, an accelerometer gain took its channel from 0.850 to 0.836 of
/// its known level while the track and compass held the run's excess, and was named. Where its
/// channels do hold an excess, a first name's drop is not split above and below their levels as
/// a later name's is: a weak true effect fits part of the known disagreement beside its own
/// (a sway-yaw coupling of 1.7 sigma on bridge seed 141209, case 60: 0.139 below against 0.101
/// above).
pub(crate) fn first_name_without_excess(
    effect: &effects::Effect,
    channels: &[&str],
    without: &[f64],
) -> Option<String> {
    if channels.len() != without.len() {
        return None;
    }
    // The re-simulated channels' levels are chi-square over a known level; a sonar channel's
    // is the likelihood of its echoes, whose level says nothing of an excess.
    let (moved, before): (Vec<&str>, Vec<f64>) = channels
        .iter()
        .zip(without)
        .filter(|(c, _)| moves(effect, c) && resim::MODELLED.contains(c))
        .map(|(c, x)| (*c, *x))
        .unzip();
    if before.is_empty() {
        return None;
    }
    let moved = moved.join(", ");
    let mean = level_mean(&before);
    (mean <= 1.0).then(|| {
        format!(
            "the channels it moves ({moved}) hold no disagreement beyond their known levels \
             (their mean chi-square over those levels {mean:.3}): what it would fit is \
             disagreement the calibration's own runs show"
        )
    })
}

/// True when the earlier names leave the whole run at or below its known levels while the
/// channels `effect` moves (its signature channels and `also_moves`) still hold an excess:
/// `without` holds each channel's chi-square over its known level, `channels` naming them in
/// order. Channels the model fits better than the calibration's runs hide that excess in the
/// run's mean: a water current's track at 4.1 times its known level once a paddle-wheel scale
/// is named, beside six channels at 0.14 to 1.1 and a mean of 0.93. Such a name is judged in
/// the channels it moves instead of refused for "nothing left".
pub(crate) fn excess_only_where_it_acts(
    effect: &effects::Effect,
    channels: &[&str],
    without: &[f64],
) -> bool {
    let there = where_it_acts(effect, channels, without);
    channels.len() == without.len()
        && level_mean(without) <= 1.0
        && !there.is_empty()
        && level_mean(&there) > 1.0
}

fn level_mean(levels: &[f64]) -> f64 {
    levels.iter().sum::<f64>() / levels.len().max(1) as f64
}

/// Why an effect named first is what the calibration's own runs show where it acts, judged on
/// the channels it moves (`channels` naming the entries of `without` and `with` in order,
/// with the model as given, `start`):
/// - explaining less than [`LATER_NAME_MIN_SHARE`] of the excess over the known levels there,
///   when none of those channels is off by more than runs with nothing new are
///   ([`nothing_off_that_it_moves`]). The rule a later name meets: on a null run of structure
///   322133 (seed 267713, case 65) the depth channel sat at 2.36 of its known level, under
///   what the calibration's runs scatter to, and a `depth_offset` of 0.018 m took it to 2.06
///   and was named.
/// - explaining most of it, when moreover those channels together are not off by more than
///   runs with nothing new are ([`off_together`]). Such a name fits the excess the run shows
///   where it acts, and a run with nothing new shows one too: a `thrust_curve` took 130 % and
///   260 % of the excess of two null runs of structures 882247 and 886259 (seed 827817, case
///   66; seed 831829, case 69), its eight channels at -1.0 to 1.5 sigma of how the
///   calibration's runs scatter, and tied with a thrust gain. A real effect spread over the
///   channels it moves leaves each within its own bound but all of them high together: a thrust
///   gain of 19.6 sigma on structure 814069 (seed 759647, case 39), its channels 3.7 sigma off
///   together, none off alone.
///
/// `None` when it is not: a channel it moves is off, alone or with the others, or it moves no
/// re-simulated channel (a sonar effect).
#[allow(clippy::too_many_arguments)]
pub(crate) fn first_name_within_the_scatter(
    model: &GapModel,
    m: &Measurement,
    effect: &effects::Effect,
    channels: &[&str],
    without: &[f64],
    with: &[f64],
    start: &Configs,
    floors: &[Option<resim::Floor>],
    weights: &[f64],
) -> Result<Option<String>, GapError> {
    if channels.len() != without.len() || channels.len() != with.len() {
        return Ok(None);
    }
    // The re-simulated channels alone, as `first_name_without_excess` reads them: a sonar
    // channel's level is the likelihood of its echoes, whose level says nothing of an excess.
    let (mut kept, mut before, mut after) = (Vec::new(), Vec::new(), Vec::new());
    for ((c, b), a) in channels.iter().zip(without).zip(with) {
        if resim::MODELLED.contains(c) {
            kept.push(*c);
            before.push(*b);
            after.push(*a);
        }
    }
    if where_it_acts(effect, &kept, &before).is_empty() {
        return Ok(None);
    }
    let share = share_where_it_acts(effect, &kept, &before, &after);
    let most = share >= LATER_NAME_MIN_SHARE;
    let judged = if most {
        Judged::AloneOrTogether
    } else {
        Judged::Alone
    };
    let why = nothing_off_that_it_moves(model, m, effect, start, floors, weights, judged)?;
    Ok(why.map(|why| {
        format!(
            "named first, it explains {:.0} % of the excess over the known levels in the \
             channels it moves, and {why}",
            100.0 * share
        )
    }))
}

/// Rescores the candidates of a later round that the earlier names may have left too little
/// of their own: those that passed every guard fitted alone the round before (`previous`) and
/// now pass their signature, their held-out blocks and their bounds but not their
/// significance or their interval, fitted with the earlier names (`accepted`) held. Each is
/// fitted again with those names free ([`fit::with_earlier_free`]) and the round ranked anew.
/// A sensor effect that now fails more, and stands where an earlier sensor name stands (a
/// look-alike of its kind on a shared channel, [`candidate::of_its_kind`]: a depth gain beside
/// a depth offset), is judged on its held-out blocks and signature again too, on a joint fit
/// ([`fit::judged_with_earlier_free`]). Two sensor effects of one channel are two terms of one
/// reading model, which the data fix where the quantity read takes more than one value. Two
/// physics look-alikes are not asked: on a vehicle of another structure, the second takes the
/// dynamics the calibrated base does not have at the operating point the first moved it to (a
/// thrust curve beside a thrust gain, on a run with a thrust gain alone hidden).
/// `setup` makes the setup of the model without the named effects, asked for only when a
/// candidate is rescored.
pub(crate) fn rescore_with_earlier_free<'a>(
    results: &mut [Candidate],
    previous: &[Candidate],
    accepted: &[Candidate],
    setup: impl FnOnce() -> Result<fit::Setup<'a>, GapError>,
) -> Result<(), GapError> {
    use rayon::prelude::*;
    let strong_alone = |name: &str| {
        previous
            .iter()
            .any(|p| p.name == name && p.testable && p.guards.all())
    };
    let held_back = |c: &Candidate| {
        let g = c.guards;
        c.testable
            && g.signature
            && g.heldout == Some(true)
            && g.inside_bounds
            && !(g.significant && g.interval_excludes_zero)
            && strong_alone(&c.name)
    };
    let sensor = |name: &str| effects::by_name(name).is_some_and(|e| !e.physics);
    let beside_earlier = |c: &Candidate| {
        c.testable
            && !c.guards.all()
            && !held_back(c)
            && strong_alone(&c.name)
            && sensor(&c.name)
            && accepted
                .iter()
                .any(|a| sensor(&a.name) && candidate::of_its_kind(c, a))
    };
    if accepted.is_empty() || !results.iter().any(|c| held_back(c) || beside_earlier(c)) {
        return Ok(());
    }
    let setup = setup()?;
    let named = fit::named(accepted)?;
    results
        .par_iter_mut()
        .filter(|c| held_back(c) || beside_earlier(c))
        .for_each(|c| {
            if held_back(c) {
                fit::with_earlier_free(&setup, &named, c);
            } else {
                fit::judged_with_earlier_free(&setup, &named, c);
            }
        });
    candidate::rank(results);
    Ok(())
}

/// Why an effect named after others finds no disagreement of its own left: with the
/// earlier names in the model (`earlier`), none of the channels it moves (its signature
/// channels and `also_moves`) is significantly off: its chi-square over its known level beyond
/// the noise, and over the bound a run with nothing new stays under in those channels judged
/// together ([`GapModel::run_bound_among`]). `None` when one is.
///
/// Asked of a later name that explains less than [`LATER_NAME_MIN_SHARE`] of what the earlier
/// ones left. Where they leave every channel it moves within what the calibration's runs show,
/// what such a name fits is that known disagreement: on a vehicle of another structure, the
/// mean surge acceleration a chattering depth hold makes once a depth EMI is named (an
/// `accel_x_offset` taking 10 % of what the EMI left, its channel at 2.95 against a known
/// 2.66). A name that explains most of what is left is not asked: spread over several
/// channels, a real effect can leave each within its run bound (a compass latency after a
/// depth offset, 94 % of what the offset left, with track and heading each under their
/// bounds).
///
/// The question is about the channels the name moves, not about the whole run, so the run
/// bound is the one for those channels together: the report's bound covers every channel at
/// once, and with three runs with nothing new it lies several times over the known level (a
/// paddle-wheel channel at 6.08 against a known 1.65 and a report bound of 6.50, a velocity
/// scale's own channel left off by a thrust gain named before it).
///
/// With [`Judged::AloneOrTogether`] the channels are judged together as well
/// ([`off_together`]): `None` when one is off alone or all are off together.
pub(crate) fn nothing_off_that_it_moves(
    model: &GapModel,
    m: &Measurement,
    effect: &effects::Effect,
    earlier: &Configs,
    floors: &[Option<resim::Floor>],
    weights: &[f64],
    judged: Judged,
) -> Result<Option<String>, GapError> {
    let run = resim::simulate(earlier, m, None)?;
    let stats = stats_for(model, m, earlier, &run, floors, weights);
    let moved = moved_by(effect, &stats);
    // The run bound read against `floors` (`weights`, by channel index:
    // `fit::known_weights`), or as the calibration measured it, whichever is larger. The
    // weight assumes the known disagreement spread evenly over the samples; where it lies
    // where a named noise source leaves the floor as it was (the surfacing with the motors
    // off, for a stern-duty EMI), it keeps its whole size, and a later name fitting it there
    // is a stand-in (a `thrust_curve` after a depth EMI, on every EMI case of structure
    // 306059, seed 251677, once the start depth was read from the data).
    let weight = |channel: &str| {
        m.channels
            .iter()
            .position(|c| c.name == channel)
            .and_then(|i| weights.get(i).copied())
            .unwrap_or(1.0)
    };
    let bound = |s: &ChannelStats| {
        model
            .run_bound_among(&s.channel, moved.len())
            .map(|b| residuals::level_under(b, weight(&s.channel)).max(b))
    };
    let off = |s: &&ChannelStats| {
        let known = Known {
            level: s.known_chi2_per_sample,
            run_bound: bound(s),
        };
        residuals::disagrees(s.chi2_per_sample, s.samples, s.chi2_tau_samples, known)
    };
    if moved.is_empty() || moved.iter().any(off) {
        return Ok(None);
    }
    let jointly = if judged == Judged::AloneOrTogether {
        let Some(t) = off_together(model, &moved) else {
            return Ok(None);
        };
        if t.off() {
            return Ok(None);
        }
        format!(
            ", nor are they together ({:.2} sigma over how those runs scatter, {} channels)",
            t.z, t.channels
        )
    } else {
        String::new()
    };
    let figures = moved
        .iter()
        .map(|s| {
            let bound = bound(s).map_or_else(
                || "no run bound".to_string(),
                |b| format!("run bound {b:.2}"),
            );
            format!(
                "{} {:.2} (known {:.2}, {bound})",
                s.channel, s.chi2_per_sample, s.known_chi2_per_sample
            )
        })
        .collect::<Vec<_>>()
        .join(", ");
    Ok(Some(format!(
        "no channel it moves is off by more than runs with nothing new are (chi-square per \
         sample: {figures}){jointly}: what it would fit is disagreement the calibration's own \
         runs show"
    )))
}

/// How [`nothing_off_that_it_moves`] judges the channels an effect moves.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Judged {
    /// Each channel against its own run bound.
    Alone,
    /// Each against its own run bound, and all of them together ([`off_together`]).
    AloneOrTogether,
}

/// How far the channels an effect moves lie, together, above how the calibration's runs with
/// nothing new scatter in them ([`GapModel::discrepancy_scatter`]).
#[derive(Debug, Clone, Copy, PartialEq)]
pub(crate) struct Together {
    /// Stouffer's combination of the channels' one-sided tails, in standard normal units.
    pub z: f64,
    /// The channels judged: those with a scatter.
    pub channels: usize,
}

impl Together {
    /// Beyond the one-sided [`crate::gap::model::RUN_BOUND_LEVEL`] tail: the channels are off
    /// together.
    pub fn off(&self) -> bool {
        use statrs::distribution::{ContinuousCDF, Normal};
        let q = Normal::standard().inverse_cdf(1.0 - crate::gap::model::RUN_BOUND_LEVEL);
        self.z > q
    }
}

/// The channels of `moved` judged together against how runs with nothing new scatter in each.
/// A channel's log chi-square per sample against the `k` runs' mean and standard deviation of
/// theirs is Student's t with `k - 1` degrees of freedom for one more such run, as
/// [`crate::gap::model::RunScatter::bound`] reads it; each t's one-sided tail is turned into a
/// standard normal quantile and the quantiles combined by Stouffer's method, their sum over the
/// root of their count. A channel high and another low cancel, so an effect that fits a run's
/// scatter finds it no further off than runs with nothing new, however many channels it
/// moves. `None` when no channel it moves has a scatter (a model calibrated on one run).
pub(crate) fn off_together(model: &GapModel, moved: &[&ChannelStats]) -> Option<Together> {
    use statrs::distribution::{ContinuousCDF, Normal, StudentsT};
    let normal = Normal::standard();
    let quantiles: Vec<f64> = moved
        .iter()
        .filter_map(|s| {
            let sc = model.discrepancy_scatter.get(&s.channel)?;
            let k = f64::from(sc.runs);
            if sc.log_sd <= 0.0 || s.chi2_per_sample.is_nan() || s.chi2_per_sample <= 0.0 {
                return None;
            }
            let t = (s.chi2_per_sample.ln() - sc.log_mean) / (sc.log_sd * (1.0 + 1.0 / k).sqrt());
            let below = StudentsT::new(0.0, 1.0, k - 1.0).ok()?.cdf(t);
            // The tails clamped where a quantile of the normal stays finite.
            Some(normal.inverse_cdf(below.clamp(1e-15, 1.0 - 1e-15)))
        })
        .collect();
    (!quantiles.is_empty()).then(|| Together {
        z: quantiles.iter().sum::<f64>() / (quantiles.len() as f64).sqrt(),
        channels: quantiles.len(),
    })
}

/// The statistics of the channels `effect` moves: its signature channels and `also_moves`.
fn moved_by<'a>(effect: &effects::Effect, stats: &'a [ChannelStats]) -> Vec<&'a ChannelStats> {
    stats.iter().filter(|s| moves(effect, &s.channel)).collect()
}

/// From this cosine between two changes of the residuals a candidate of an earlier name's
/// round is tried in its place ([`exchange_lookalikes`]): below
/// [`candidate::SAME_CHANGE_COSINE`], at which two fits explain the same disagreement. A
/// first round that takes one of two hidden effects with its look-alike reads the look-alike's
/// change mixed with the other effect's, so the two part further than two fits of one
/// disagreement do: a thrust curve named first for a thrust gain of 29 and 37 sigma beside a
/// yaw damping changed the residuals at cosine 0.86 and 0.81 to the gain's (structures 910361,
/// seed 855931, pair 35; 854163, seed 799711, pair 20). A trial is cheap beside a wrong name,
/// and every exchange is held to its rules (the fit and the channels' mean both better, each
/// exchanged value inside its bounds and clear of zero).
pub const EXCHANGE_COSINE: f64 = 0.8;

/// The named effects after an exchange ([`exchange_lookalikes`]): the candidates, with the
/// joint values, and the configurations with them applied.
pub(crate) struct Exchanged {
    pub accepted: Vec<Candidate>,
    pub configs: Configs,
}

/// An exchange tried: its gain over the named set (BIC cost of extra parameters paid), the
/// summed chi-square and the gap measure's channel mean with it, the names put in (index in
/// the named set, candidate) and the joint refit.
struct Trial {
    gain: f64,
    chi2: (f64, f64),
    swap: Vec<(usize, Candidate)>,
    refit: Vec<fit::Refit>,
}

/// Once two or more effects are named, each earlier name is exchanged for a look-alike of its
/// round where that fits the data better with the later names in: the greedy rounds chose it
/// before the later names changed the model. A look-alike passed every guard in the earlier
/// name's round, is of its kind, shares a signature channel, and changed the residuals as it
/// did (cosine at least [`EXCHANGE_COSINE`]): on a depth hold a depth gain and a
/// depth offset move the reading alike, and which of them fits better can turn once a thrust
/// gain beside them is named. The exchanged set is refitted jointly
/// ([`fit::refit_jointly`]) from the look-alike's round values; it is kept when its
/// chi-square, less the look-alike's extra parameters' BIC cost, is lower by more than
/// [`fit::BIC_MARGIN`], and the look-alike's joint values lie inside its bounds with an
/// interval clear of zero. The later rounds chose with the earlier name in, so beside the
/// look-alike each later name is also tried exchanged for one of its own round's strongest
/// rivals that passed every guard ([`LATER_RIVALS`]), the pair refitted and held to the same
/// rules (each exchanged name's extra parameters paid for, each inside its bounds and clear of
/// zero): a thrust curve named for a thrust gain leaves the yaw damping beside it to a rival
/// the thrust curve's own form wanted. Replacing a variance effect (a depth EMI) is not tried.
///
/// The exchanged set must also bring the model closer to the data by the measure the gap is
/// reported in, every channel counted once: the channels' mean chi-square over their known
/// levels with it lower than with the named set, as every name's must be
/// ([`crate::gap::channel_mean`]). The summed chi-square alone lets a set that fits the
/// many samples of the track and accelerometers better, and the compass worse, take the place
/// of one that fits every channel: on structure 866197 (seed 811733, case 78) a thrust gain
/// and a compass offset, both hidden and both named, were exchanged for a thrust curve and a
/// yaw damping that lowered the summed chi-square by 1457.
///
/// `setup` is the model without any named effect (its `base`); `rounds[i]` holds the round
/// in which `accepted[i]` was named, whose values are the joint ones. `None` when nothing is
/// exchanged.
pub(crate) fn exchange_lookalikes(
    setup: &fit::Setup<'_>,
    rounds: &[Vec<Candidate>],
    accepted: &[Candidate],
) -> Option<Exchanged> {
    if accepted.len() < 2 {
        return None;
    }
    let effect_of = |c: &Candidate| effects::by_name(&c.name);
    let configs_of = |named: &[fit::Named]| {
        let mut c = setup.base.clone();
        for (effect, values, _) in named {
            effects::apply(effect, values, &mut c);
        }
        c
    };
    // The summed chi-square and the gap measure's channel mean.
    let chi2_of = |c: &Configs| -> Option<(f64, f64)> {
        let run = resim::simulate(c, setup.m, None)
            .ok()
            .filter(|r| r.divergences.is_empty())?;
        let r = setup.residuals(c, &run);
        let levels = setup.part_levels(&r, None);
        let mean = channel_mean(levels.into_iter().map(|(i, chi2)| (chi2, setup.known[i])))?;
        Some((r.all_chi2(), mean))
    };
    let mut current = accepted.to_vec();
    let mut named: Vec<fit::Named> = current
        .iter()
        .map(|c| Some((effect_of(c)?, c.values(), c.noise_factor)))
        .collect::<Option<_>>()?;
    // The named set's own joint fit, which the look-alikes' are measured against.
    let mut chi2_now: Option<(f64, f64)> = None;
    let ln_n = setup.n_eff(None).ln();
    let mut exchanged = false;
    for i in 0..current.len() {
        let (earlier, round) = (current[i].clone(), rounds.get(i)?);
        let e = effect_of(&earlier)?;
        if e.kind != Kind::Mean {
            continue;
        }
        let lookalikes = round.iter().filter(|c| {
            c.name != earlier.name
                && current.iter().all(|a| a.name != c.name)
                && c.testable
                && c.guards.all()
                && candidate::of_its_kind(c, &earlier)
                && candidate::change_cosine(c, &earlier).is_some_and(|cos| cos >= EXCHANGE_COSINE)
        });
        let mut best: Option<Trial> = None;
        for look in lookalikes {
            // The look-alike alone in the earlier name's place, and beside it each later name
            // exchanged for a rival that passed every guard in its own round: the later rounds
            // chose with the earlier name in, and with the look-alike there another of their
            // rivals may be the later effect.
            let mut swaps = vec![vec![(i, look)]];
            for (j, later_round) in rounds.iter().enumerate().take(current.len()).skip(i + 1) {
                if effect_of(&current[j]).is_none_or(|e| e.kind != Kind::Mean) {
                    continue;
                }
                let mut rivals: Vec<&Candidate> = later_round
                    .iter()
                    .filter(|c| {
                        c.name != look.name
                            && current.iter().all(|a| a.name != c.name)
                            && c.testable
                            && c.guards.all()
                            && effect_of(c).is_some_and(|e| e.kind == Kind::Mean)
                    })
                    .collect();
                rivals.sort_by(|a, b| {
                    b.delta_bic_uncalibrated
                        .total_cmp(&a.delta_bic_uncalibrated)
                });
                swaps.extend(
                    rivals
                        .into_iter()
                        .take(LATER_RIVALS)
                        .map(|rival| vec![(i, look), (j, rival)]),
                );
            }
            for swap in swaps {
                let (now, mean_now) = match chi2_now {
                    Some(now) => now,
                    None => {
                        if let Some(refit) = fit::refit_jointly(setup, &named) {
                            for ((_, values, _), (new, _)) in named.iter_mut().zip(&refit) {
                                values.clone_from(new);
                            }
                        }
                        let now = chi2_of(&configs_of(&named))?;
                        chi2_now = Some(now);
                        now
                    }
                };
                let mut trial = named.clone();
                let mut extra = 0.0;
                for (k, c) in &swap {
                    let Some(r) = effect_of(c) else { continue };
                    extra += r.parameters.len() as f64 - trial[*k].0.parameters.len() as f64;
                    trial[*k] = (r, c.values(), c.noise_factor);
                }
                let Some(refit) = fit::refit_jointly(setup, &trial) else {
                    continue;
                };
                for ((_, values, _), (new, _)) in trial.iter_mut().zip(&refit) {
                    values.clone_from(new);
                }
                let Some((chi2, mean)) = chi2_of(&configs_of(&trial)) else {
                    continue;
                };
                let gain = now - chi2 - extra * ln_n;
                let shrinks = mean < mean_now;
                let holds = swap.iter().all(|(k, _)| {
                    let (values, ci) = (&refit[*k].0, &refit[*k].1);
                    ci.iter().any(|[lo, hi]| *lo > 0.0 || *hi < 0.0)
                        && effects::inside_bounds(trial[*k].0, values)
                });
                tracing::debug!(
                    earlier = earlier.name,
                    exchanged = ?swap.iter().map(|(_, c)| c.name.as_str()).collect::<Vec<_>>(),
                    gain,
                    holds,
                    mean,
                    mean_now,
                    values = ?swap.iter().map(|(k, _)| &refit[*k].0).collect::<Vec<_>>(),
                    "an earlier name against its look-alike, with the later names in"
                );
                if gain > fit::BIC_MARGIN
                    && holds
                    && shrinks
                    && best.as_ref().is_none_or(|b| gain > b.gain)
                {
                    let swap = swap.iter().map(|(k, c)| (*k, (*c).clone())).collect();
                    best = Some(Trial {
                        gain,
                        chi2: (chi2, mean),
                        swap,
                        refit,
                    });
                }
            }
        }
        let Some(Trial {
            chi2, swap, refit, ..
        }) = best
        else {
            continue;
        };
        for (k, c) in swap {
            named[k] = (effect_of(&c)?, Vec::new(), c.noise_factor);
            current[k] = c;
        }
        for ((c, n), (values, ci)) in current.iter_mut().zip(named.iter_mut()).zip(refit) {
            for ((_, v), new) in c.parameters.iter_mut().zip(&values) {
                *v = *new;
            }
            if !ci.is_empty() {
                for ((_, old), new) in c.ci95.iter_mut().zip(&ci) {
                    *old = *new;
                }
            }
            n.1 = values;
        }
        chi2_now = Some(chi2);
        exchanged = true;
    }
    exchanged.then(|| Exchanged {
        configs: configs_of(&named),
        accepted: current,
    })
}

#[cfg(test)]
mod tests;

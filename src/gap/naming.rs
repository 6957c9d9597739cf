//! Naming a round's winner: the state one analysis's rounds share, and the rules a winner of
//! the greedy selection ([`candidate::select_past_ties`]) is taken into the model by or
//! refused by (`docs/gap.md`, Method, "The guards and the verdicts"). Each rule reads the
//! model with the winner and the earlier names refitted together ([`Winner`]); the first that
//! refuses gives the [`Refusal`], and a winner none refuses is taken in and becomes what the
//! next round fits against.

use std::cell::RefCell;

use crate::gap::candidate::{self, Candidate, Refusal, Refused};
use crate::gap::effects::{self, Configs};
use crate::gap::format::Measurement;
use crate::gap::later::{self, nothing_off_that_it_moves};
use crate::gap::model::{EnabledEffect, GapModel};
use crate::gap::{
    GapError, LATER_NAME_MIN_SHARE, Options, channel_mean, fit, part_channels, resim,
};

/// What the rounds of one analysis share: the data, the model as given and its floor, and the
/// model with the effects accepted so far, which each round fits against and each winner is
/// judged beside.
pub(crate) struct Naming<'s> {
    pub model: &'s GapModel,
    pub m: &'s Measurement,
    pub options: Options,
    pub spread: &'s [EnabledEffect],
    /// The model as given, its re-simulation and its noise floor.
    pub start: &'s Configs,
    pub clean0: &'s resim::Run,
    pub floors: &'s [Option<resim::Floor>],
    /// The first round's setup, against the model as given.
    pub first: &'s fit::Setup<'s>,
    /// The channels [`Naming::levels_of`] reads, in its order.
    pub channel_names: Vec<String>,
    /// The configurations with the effects accepted so far.
    pub configs: RefCell<Configs>,
    /// The model file with the effects accepted so far.
    pub fitted: RefCell<GapModel>,
    /// The noise floor every round is judged against: the model's, and once a noise source
    /// (depth EMI) is named, the model's with it. Against the old floor, the named noise would
    /// stay in the residuals as disagreement for the next round's candidates to fit.
    pub current_floors: RefCell<Vec<Option<resim::Floor>>>,
    /// The configuration `current_floors` is the floor of.
    pub floors_of: RefCell<Configs>,
    /// Each channel's chi-square over its known level with the effects accepted so far, the
    /// terms of the gap measure's mean.
    pub current: RefCell<Vec<f64>>,
    /// The structural terms fitted against a round's model, for every winner judged in it.
    pub rival_fits: RefCell<fit::RivalFits>,
}

/// A winner refitted with the earlier names, as the rules read it.
struct Winner<'a> {
    named: Vec<fit::Named>,
    /// Every named effect's values and intervals, refitted together.
    joint: Vec<(Vec<f64>, Vec<[f64; 2]>)>,
    /// The model with every named effect at its joint values.
    with_it: Configs,
    /// The earlier names as the joint fit has them beside the newest: what a later name is
    /// judged against. Held at their own rounds' values they keep the share of its
    /// disagreement they took before it was in the model (a thruster lag fitted 2.7 s long
    /// where it stood in for a compass latency), and the newest then looks like a stand-in for
    /// what they lack.
    earlier: Configs,
    newest_values: Vec<f64>,
    /// Each channel's chi-square over its known level with it, and the channels' mean with
    /// and without it.
    levels: Vec<f64>,
    mean: f64,
    without: f64,
    /// What it explains of the excess the earlier names left.
    share: f64,
    channel_names: Vec<&'a str>,
    /// A channel without samples is left out of the levels: then the whole run's alone.
    named_in_order: bool,
    /// The earlier names leave the whole run at or below its known levels while the channels
    /// it moves still hold an excess.
    excess_where_it_acts: bool,
    /// The floor and its configuration before a newly named noise source moved them.
    floor_before: Option<(Vec<Option<resim::Floor>>, Configs)>,
}

impl Winner<'_> {
    /// The newest name: its effect and its round's noise factor.
    fn newest(&self) -> Option<(&'static effects::Effect, f64)> {
        self.named.last().map(|(e, _, nf)| (*e, *nf))
    }

    /// The effects named before the newest, the latest first.
    fn before_it(&self) -> Vec<&'static effects::Effect> {
        self.named.iter().rev().skip(1).map(|n| n.0).collect()
    }
}

impl Naming<'_> {
    /// Each channel's known level read against the floor the named noise sources give
    /// ([`fit::known_weights`]): the model's own floor until one is named.
    pub fn noise_weights(&self, now: &[Option<resim::Floor>]) -> Vec<f64> {
        fit::known_weights(self.floors, now)
    }

    /// A round's setup: `base` against `floors` (the current floor) and the known levels read
    /// against it.
    pub fn setup_on<'f>(
        &'f self,
        base: Configs,
        floors: &'f [Option<resim::Floor>],
    ) -> Result<fit::Setup<'f>, GapError> {
        Ok(
            fit::setup(self.m, base, floors, self.options.split, self.spread)?
                .with_known(self.model, &self.noise_weights(floors)),
        )
    }

    /// Each channel's chi-square over its known level for configuration `c` and its
    /// re-simulation `run`.
    pub fn levels_of(&self, c: &Configs, run: &resim::Run) -> Vec<f64> {
        let floors = self.current_floors.borrow();
        let judged = fit::Setup {
            floors: &floors,
            base: self.first.base.clone(),
            clean: self.first.clean.clone(),
            spread: self.first.spread.clone(),
            known: Vec::new(),
            m: self.first.m,
            split: self.first.split,
        }
        .with_known(self.model, &self.noise_weights(&floors));
        part_channels(&judged, c, run, false, None)
            .into_iter()
            .map(|(chi2, known)| chi2 / known.max(1.0))
            .collect()
    }

    /// Takes the newest of `accepted` into the model, or refuses it: [`candidate::Accept`].
    /// Taken in, every accepted effect's values become their joint refit's.
    pub fn accept(
        &self,
        accepted: &mut [Candidate],
        refused_before: &[Refused],
    ) -> Result<Option<Refusal>, GapError> {
        let w = self.winner(accepted)?;
        if let Some(refusal) = self.refusal(&w, accepted, refused_before)? {
            return Ok(Some(refusal));
        }
        let Winner {
            levels,
            joint,
            with_it,
            ..
        } = w;
        *self.current.borrow_mut() = levels;
        for (a, (values, ci)) in accepted.iter_mut().zip(joint) {
            for ((_, v), new) in a.parameters.iter_mut().zip(&values) {
                *v = *new;
            }
            for ((_, old), new) in a.ci95.iter_mut().zip(&ci) {
                *old = *new;
            }
        }
        *self.configs.borrow_mut() = with_it;
        *self.fitted.borrow_mut() = crate::gap::with_named(self.model, accepted)?;
        Ok(None)
    }

    /// The winner refitted with the earlier names, and the gap measure with it.
    fn winner(&self, accepted: &[Candidate]) -> Result<Winner<'_>, GapError> {
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
            floor_before = Some((
                self.current_floors.borrow().clone(),
                self.floors_of.borrow().clone(),
            ));
            let mut noisy = self.start.clone();
            for (effect, values, _) in named.iter().filter(|n| n.0.kind != effects::Kind::Mean) {
                effects::apply(effect, values, &mut noisy);
            }
            let clean = resim::simulate(&noisy, self.m, None)?;
            *self.current_floors.borrow_mut() = resim::noise_floor(&noisy, self.m, &clean)?;
            *self.floors_of.borrow_mut() = noisy;
        }
        if named.len() > 1 {
            let floors = self.current_floors.borrow();
            let setup = self.setup_on(self.start.clone(), &floors)?;
            if let Some(refit) = fit::refit_jointly(&setup, &named) {
                for ((values, ci), (new_values, new_ci)) in joint.iter_mut().zip(refit) {
                    *values = new_values;
                    if !new_ci.is_empty() {
                        *ci = new_ci;
                    }
                }
            }
        }
        let mut with_it = self.start.clone();
        for ((effect, _, _), (values, _)) in named.iter().zip(&joint) {
            effects::apply(effect, values, &mut with_it);
        }
        let mut earlier = self.start.clone();
        let earlier_count = named.len().saturating_sub(1);
        for ((effect, _, _), (values, _)) in named.iter().zip(&joint).take(earlier_count) {
            effects::apply(effect, values, &mut earlier);
        }
        let newest_values = joint.last().map(|(v, _)| v.clone()).unwrap_or_default();
        tracing::debug!(
            joint = ?joint.iter().map(|(v, _)| v).collect::<Vec<_>>(),
            ci95 = ?joint.iter().map(|(_, c)| c).collect::<Vec<_>>(),
            "the named effects' values and intervals, refitted together"
        );
        let run = resim::simulate(&with_it, self.m, None)?;
        let levels = self.levels_of(&with_it, &run);
        let mean_of =
            |levels: &[f64]| channel_mean(levels.iter().map(|&q| (q, 1.0))).unwrap_or(0.0);
        let mean = mean_of(&levels);
        let without = mean_of(&self.current.borrow());
        tracing::debug!(
            effect = named.last().map(|n| n.0.name),
            mean,
            without,
            ?levels,
            before = ?self.current.borrow(),
            "the gap's channel mean with the newest effect"
        );
        let channel_names: Vec<&str> = self.channel_names.iter().map(String::as_str).collect();
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
                        &self.current.borrow(),
                    )
            });
        let share = if without > 1.0 {
            (without - mean) / (without - 1.0)
        } else if let Some((effect, _, _)) = named.last()
            && excess_where_it_acts
        {
            later::share_where_it_acts(effect, &channel_names, &self.current.borrow(), &levels)
        } else {
            1.0
        };
        Ok(Winner {
            named,
            joint,
            with_it,
            earlier,
            newest_values,
            levels,
            mean,
            without,
            share,
            channel_names,
            named_in_order,
            excess_where_it_acts,
            floor_before,
        })
    }

    /// The first rule that refuses the winner, in order.
    fn refusal(
        &self,
        w: &Winner<'_>,
        accepted: &[Candidate],
        refused_before: &[Refused],
    ) -> Result<Option<Refusal>, GapError> {
        if let Some(why) = self.does_not_shrink(w) {
            return Ok(Some(why.into()));
        }
        if let Some(why) = self.first_name_rules(w)? {
            return Ok(Some(why.into()));
        }
        if let Some(why) = self.later_share_rules(w)? {
            return Ok(Some(why.into()));
        }
        if let Some(refusal) = self.in_place_of_a_refused_winner(w, accepted, refused_before) {
            return Ok(Some(refusal));
        }
        if let Some(why) = self.follows_the_earlier_names(w)? {
            return Ok(Some(why.into()));
        }
        self.structural_rival(w, accepted)
    }

    /// A mean effect must bring the model closer to the data by the measure the gap is
    /// reported in, every channel counted once: a fit that buys chi-square in a channel of
    /// many samples with a worse fit of others trades disagreement, as a stand-in for a term
    /// the library lacks does.
    fn does_not_shrink(&self, w: &Winner<'_>) -> Option<String> {
        let (effect, _) = w.newest()?;
        let (mean, without) = (w.mean, w.without);
        (effect.kind == effects::Kind::Mean && mean >= without).then(|| {
            format!(
                "with it, the channels' mean chi-square over their known levels is {mean:.3}, \
                 against {without:.3} without it: it does not shrink the gap"
            )
        })
    }

    /// A first name must find an excess where it acts, as a later one must
    /// ([`later::first_name_without_excess`], [`later::first_name_within_the_scatter`]).
    fn first_name_rules(&self, w: &Winner<'_>) -> Result<Option<String>, GapError> {
        let Some((effect, _)) = w.newest() else {
            return Ok(None);
        };
        if w.named.len() != 1 || effect.kind != effects::Kind::Mean {
            return Ok(None);
        }
        if let Some(why) =
            later::first_name_without_excess(effect, &w.channel_names, &self.current.borrow())
        {
            return Ok(Some(why));
        }
        later::first_name_within_the_scatter(
            self.model,
            self.m,
            effect,
            &w.channel_names,
            &self.current.borrow(),
            &w.levels,
            &w.earlier,
            &self.current_floors.borrow(),
            &self.noise_weights(&self.current_floors.borrow()),
        )
    }

    /// An effect named after others must take at least a tenth of what they left
    /// ([`later::too_small_later_share`]; a noise source refused there leaves the floor as it
    /// was); one judged in the channels it moves must find one of them still off; and one
    /// that explains less than most of what they left must find a disagreement left that runs
    /// with nothing new do not show: a channel it moves still significantly off, by the test
    /// the report's "still off" list uses.
    fn later_share_rules(&self, w: &Winner<'_>) -> Result<Option<String>, GapError> {
        let Some((effect, _)) = w.newest() else {
            return Ok(None);
        };
        if w.named.len() <= 1 {
            return Ok(None);
        }
        let (without, mean, share) = (w.without, w.mean, w.share);
        if let Some(why) = later::too_small_later_share(
            effect,
            w.named_in_order.then_some(&w.channel_names[..]),
            &self.current.borrow(),
            &w.levels,
            w.excess_where_it_acts,
        ) {
            if let Some((floors, of)) = w.floor_before.clone() {
                *self.current_floors.borrow_mut() = floors;
                *self.floors_of.borrow_mut() = of;
            }
            return Ok(Some(why));
        }
        if w.excess_where_it_acts {
            if let Some(why) = self.nothing_off(effect, &w.earlier)? {
                return Ok(Some(format!(
                    "the effects named before it leave the channels' mean chi-square at \
                     {without:.3}, at or below the known levels, and {why}"
                )));
            }
            tracing::debug!(
                effect = effect.name,
                without,
                share,
                "a later name judged in the channels it moves: the whole run at or below its \
                 known levels, those channels above theirs"
            );
        }
        if effect.kind == effects::Kind::Mean
            && share < LATER_NAME_MIN_SHARE
            && let Some(why) = self.nothing_off(effect, &w.earlier)?
        {
            return Ok(Some(format!(
                "it explains {:.0} % of the disagreement the effects named before it left (the \
                 channels' mean chi-square over their known levels {without:.3} -> {mean:.3}), \
                 and {why}",
                100.0 * share
            )));
        }
        Ok(None)
    }

    /// [`nothing_off_that_it_moves`] against the current floor.
    fn nothing_off(
        &self,
        effect: &effects::Effect,
        earlier: &Configs,
    ) -> Result<Option<String>, GapError> {
        nothing_off_that_it_moves(
            self.model,
            self.m,
            effect,
            earlier,
            &self.current_floors.borrow(),
            &self.noise_weights(&self.current_floors.borrow()),
            later::Judged::Alone,
        )
    }

    /// A winner in place of one refused in the same round must explain most of what is left
    /// in the channels it moves ([`later::share_where_it_acts`]), unless the refused one gave
    /// way to a structural term the winner changes the residuals unlike
    /// ([`later::held_as_stand_in`]). Held as a stand-in for that term, it is refused for the
    /// disagreement the term explains: the refusal repeats the first ([`Refusal::repeats`]),
    /// and the round's next candidate is judged on its own.
    fn in_place_of_a_refused_winner(
        &self,
        w: &Winner<'_>,
        accepted: &[Candidate],
        refused_before: &[Refused],
    ) -> Option<Refusal> {
        let (effect, _) = w.newest()?;
        let first = refused_before.first()?;
        let win = accepted.last()?;
        if effect.kind != effects::Kind::Mean
            || !later::held_as_stand_in(win, first.structure.as_deref())
        {
            return None;
        }
        let share = if w.named_in_order {
            later::share_where_it_acts(effect, &w.channel_names, &self.current.borrow(), &w.levels)
        } else {
            w.share
        };
        if share >= LATER_NAME_MIN_SHARE {
            return None;
        }
        let there = if w.named_in_order {
            "in the channels it moves"
        } else {
            "in the channels"
        };
        let why = format!(
            "it takes the place of `{}`, refused in the same round, and explains only {:.0} % of \
             the disagreement left {there} (their mean chi-square over their known levels); in \
             place of a refused winner an effect must explain most of it ({:.0} %)",
            first.name,
            100.0 * share,
            100.0 * LATER_NAME_MIN_SHARE
        );
        Some(if first.structure.is_some() {
            Refusal::repeating(why)
        } else {
            why.into()
        })
    }

    /// An effect named after others is refused as a stand-in when its value follows them
    /// (asked as [`later::asks_constancy`] says): where they act strongly they drive the model
    /// where the calibration did not take it, and what their form lacks shows as a
    /// disagreement another effect can take in part.
    fn follows_the_earlier_names(&self, w: &Winner<'_>) -> Result<Option<String>, GapError> {
        let Some((effect, noise_factor)) = w.newest() else {
            return Ok(None);
        };
        let (without, mean, share) = (w.without, w.mean, w.share);
        if w.named.len() <= 1 || !later::asks_constancy(effect, &w.before_it(), share) {
            return Ok(None);
        }
        let floors = self.current_floors.borrow();
        let setup = self.setup_on(w.earlier.clone(), &floors)?;
        let now = setup.residuals(&setup.base, &setup.clean);
        let block_s = self.options.split.block_s;
        // Where the earlier names change the fit most against where they change it least;
        // and, after a noise source, where it widens the floor against where it leaves it as
        // it was: it changes no mean, and a stand-in for what it drives (a depth hold
        // chattering on a noisy reading) differs there, not where the means moved least.
        let by_change = fit::strong_blocks(
            &self.first.residuals(self.start, self.clean0),
            &now,
            block_s,
        );
        let mut splits = vec![(
            by_change,
            "blocks where they change the fit most",
            "where they change it least",
        )];
        if w.before_it().iter().any(|e| e.kind != effects::Kind::Mean) {
            splits.push((
                fit::noise_source_blocks(&now, self.floors, &floors, block_s),
                "blocks where the noise source named before it widens the floor",
                "where it leaves the floor as it was",
            ));
        }
        for (strong, there, elsewhere) in splits {
            let test = fit::constancy(&setup, effect, &w.newest_values, noise_factor, &strong);
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
                return Ok(Some(format!(
                    "it explains {:.0} % of the disagreement the effects named before it left \
                     (the channels' mean chi-square over their known levels {without:.3} -> \
                     {mean:.3}), and its value follows them: [{}] in the {} s {there}, [{}] \
                     {elsewhere} (Wald statistic {:.1} > {:.1}, its {:.0} % point). Read it as \
                     what the earlier names' form lacks",
                    100.0 * share,
                    show(&t.strong),
                    block_s,
                    show(&t.weak),
                    t.statistic,
                    t.critical,
                    100.0 * fit::CONSTANCY_LEVEL
                )));
            }
        }
        Ok(None)
    }

    /// A later name is refused for its form when the earlier names changed the vehicle's
    /// dynamics ([`fit::earlier_change_dynamics`]), moved its channels somewhere new, and a
    /// term of the base model's structure explains the same disagreement as well or better
    /// there ([`fit::RivalFits::rival_of`]).
    fn structural_rival(
        &self,
        w: &Winner<'_>,
        accepted: &[Candidate],
    ) -> Result<Option<Refusal>, GapError> {
        let Some((effect, _)) = w.newest() else {
            return Ok(None);
        };
        let Some(win) = accepted.last() else {
            return Ok(None);
        };
        if w.named.len() <= 1
            || effect.kind != effects::Kind::Mean
            || !fit::earlier_change_dynamics(&w.before_it())
        {
            return Ok(None);
        }
        let floors = self.current_floors.borrow();
        let setup = self.setup_on(self.configs.borrow().clone(), &floors)?;
        let unnamed = setup.residuals(self.start, self.clean0);
        if fit::moved_to_new_regime(&setup, &w.before_it(), &unnamed, win)
            && let Some(rival) = self.rival_fits.borrow_mut().rival_of(&setup, win)
        {
            let why = format!(
                "`{}`, a term of the base model's structure, explains the same disagreement as \
                 well or better (delta BIC {:.1} against {:.1}): the earlier names take the \
                 vehicle where the baseline runs did not, and the data do not tell a new effect \
                 from structure those runs left unpinned there",
                rival.name, rival.delta_bic_uncalibrated, win.delta_bic_uncalibrated
            );
            return Ok(Some(candidate::Refusal::of_its_form(why, rival)));
        }
        Ok(None)
    }
}

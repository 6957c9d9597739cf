//! The evaluations of one effect against one setup, kept for the fits that come back to them.
//!
//! A candidate's fits revisit points: the bounded search evaluates a trial point clamped onto
//! a bound again and again while its trust region shrinks, the fit on all the data starts where
//! the training fit ended, both take the Jacobian at "no effect", and the held-out comparison
//! needs the pool contacts of the fitted point's run. A re-simulation is deterministic (no
//! process noise, the same configuration gives the same run), so a point evaluated once is
//! looked up, not re-simulated: the figures are the same, the time is not.

use std::sync::Mutex;

use super::{Residuals, Setup};
use crate::gap::effects::{self, Effect};
use crate::gap::resim;

/// One evaluation of an effect at one point.
#[derive(Debug, Clone)]
pub(super) struct Evaluated {
    pub residuals: Residuals,
    /// The contact intervals of the point's re-simulation ([`resim::Run::contacts`]); `None`
    /// where it is the setup's own run (an effect that leaves the physics alone, or the setup's
    /// configuration itself).
    pub contacts: Option<Vec<[f64; 2]>>,
}

/// Every point one effect was evaluated at against one setup, with its evaluation (`None`:
/// the model could not be evaluated there).
pub(super) struct Evaluations<'s, 'a> {
    setup: &'s Setup<'a>,
    effect: &'static Effect,
    kept: Mutex<Vec<(Vec<f64>, Option<Evaluated>)>>,
}

impl<'s, 'a> Evaluations<'s, 'a> {
    /// Starts with "no effect", whose residuals `r0` the caller has, where the effect at zero
    /// leaves the setup's configuration as it is and its run did not diverge.
    pub fn new(setup: &'s Setup<'a>, effect: &'static Effect, r0: &Residuals) -> Self {
        let zero = vec![0.0; effect.parameters.len()];
        let mut c = setup.base.clone();
        effects::apply(effect, &zero, &mut c);
        let mut kept = Vec::new();
        if c == setup.base && setup.clean.divergences.is_empty() {
            let at_zero = Evaluated {
                residuals: r0.clone(),
                contacts: None,
            };
            kept.push((zero, Some(at_zero)));
        }
        Self {
            setup,
            effect,
            kept: Mutex::new(kept),
        }
    }

    /// The evaluation at `params`: looked up when it was made before, else made and kept.
    pub fn at(&self, params: &[f64]) -> Option<Evaluated> {
        if let Some(found) = self.kept.lock().ok().and_then(|kept| {
            kept.iter()
                .find(|(p, _)| p.as_slice() == params)
                .map(|(_, e)| e.clone())
        }) {
            return found;
        }
        let made = self.setup.evaluate(self.effect, params);
        if let Ok(mut kept) = self.kept.lock() {
            kept.push((params.to_vec(), made.clone()));
        }
        made
    }

    /// Every point evaluated so far, in the order first asked.
    #[cfg(test)]
    pub fn points(&self) -> Vec<Vec<f64>> {
        self.kept
            .lock()
            .map(|kept| kept.iter().map(|(p, _)| p.clone()).collect())
            .unwrap_or_default()
    }
}

impl Setup<'_> {
    /// Residuals with `effect` applied at `params`, and the contacts of its re-simulation.
    pub(super) fn evaluate(&self, effect: &Effect, params: &[f64]) -> Option<Evaluated> {
        let mut c = self.base.clone();
        effects::apply(effect, params, &mut c);
        if self.resimulates(effect) {
            // A trial point under which the run diverges is a failed evaluation: the bounded
            // fit steps back from it.
            let run = resim::simulate(&c, self.m, None)
                .ok()
                .filter(|r| r.divergences.is_empty())?;
            Some(Evaluated {
                residuals: self.residuals(&c, &run),
                contacts: Some(run.contacts),
            })
        } else {
            Some(Evaluated {
                residuals: self.residuals(&c, &self.clean),
                contacts: None,
            })
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::effects::Kind;
    use crate::gap::fit::{Split, setup};

    fn bits(r: &Residuals) -> Vec<u64> {
        r.values.iter().map(|v| v.to_bits()).collect()
    }

    /// What the kept evaluations give is what evaluating again gives, to the bit: "no effect",
    /// which they start with from the setup's own residuals, for every candidate of the library
    /// (the effect at zero leaves the configuration as it is), and any point asked twice,
    /// which is evaluated once.
    #[test]
    fn a_kept_evaluation_is_what_evaluating_again_gives() {
        let (_, c, m) = crate::gap::resim::tests::manoeuvre_of(31, |t| {
            t.sensors.depth.errors.bias += 0.015;
        });
        let clean = resim::simulate(&c, &m, None).unwrap();
        let floors = resim::noise_floor(&c, &m, &clean).unwrap();
        let setup = setup(&m, c, &floors, Split::DEFAULT, &[]).unwrap();
        let r0 = setup.residuals(&setup.base, &setup.clean);
        let mut started_with_zero = 0;
        for effect in effects::candidates().filter(|e| e.kind == Kind::Mean) {
            let kept = Evaluations::new(&setup, effect, &r0);
            let zero = vec![0.0; effect.parameters.len()];
            let seeded = kept.kept.lock().unwrap().len();
            started_with_zero += seeded;
            let again = setup.evaluate(effect, &zero).unwrap();
            let looked_up = kept.at(&zero).unwrap();
            assert_eq!(
                bits(&looked_up.residuals),
                bits(&again.residuals),
                "{}",
                effect.name
            );
            let contacts =
                |e: &Evaluated| e.contacts.clone().unwrap_or(setup.clean.contacts.clone());
            assert_eq!(contacts(&looked_up), contacts(&again), "{}", effect.name);
            let p: Vec<f64> = effect.scales.iter().map(|s| 0.5 * s).collect();
            let first = kept.at(&p).map(|e| bits(&e.residuals));
            let second = kept.at(&p).map(|e| bits(&e.residuals));
            let fresh = setup.evaluate(effect, &p).map(|e| bits(&e.residuals));
            assert_eq!(first, fresh, "{}", effect.name);
            assert_eq!(second, fresh, "{}", effect.name);
            assert_eq!(
                kept.kept.lock().unwrap().len(),
                2,
                "{}: each point once",
                effect.name
            );
        }
        assert!(started_with_zero > 0);
    }
}

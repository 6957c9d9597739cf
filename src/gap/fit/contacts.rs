//! Where a fit leaves out the samples of a wall contact beyond those its setup's base run left
//! out: the contacts of another run (a trained point's, for its held-out comparison), and those
//! of a search's start point ([`search_contacts`]).

use std::borrow::Cow;

use nalgebra::DVector;

use super::{Residuals, Setup, memo};
use crate::gap::resim;

/// `r` with every sample where a run with `contacts` touched the pool ([`resim::Run::in_contact`]) set
/// to zero, as the setup leaves out those where its base run touched; `r` itself, uncopied, when
/// there are none.
pub(crate) fn left_out_where_touched<'r>(
    r: &'r Residuals,
    contacts: Option<&[[f64; 2]]>,
) -> Cow<'r, Residuals> {
    let Some(contacts) = contacts.filter(|c| !c.is_empty()) else {
        return Cow::Borrowed(r);
    };
    let mut r = r.clone();
    for ((v, t), memory_s) in r.values.iter_mut().zip(&r.times).zip(&r.memory_s) {
        if resim::touching(contacts, *t, *memory_s) {
            *v = 0.0;
        }
    }
    Cow::Owned(r)
}

/// A run's `contacts` when they are not the setup's base run's: what a fit leaves out beside
/// what the base leaves out, or `None`.
pub(super) fn beyond_base(
    setup: &Setup<'_>,
    contacts: Option<Vec<[f64; 2]>>,
) -> Option<Vec<[f64; 2]>> {
    contacts.filter(|c| *c != setup.clean.contacts)
}

/// Where the best of `starts` (by the chi-square of its `select`ed residuals) touches the pool
/// and the setup's base run does not: the samples a fit's search leaves out beside the base's.
/// A start away from "no effect" can ride a wall the base does not reach, and there a step far
/// below the Jacobian's moves the first touch by a physics step and the chi-square by hundreds
/// (one accelerometer sample at the impulse): on a vehicle riding a wall, a hard iron's search
/// stopped on its scan start and the tilt of the field was named in its place.
pub(super) fn search_contacts(
    setup: &Setup<'_>,
    starts: &[DVector<f64>],
    at: impl Fn(&DVector<f64>) -> Option<memo::Evaluated>,
    select: impl Fn(&Residuals) -> DVector<f64>,
) -> Option<Vec<[f64; 2]>> {
    let best = starts
        .iter()
        .filter_map(|x| {
            let e = at(x)?;
            Some((select(&e.residuals).norm_squared(), e))
        })
        .min_by(|a, b| a.0.total_cmp(&b.0));
    beyond_base(setup, best.and_then(|(_, e)| e.contacts))
}

//! Where a fit leaves out the samples of a wall contact beyond those its setup's base run left
//! out: the contacts of another run (a trained point's, for its held-out comparison), and those
//! of a search's start point ([`search_contacts`]).

use nalgebra::DVector;

use super::{Residuals, Setup, memo};
use crate::gap::resim;

/// `r` with every sample where a run with `contacts` touched the pool ([`resim::Run::in_contact`]) set
/// to zero, as the setup leaves out those where its base run touched.
pub(crate) fn left_out_where_touched(r: &Residuals, contacts: Option<&[[f64; 2]]>) -> Residuals {
    let mut r = r.clone();
    if let Some(contacts) = contacts {
        for (v, t) in r.values.iter_mut().zip(&r.times) {
            if resim::touching(contacts, *t) {
                *v = 0.0;
            }
        }
    }
    r
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
    starts
        .iter()
        .filter_map(|x| {
            let e = at(x)?;
            Some((select(&e.residuals).norm_squared(), e))
        })
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .and_then(|(_, e)| e.contacts)
        .filter(|contacts| *contacts != setup.clean.contacts)
}

//! Wall contacts in the scores: samples where a run touched the pool are left out of the
//! held-out comparison and of a channel's level.

use super::*;

/// A trial point that drives the model into a wall in a held-out block makes its readings jump
/// there as contact impulses do; left out where that run touched, the held-out comparison sees
/// the gain the point makes everywhere else, and outside the contact nothing is left out.
#[test]
fn held_out_samples_where_the_trial_run_touches_are_left_out() {
    // Long enough that the contact's memory ends before the run does.
    let times: Vec<f64> = (0..1200).map(|i| f64::from(i) * 0.1).collect();
    let split = Split::DEFAULT;
    let before = Residuals {
        values: vec![2.0; times.len()],
        owner: vec![0; times.len()],
        training: times.iter().map(|t| split.is_training(*t)).collect(),
        times: times.clone(),
        memory_s: vec![crate::gap::run::CONTACT_MEMORY_S; times.len()],
    };
    // The trial point halves every residual but the contact's, 31-33 s in a held-out block.
    let mut after = before.clone();
    for (v, t) in after.values.iter_mut().zip(&times) {
        *v = if (31.0..33.0).contains(t) { 60.0 } else { 1.0 };
    }
    assert!(
        before.chi2(false) < after.chi2(false),
        "the contact makes the held-out worse"
    );
    let run = Run::touched_at(vec![[31.0, 33.0]], crate::gap::run::CONTACT_MEMORY_S);
    let (b, a) = (
        left_out_where_touched(&before, Some(&run.contacts)),
        left_out_where_touched(&after, Some(&run.contacts)),
    );
    assert!(b.chi2(false) > a.chi2(false), "left out, the gain shows");
    let kept = |r: &Residuals| r.values.iter().filter(|v| **v != 0.0).count();
    let memory = (crate::gap::run::CONTACT_MEMORY_S * 10.0) as usize;
    let lead = (crate::gap::run::CONTACT_LEAD_S * 10.0) as usize;
    assert_eq!(
        kept(&b),
        times.len() - lead - 20 - memory,
        "the contact, its lead and its memory only"
    );
    assert_eq!(left_out_where_touched(&after, None).values, after.values);
}

/// A channel's level is its chi-square per independent sample over the samples the fits see:
/// where the base re-simulation touched the pool the residuals are zeros, left out of the
/// count as well as the sum. Counted, a run whose contacts take half a channel's samples read
/// that channel at half its level, and a later effect was refused for "no disagreement left".
#[test]
fn a_level_leaves_the_contact_samples_out_of_its_count() {
    let (_, c, m) = crate::gap::resim::tests::manoeuvre_of(31, |t| {
        t.sensors.depth.errors.bias += 0.015;
    });
    let clean = resim::simulate(&c, &m, None).unwrap();
    let floors = resim::noise_floor(&c, &m, &clean).unwrap();
    let mut setup = setup(&m, c.clone(), &floors, Split::DEFAULT, &[]).unwrap();
    let free = setup.part_levels(&setup.residuals(&c, &clean), None);
    let end = m.experiment.duration_s;
    // A contact from the start to well past half the run, every channel's memory included.
    setup.clean.contacts = vec![[0.0, 0.6 * end]];
    let r = setup.residuals(&c, &clean);
    let touched = setup.part_levels(&r, None);
    for (i, level) in &touched {
        let name = &m.channels[*i].name;
        let tau = floors[*i].as_ref().unwrap().tau;
        let (sum, n) = r
            .values
            .iter()
            .zip(&r.owner)
            .zip(&r.times)
            .filter(|((_, o), t)| **o == *i && !setup.clean.in_contact(**t, name))
            .fold((0.0, 0.0), |(s, n), ((v, _), _)| (s + v * v, n + 1.0));
        assert!(n > 0.0, "{name}: samples are left after the contact");
        let expected = sum / (n / tau);
        assert!(
            (level - expected).abs() <= 1e-12 * expected.max(1.0),
            "{name}: level {level} against {expected} over the samples left in"
        );
    }
    let left_out = r.values.iter().filter(|v| **v == 0.0).count();
    assert!(
        left_out * 2 > r.values.len(),
        "the contact leaves out most samples ({left_out} of {})",
        r.values.len()
    );
    assert!(!touched.is_empty() && touched.len() <= free.len());
}

//! Tests of the joint fits: a later candidate fitted with the earlier names free, and a sensor
//! look-alike judged on a joint fit.

use crate::gap::effects;
use crate::gap::fit::{Split, fit_effects, judged_with_earlier_free, setup, with_earlier_free};
use crate::gap::resim;

/// A later candidate scored with the earlier names free: on a run with a thruster lag and a
/// compass latency both hidden, an earlier name that took part of the later one's share
/// (a lag fitted alone too long, as on a vehicle of another structure, where a lag stood in
/// for a compass latency 2.7 s long) leaves the latency, fitted with the lag held there, short
/// of its truth and explaining less. Fitted with the lag free, the latency explains more, its
/// value and interval take back its share, and the lag moves toward its truth.
#[test]
fn a_later_candidate_fitted_with_the_earlier_names_free_takes_back_its_share() {
    let (lag_s, latency_s) = (0.5, 0.5);
    let lag = effects::by_name("thruster_lag").unwrap();
    let latency = effects::by_name("sensor_latency").unwrap();
    let (_, c, m) = crate::gap::resim::tests::manoeuvre_of(13, |t| {
        effects::apply(lag, &[lag_s], t);
        effects::apply(latency, &[latency_s], t);
    });
    let clean = resim::simulate(&c, &m, None).unwrap();
    let floors = resim::noise_floor(&c, &m, &clean).unwrap();
    let first = setup(&m, c.clone(), &floors, Split::DEFAULT, &[]).unwrap();
    let named = fit_effects(&first, &[lag], &mut |_| {}).remove(0);
    assert!(named.guards.all(), "{:?}", named.guards);
    let too_long = 2.0 * lag_s;
    let mut held = c.clone();
    effects::apply(lag, &[too_long], &mut held);
    let second = setup(&m, held, &floors, Split::DEFAULT, &[]).unwrap();
    let mut later = fit_effects(&second, &[latency], &mut |_| {}).remove(0);
    let held_bic = later.delta_bic;
    let held_value = later.values()[0];
    let earlier = [(lag, vec![too_long], named.noise_factor)];
    assert!(
        with_earlier_free(&first, &earlier, &mut later),
        "not rescored: held delta BIC {held_bic:.1}, latency {held_value:.3}"
    );
    let free_value = later.values()[0];
    let ci = later.ci95[0].1;
    let refitted_lag = later.refitted[0].values[0];
    assert!(
        later.delta_bic > held_bic,
        "{} <= {held_bic}",
        later.delta_bic
    );
    assert!(
        (free_value - latency_s).abs() < (held_value - latency_s).abs(),
        "latency {free_value:.3} free, {held_value:.3} held (truth {latency_s})"
    );
    assert!(ci[0] <= latency_s && latency_s <= ci[1], "{ci:?}");
    assert!(later.guards.interval_excludes_zero, "{ci:?}");
    assert!(
        (refitted_lag - lag_s).abs() < (too_long - lag_s).abs() / 4.0,
        "lag {refitted_lag:.3} refitted from {too_long} (truth {lag_s})"
    );
}

/// A later candidate the earlier name left nothing of its own, judged on a joint fit: with a
/// depth offset and a depth gain both hidden on a run that visits several depths, the offset
/// fitted alone takes part of the gain's disagreement with its own, and the gain, fitted with
/// that offset held, fails its guards (the rule that rescores only a candidate failing its
/// significance or interval does not ask it). Judged on the joint fit, it passes its held-out
/// blocks and its signature, and its value and interval hold the truth. With no gain hidden,
/// the same judgement does not name one.
#[test]
fn a_look_alike_the_earlier_name_left_nothing_is_judged_on_a_joint_fit() {
    let offset = effects::by_name("depth_offset").unwrap();
    let gain = effects::by_name("depth_gain").unwrap();
    let judged = |gain_truth: f64| {
        let (_, c, m) = crate::gap::resim::tests::manoeuvre_of(17, |t| {
            effects::apply(offset, &[0.1], t);
            effects::apply(gain, &[gain_truth], t);
        });
        let clean = resim::simulate(&c, &m, None).unwrap();
        let floors = resim::noise_floor(&c, &m, &clean).unwrap();
        let first = setup(&m, c.clone(), &floors, Split::DEFAULT, &[]).unwrap();
        let alone = fit_effects(&first, &[offset], &mut |_| {}).remove(0);
        assert!(alone.guards.all(), "{:?}", alone.guards);
        let mut held = c.clone();
        effects::apply(offset, &alone.values(), &mut held);
        let second = setup(&m, held, &floors, Split::DEFAULT, &[]).unwrap();
        let mut later = fit_effects(&second, &[gain], &mut |_| {}).remove(0);
        let held_guards = later.guards;
        let earlier = [(offset, alone.values(), alone.noise_factor)];
        let rescored = judged_with_earlier_free(&first, &earlier, &mut later);
        (alone, held_guards, rescored, later)
    };
    let (alone, held_guards, rescored, later) = judged(0.2);
    assert!(
        !held_guards.signature || held_guards.heldout != Some(true),
        "the held gain fails only its significance or interval: {held_guards:?}"
    );
    assert!(rescored, "not rescored: {:?}", later.guards);
    assert!(later.guards.all(), "{:?}", later.guards);
    let (value, ci) = (later.values()[0], later.ci95[0].1);
    assert!(ci[0] <= 0.2 && 0.2 <= ci[1], "gain {value:.3}, {ci:?}");
    let offset_refitted = later.refitted[0].values[0];
    assert!(
        (offset_refitted - 0.1).abs() < (alone.values()[0] - 0.1).abs(),
        "offset {offset_refitted:.3} refitted, {:.3} alone (truth 0.1)",
        alone.values()[0]
    );
    let (_, _, _, none) = judged(0.0);
    assert!(
        !none.guards.all(),
        "a gain named where none is hidden: {:?}",
        none.ci95
    );
}

use super::*;

mod contacts;

/// The interval guard: an infinite interval, or an estimate whose confidence region holds
/// 0, names nothing; two correlated parameters whose intervals each hold 0 can still be
/// jointly clear of it.
#[test]
fn interval_guard_needs_finite_intervals_and_a_region_clear_of_zero() {
    let one = |x: f64, sd: f64| {
        let ci = [[x - 1.96 * sd, x + 1.96 * sd]];
        let cov = nalgebra::DMatrix::from_element(1, 1, sd * sd);
        interval_excludes_zero(&ci, &DVector::from_element(1, x), Some(&cov), 1.0)
    };
    assert!(one(0.2, 0.05));
    assert!(one(-0.2, 0.05));
    // The null run's thruster imbalance: -0.03 with [-0.58, 0.52].
    assert!(!one(-0.03, 0.28));
    // A variance factor widens the region.
    let cov = nalgebra::DMatrix::from_element(1, 1, 0.01);
    let x = DVector::from_element(1, 0.25);
    assert!(interval_excludes_zero(&[[0.05, 0.45]], &x, Some(&cov), 1.0));
    assert!(!interval_excludes_zero(
        &[[0.05, 0.45]],
        &x,
        Some(&cov),
        4.0
    ));
    assert!(!interval_excludes_zero(
        &[[f64::NEG_INFINITY, f64::INFINITY]],
        &x,
        Some(&cov),
        1.0
    ));
    // Strongly anti-correlated pair: each marginal holds 0, the pair does not.
    let cov = nalgebra::DMatrix::from_row_slice(2, 2, &[1.0, -0.99, -0.99, 1.0]);
    let x = DVector::from_row_slice(&[1.0, 1.0]);
    assert!(interval_excludes_zero(
        &[[-0.96, 2.96], [-0.96, 2.96]],
        &x,
        Some(&cov),
        1.0
    ));
    let x = DVector::from_row_slice(&[1.0, -1.0]);
    assert!(!interval_excludes_zero(
        &[[-0.96, 2.96], [-2.96, 0.96]],
        &x,
        Some(&cov),
        1.0
    ));
}

#[test]
fn split_alternates_blocks() {
    let s = Split { block_s: 10.0 };
    assert!(s.is_training(0.0));
    assert!(s.is_training(9.99));
    assert!(!s.is_training(10.0));
    assert!(!s.is_training(19.9));
    assert!(s.is_training(20.0));
}

/// The blocks where the earlier names changed the fit most: per block, the chi-square
/// without them less the chi-square with them; the blocks at or above the median change
/// (whatever its sign) are strong, every element of a block alike.
#[test]
fn strong_blocks_are_where_the_earlier_names_changed_the_fit_most() {
    let times: Vec<f64> = (0..40).map(|i| f64::from(i) * 0.5).collect();
    let before: Vec<f64> = times
        .iter()
        .map(|t| if *t < 10.0 { 3.0 } else { 1.0 })
        .collect();
    let residuals = |values: Vec<f64>| Residuals {
        owner: vec![0; values.len()],
        training: vec![true; values.len()],
        times: times.clone(),
        memory_s: vec![crate::gap::run::CONTACT_MEMORY_S; values.len()],
        values,
    };
    // Fixed in the first 10 s block; in the second, one sample made worse.
    let mut after = vec![1.0; times.len()];
    after[30] = 1.5;
    let strong = strong_blocks(&residuals(before), &residuals(after), 10.0);
    assert_eq!(strong.len(), times.len());
    assert!(strong[..20].iter().all(|s| *s), "{strong:?}");
    assert!(strong[20..].iter().all(|s| !*s), "{strong:?}");
}

/// The blocks where a named noise source acts: where a channel's white measurement noise is
/// wider with it than without it at some sample; every element of such a block alike, in
/// every channel, and none where it is the same throughout.
#[test]
fn noise_source_blocks_are_where_the_floor_is_wider() {
    let floor = |std: Vec<f64>| {
        Some(crate::gap::resim::Floor {
            sigma: std.clone(),
            tau: 1.0,
            measurement_std: std,
            null: Vec::new(),
            chi2_tau_once: std::sync::OnceLock::new(),
        })
    };
    // Channel 0 sampled every second for 30 s, channel 1 every 5 s.
    let t0: Vec<f64> = (0..30).map(f64::from).collect();
    let t1: Vec<f64> = (0..6).map(|i| 5.0 * f64::from(i)).collect();
    let without = vec![floor(vec![1.0; 30]), floor(vec![2.0; 6])];
    // Channel 0 wider from 12 s to 14 s only: the 10-20 s block.
    let mut wide = vec![1.0; 30];
    for w in &mut wide[12..15] {
        *w = 1.5;
    }
    let with = vec![floor(wide), floor(vec![2.0; 6])];
    let r = Residuals {
        values: vec![0.0; 36],
        owner: [vec![0; 30], vec![1; 6]].concat(),
        training: vec![true; 36],
        times: [t0.clone(), t1.clone()].concat(),
        memory_s: vec![crate::gap::run::CONTACT_MEMORY_S; 36],
    };
    let acts = noise_source_blocks(&r, &without, &with, 10.0);
    let expected: Vec<bool> = t0
        .iter()
        .chain(&t1)
        .map(|t| (10.0..20.0).contains(t))
        .collect();
    assert_eq!(acts, expected);
    // The same floors: no block.
    assert!(
        !noise_source_blocks(&r, &without, &without, 10.0)
            .iter()
            .any(|a| *a)
    );
}

/// The constancy test on a run of the model's own form whose compass reads off: by a
/// constant angle, the values fitted in the two halves agree; by one angle where the
/// earlier names act and another elsewhere, they differ, each half finding its own. A split
/// with every element on one side tests nothing.
#[test]
fn constancy_tells_one_value_from_a_value_that_follows_the_earlier_names() {
    let (_, c, m) = crate::gap::resim::tests::manoeuvre(7);
    let clean = resim::simulate(&c, &m, None).unwrap();
    let floors = resim::noise_floor(&c, &m, &clean).unwrap();
    let effect = effects::by_name("compass_offset").unwrap();
    let half = m.experiment.duration_s / 2.0;
    let offset = |first: f64, second: f64| {
        let mut off = m.clone();
        let ch = off
            .channels
            .iter_mut()
            .find(|ch| ch.name == "compass_deg")
            .unwrap();
        for (t, v) in &mut ch.samples {
            *v += if *t < half { first } else { second };
        }
        off
    };
    let test = |measured: &Measurement| {
        let setup = setup(measured, c.clone(), &floors, Split::DEFAULT, &[]).unwrap();
        let r = setup.residuals(&setup.base, &setup.clean);
        let strong: Vec<bool> = r.times.iter().map(|t| *t < half).collect();
        constancy(&setup, effect, &[6.0], 1.0, &strong).expect("both halves fit")
    };
    let one = test(&offset(6.0, 6.0));
    assert!(one.holds(), "{one:?}");
    assert!((one.strong[0] - one.weak[0]).abs() < 1.0, "{one:?}");
    let two = test(&offset(2.0, 12.0));
    assert!(!two.holds(), "{two:?}");
    assert!(
        (two.weak[0] - two.strong[0]).abs() > 7.0,
        "each half finds its own: {two:?}"
    );
    // Every element on one side: nothing to compare.
    let measured = offset(2.0, 12.0);
    let setup = setup(&measured, c.clone(), &floors, Split::DEFAULT, &[]).unwrap();
    let all = vec![true; setup.residuals(&setup.base, &setup.clean).values.len()];
    assert!(constancy(&setup, effect, &[6.0], 1.0, &all).is_none());
}

/// A later name is a stand-in when the base model's structure explains its disagreement: on a
/// vehicle whose lag acts on the propeller's speed (thrust ~ speed squared) and is long, a
/// model that lags the thrust itself leaves a disagreement after every thrust step that the
/// surge added mass takes in part, and the lag's shape, a discrepancy term of the calibration,
/// takes in better. A surge added mass that is really there has no such rival.
#[test]
fn a_structural_term_outranks_a_later_stand_in_and_not_a_real_effect() {
    let lag = |c: &mut Configs| {
        c.vehicle.thruster_common.lag_s = 1.5;
        c.vehicle.thruster_common.lag_down_s = 1.5;
    };
    let added = effects::by_name("added_mass").unwrap();
    let fitted = |truth: &dyn Fn(&mut Configs)| {
        let (_, mut c, m) = crate::gap::resim::tests::manoeuvre_of(11, truth);
        lag(&mut c);
        let clean = resim::simulate(&c, &m, None).unwrap();
        let floors = resim::noise_floor(&c, &m, &clean).unwrap();
        let setup = setup(&m, c, &floors, Split::DEFAULT, &[]).unwrap();
        let win = fit_effects(&setup, &[added], &mut |_| {}).remove(0);
        (win.clone(), structural_rival(&setup, &win))
    };
    let (stand_in, rival) = fitted(&|c: &mut Configs| {
        lag(c);
        c.vehicle.thruster_common.lag_exponent = 2.0;
    });
    let rival = rival.expect("a structural rival");
    assert!(
        ["thruster_lag_shape", "thruster_spin_down"].contains(&rival.name.as_str()),
        "{} (stand-in delta BIC {:.1})",
        rival.name,
        stand_in.delta_bic_uncalibrated
    );
    let (real, rival) = fitted(&|c: &mut Configs| {
        lag(c);
        c.vehicle.added_mass[0] += 20.0;
    });
    assert!(real.guards.all(), "{:?}", real.guards);
    assert!(
        rival.is_none(),
        "{:?} against a real added mass (delta BIC {:.1})",
        rival.map(|r| (r.name, r.delta_bic_uncalibrated)),
        real.delta_bic_uncalibrated
    );
}

/// A real effect beside a loose structure is kept: with the lag's shape off and a thruster
/// imbalance really there, the structural term that mends the shape explains much of the
/// compass and track disagreement too, but the imbalance fitted beside it still passes every
/// guard, by a change of its own; the surge added mass that stands in for the same shape
/// error adds nothing beside it.
#[test]
fn a_real_effect_adds_to_its_structural_rival_and_a_stand_in_does_not() {
    let lag = |c: &mut Configs| {
        c.vehicle.thruster_common.lag_s = 1.5;
        c.vehicle.thruster_common.lag_down_s = 1.5;
        c.vehicle.thruster_common.lag_exponent = 2.0;
    };
    let shape = effects::by_name("thruster_lag_shape").unwrap();
    let fitted = |truth: &dyn Fn(&mut Configs), name: &str| {
        let (_, mut c, m) = crate::gap::resim::tests::manoeuvre_of(11, truth);
        c.vehicle.thruster_common.lag_s = 1.5;
        c.vehicle.thruster_common.lag_down_s = 1.5;
        let clean = resim::simulate(&c, &m, None).unwrap();
        let floors = resim::noise_floor(&c, &m, &clean).unwrap();
        let setup = setup(&m, c, &floors, Split::DEFAULT, &[]).unwrap();
        let effect = effects::by_name(name).unwrap();
        let win = fit_effects(&setup, &[effect], &mut |_| {}).remove(0);
        let mend = fit_effects(&setup, &[shape], &mut |_| {}).remove(0);
        assert!(
            mend.guards.all(),
            "{name}: the shape is off: {:?}",
            mend.guards
        );
        let adds = rival::adds_to(&setup, effect, &mend);
        let cosine = crate::gap::candidate::change_cosine_where_changed(&mend, &win);
        (adds, cosine, win.clone(), structural_rival(&setup, &win))
    };
    let (stand_in_adds, _, _, _) = fitted(&lag, "added_mass");
    assert!(!stand_in_adds, "a stand-in adds to the shape");
    let (real_adds, cosine, real, rival) = fitted(
        &|c: &mut Configs| {
            lag(c);
            c.vehicle.thrusters[0].gain *= 0.93;
        },
        "thruster_imbalance",
    );
    assert!(real.guards.all(), "{:?}", real.guards);
    assert!(real_adds, "the real imbalance adds nothing to the shape");
    assert!(
        cosine.is_some_and(|c| c < rival::RIVAL_SAME_PATTERN_COSINE),
        "{cosine:?}"
    );
    assert!(
        rival.is_none(),
        "{:?} refuses a real imbalance (delta BIC {:.1})",
        rival.map(|r| (r.name, r.delta_bic_uncalibrated)),
        real.delta_bic_uncalibrated
    );
}

/// The held-out guard's second half: residuals that lower the held-out chi-square in all (the
/// channel with the most independent samples a little better) but raise the report's gap
/// measure (the channel with the fewest much worse) grow the held-out gap; the same residuals
/// against a known level that expects that channel to be so far off do not, and residuals
/// better in both channels do not.
#[test]
fn a_held_out_gain_bought_in_one_dense_channel_grows_the_held_out_gap() {
    let (_, c, m) = crate::gap::resim::tests::manoeuvre(7);
    let clean = resim::simulate(&c, &m, None).unwrap();
    let floors = resim::noise_floor(&c, &m, &clean).unwrap();
    let plain = setup(&m, c.clone(), &floors, Split::DEFAULT, &[]).unwrap();
    // One floor of residual everywhere: each channel's level is then its correlation time.
    let mut before = plain.residuals(&plain.base, &plain.clean);
    before.values.iter_mut().for_each(|v| *v = 1.0);
    let held_out = |i: usize| {
        before
            .part(false)
            .filter(|(k, _)| before.owner[*k] == i)
            .count()
    };
    let independent = |i: usize| held_out(i) as f64 / floors[i].as_ref().unwrap().tau;
    let mut channels = plain.modelled();
    channels.sort_by(|a, b| independent(*a).total_cmp(&independent(*b)));
    let (sparse, dense) = (channels[0], channels[channels.len() - 1]);
    let tau = |i: usize| floors[i].as_ref().unwrap().tau;
    // Squared residuals: dense 1 - d, sparse 1 + e, with e between the bounds that keep the
    // chi-square falling (e < d n_dense / n_sparse) and make the measure rise
    // (e > d tau_dense / tau_sparse).
    let d = 0.5;
    let (n_ratio, tau_ratio) = (
        held_out(dense) as f64 / held_out(sparse) as f64,
        tau(dense) / tau(sparse),
    );
    assert!(n_ratio > tau_ratio, "{n_ratio} {tau_ratio}");
    let e = d * (n_ratio * tau_ratio).sqrt();
    let with = |dense_sq: f64, sparse_sq: f64| {
        let mut r = before.clone();
        for (v, o) in r.values.iter_mut().zip(&r.owner) {
            if *o == dense {
                *v = dense_sq.sqrt();
            } else if *o == sparse {
                *v = sparse_sq.sqrt();
            }
        }
        r
    };
    let traded = with(1.0 - d, 1.0 + e);
    assert!(
        before.chi2(false) - traded.chi2(false) > HELDOUT_MIN_GAIN,
        "the trade gains in held-out chi-square: {} -> {}",
        before.chi2(false),
        traded.chi2(false)
    );
    assert!(held_out_gap_grows(&plain, &before, &traded));
    assert!(!held_out_gap_grows(&plain, &before, &with(1.0 - d, 0.9)));
    // A known level that holds the sparse channel's disagreement as the model's own.
    let mut known = plain;
    known.known[sparse] = 100.0 * (1.0 + e);
    assert!(!held_out_gap_grows(&known, &before, &traded));
}

/// The signature correlation is read against the disagreement beyond the noise floor and the
/// channels' known levels. In the signature channels of a thruster imbalance, a smooth
/// disagreement with 3 % of the noise floor's energy, under noise at exactly the floor
/// (orthogonal to it): against the raw residual, an effect that explains the whole
/// disagreement correlates only about 0.17 and would fail; against the disagreement it
/// correlates fully and passes. An effect whose change is mostly elsewhere, explaining a tenth
/// of that disagreement, still fails.
#[test]
fn signature_correlation_is_read_beyond_the_noise_floor_and_the_known_levels() {
    use rand::{RngExt, SeedableRng};
    let (_, c, m) = crate::gap::resim::tests::manoeuvre(7);
    let clean = resim::simulate(&c, &m, None).unwrap();
    let floors = resim::noise_floor(&c, &m, &clean).unwrap();
    let s = setup(&m, c, &floors, Split::DEFAULT, &[]).unwrap();
    let effect = effects::by_name("thruster_imbalance").unwrap();
    let base = s.residuals(&s.base, &s.clean);
    let in_sig = |i: usize| effect.channels.contains(&m.channels[i].name.as_str());
    let sig: Vec<usize> = (0..base.values.len())
        .filter(|k| in_sig(base.owner[*k]))
        .collect();
    let tau = |k: usize| floors[base.owner[k]].as_ref().unwrap().tau;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
    let mut gauss = |_| rng.sample::<f64, _>(rand_distr::StandardNormal);
    let pattern: Vec<f64> = sig.iter().map(|k| (base.times[*k] / 5.0).sin()).collect();
    let mut noise: Vec<f64> = sig.iter().map(&mut gauss).collect();
    let other: Vec<f64> = sig.iter().map(&mut gauss).collect();
    let mut known_part: Vec<f64> = sig.iter().map(&mut gauss).collect();
    let training: Vec<bool> = sig.iter().map(|k| base.training[*k]).collect();
    let train_dot = |a: &[f64], b: &[f64]| -> f64 {
        a.iter()
            .zip(b)
            .zip(&training)
            .filter(|(_, t)| **t)
            .map(|((x, y), _)| x * y)
            .sum()
    };
    // Noise: orthogonal to the pattern, then scaled so that its training energy is the
    // floor's, one per independent sample.
    let k = train_dot(&noise, &pattern) / train_dot(&pattern, &pattern);
    noise
        .iter_mut()
        .zip(&pattern)
        .for_each(|(n, p)| *n -= k * p);
    let floor_energy: f64 = sig
        .iter()
        .zip(&training)
        .filter(|(_, t)| **t)
        .map(|(k, _)| 1.0 / tau(*k))
        .sum();
    let scale = (floor_energy / train_dot(&noise, &noise)).sqrt();
    noise.iter_mut().for_each(|n| *n *= scale);
    let amp = (0.03 * floor_energy / train_dot(&pattern, &pattern)).sqrt();
    let with = |v: &dyn Fn(usize) -> f64| {
        let mut r = base.clone();
        r.values.iter_mut().for_each(|x| *x = 0.0);
        for (j, k) in sig.iter().enumerate() {
            r.values[*k] = v(j);
        }
        r
    };
    let r0 = with(&|j| amp * pattern[j] + noise[j]);
    let explained = with(&|j| noise[j]);
    let raw = train_dot(&pattern, &pattern).sqrt() * amp
        / (train_dot(&pattern, &pattern) * amp * amp + floor_energy).sqrt();
    assert!(raw < SIGNATURE_MIN_CORRELATION, "raw correlation {raw}");
    let (pass, text) = signature(&s, effect, &r0, &explained);
    assert!(pass, "{text}");
    assert!(text.contains("= 1.00"), "{text}");
    // A change mostly orthogonal to the disagreement: a tenth of the pattern and a part of
    // its own as large as the whole noise.
    let q = (floor_energy / train_dot(&other, &other)).sqrt();
    let elsewhere = with(&|j| amp * pattern[j] + noise[j] - 0.1 * amp * pattern[j] - q * other[j]);
    let (pass, text) = signature(&s, effect, &r0, &elsewhere);
    assert!(!pass, "{text}");
    assert!(
        (s.independent_samples(Some(true), in_sig) - floor_energy).abs() < 1e-9 * floor_energy,
        "the floor's share counts the signature channels' training samples"
    );
    // The disagreement the calibration's own runs show is no more the effect's than the noise
    // is: beside the pattern and the noise, a known part with twice the floor's energy
    // (orthogonal to both). Read against the floor alone, the effect that explains the pattern
    // fails; with the signature channels' known level at 3, it correlates fully.
    for basis in [&pattern, &noise] {
        let k = train_dot(&known_part, basis) / train_dot(basis, basis);
        known_part
            .iter_mut()
            .zip(basis.iter())
            .for_each(|(x, b)| *x -= k * b);
    }
    let q = (2.0 * floor_energy / train_dot(&known_part, &known_part)).sqrt();
    known_part.iter_mut().for_each(|x| *x *= q);
    let r0 = with(&|j| amp * pattern[j] + noise[j] + known_part[j]);
    let explained = with(&|j| noise[j] + known_part[j]);
    let (pass, text) = signature(&s, effect, &r0, &explained);
    assert!(!pass, "{text}");
    let mut s = s;
    for (i, ch) in m.channels.iter().enumerate() {
        if effect.channels.contains(&ch.name.as_str()) {
            s.known[i] = 3.0;
        }
    }
    let (pass, text) = signature(&s, effect, &r0, &explained);
    assert!(pass && text.contains("= 1.00"), "{text}");
}

/// Sonar ranges witness the pose: a compass offset that explains its signature channels
/// and, through the heading it anchors, three times that gain in the sonar channels passes the
/// share test (the sonar gain counts as its own); the same gain in the depth channel, which
/// the heading does not move, leaves it a quarter of the improvement and fails. An effect of
/// no pose channel (a depth offset) gets no credit for the sonar.
#[test]
fn sonar_ranges_count_with_an_effect_of_the_pose() {
    let (_, c, m) = crate::gap::resim::tests::manoeuvre(7);
    let clean = resim::simulate(&c, &m, None).unwrap();
    let floors = resim::noise_floor(&c, &m, &clean).unwrap();
    let s = setup(&m, c, &floors, Split::DEFAULT, &[]).unwrap();
    let base = s.residuals(&s.base, &s.clean);
    // The manoeuvre pings no sonar: its sway accelerometer's samples stand in for a
    // transducer's (the test reads only which channel owns a residual).
    let mut sonar = m.clone();
    sonar
        .channels
        .iter_mut()
        .find(|ch| ch.name == "accel_y_adc")
        .unwrap()
        .name = "sonar1_m".into();
    let s = Setup { m: &sonar, ..s };
    let named = |k: usize| sonar.channels[base.owner[k]].name.as_str();
    let is_sonar = |k: usize| crate::gap::sonar::index(named(k)).is_some();
    let compass = effects::by_name("compass_offset").unwrap();
    let in_sig = |k: usize| compass.channels.contains(&named(k));
    let training = |k: usize| base.training[k];
    let count = |f: &dyn Fn(usize) -> bool| {
        (0..base.values.len())
            .filter(|k| training(*k) && f(*k))
            .count() as f64
    };
    // A disagreement of 3 per sample in the signature channels, explained whole; elsewhere a
    // disagreement whose explained share carries three times the signature channels' gain.
    let sig_gain = 9.0 * count(&in_sig);
    let with = |other: &dyn Fn(usize) -> bool| {
        let v = (3.0 * sig_gain / count(other)).sqrt();
        let mut r0 = base.clone();
        for (k, x) in r0.values.iter_mut().enumerate() {
            *x = if in_sig(k) {
                3.0
            } else if other(k) {
                v
            } else {
                0.0
            };
        }
        let mut r1 = r0.clone();
        r1.values.iter_mut().for_each(|x| *x = 0.0);
        (r0, r1)
    };
    let (r0, r1) = with(&is_sonar);
    let (pass, text) = signature(&s, compass, &r0, &r1);
    assert!(pass, "{text}");
    assert!(text.contains("and in sonar1_m"), "{text}");
    assert!(text.contains("= 100 %"), "{text}");
    let (r0, r1) = with(&|k| named(k) == "depth_adc");
    let (pass, text) = signature(&s, compass, &r0, &r1);
    assert!(!pass, "{text}");
    assert!(text.contains("= 25 %"), "{text}");
    let depth = effects::by_name("depth_offset").unwrap();
    let (r0, r1) = with(&is_sonar);
    let (_, text) = signature(&s, depth, &r0, &r1);
    assert!(!text.contains("sonar"), "{text}");
}

/// A structural rival is not named, so its held-out blocks need not confirm it; they must
/// only not get worse. Every other guard still holds it.
#[test]
fn a_structural_rival_needs_held_out_blocks_that_do_not_get_worse() {
    let shape = effects::by_name("thruster_lag_shape").unwrap();
    let rival = |gain: f64, interval: bool| {
        let mut c = crate::gap::candidate::Candidate::untestable(shape, 100.0, "");
        c.testable = true;
        c.guards = crate::gap::candidate::Guards {
            inside_bounds: true,
            interval_excludes_zero: interval,
            significant: true,
            signature: true,
            heldout: Some(gain > HELDOUT_MIN_GAIN),
        };
        c.heldout_gain = Some(gain);
        c
    };
    assert!(rival::stands(&rival(2.4, true)), "a small held-out gain");
    assert!(rival::stands(&rival(40.0, true)), "a confirmed one");
    assert!(!rival::stands(&rival(-0.5, true)), "a held-out loss");
    assert!(
        !rival::stands(&rival(2.4, false)),
        "an interval that holds no effect"
    );
    let mut untested = rival(2.4, true);
    untested.testable = false;
    assert!(!rival::stands(&untested));
}

/// On the simulator manoeuvre measured with `truth`: `win`'s fit against the model without
/// it, `twin`'s, `win`'s structural rival and the cosine of `twin`'s change with `win`'s.
fn fitted_beside_twin(
    win: &'static Effect,
    twin: &'static Effect,
    truth: fn(&mut Configs),
) -> (Candidate, Candidate, Option<String>, Option<f64>) {
    let (_, c, m) = crate::gap::resim::tests::manoeuvre_of(13, truth);
    let clean = resim::simulate(&c, &m, None).unwrap();
    let floors = resim::noise_floor(&c, &m, &clean).unwrap();
    let setup = setup(&m, c, &floors, Split::DEFAULT, &[]).unwrap();
    let fit = fit_effects(&setup, &[win], &mut |_| {}).remove(0);
    let other = fit_effects(&setup, &[twin], &mut |_| {}).remove(0);
    let cosine = crate::gap::candidate::change_cosine_where_changed(&other, &fit);
    let rival = structural_rival(&setup, &fit).map(|r| r.name);
    (fit, other, rival, cosine)
}

/// A yaw moment in sway (`N_v v`) and one in surge times sway (`N_uv u v`, the Munk moment)
/// are twins of form: fitted against the model that lacks a hidden sway-yaw coupling, the Munk
/// moment makes the same change of the residuals as the coupling's fit (a cosine of 0.94 on
/// this manoeuvre: above the one at which a structural rival counts as the same pattern).
/// Here the manoeuvre's turns at several speeds tell them apart: the Munk moment explains
/// less, and refuses no coupling named after another effect (`structural_rival`), as it would
/// not where it ties with it. Where the hidden term is a Munk moment, the data prefer its form
/// by more than the margin, and it refuses the coupling that stands in for it.
#[test]
fn a_sway_yaw_moment_and_the_munk_moment_are_twins_of_form() {
    let coupling = effects::by_name("sway_yaw_coupling").unwrap();
    let munk = effects::by_name("munk_moment").unwrap();
    let fitted = |truth| {
        let (win, _, rival, cosine) = fitted_beside_twin(coupling, munk, truth);
        (win, rival, cosine)
    };
    let (stand_in, rival, _) = fitted(|c| c.vehicle.damping_yaw_uv += 20.0);
    assert_eq!(
        rival.as_deref(),
        Some("munk_moment"),
        "a coupling standing in for a Munk moment ({:?})",
        stand_in.guards
    );
    let (win, rival, cosine) = fitted(|c| c.vehicle.damping_sway_yaw[1] += 5.0);
    assert!(win.guards.all(), "{:?}", win.guards);
    assert!(
        cosine.is_some_and(|c| c >= rival::RIVAL_SAME_PATTERN_COSINE),
        "{cosine:?}"
    );
    assert!(
        rival.is_none_or(|r| r != "munk_moment"),
        "the Munk moment refuses its twin"
    );
    assert!(effects::twins(coupling, munk) && effects::twins(munk, coupling));
}

/// A disagreement the model's runs share (here a depth reading off by a constant) reads as a
/// smaller chi-square per independent sample once a named depth EMI raises the floor it is
/// judged against; the known level measured without the EMI, read through
/// [`crate::gap::residuals::known_weight`], predicts the level it keeps. Left at its old
/// value, the known level put the depth channel of a calibrated vehicle below it after an EMI
/// (0.46 of it with a real depth gain fitted), and a hidden second effect there was refused
/// as a fit of known disagreement.
#[test]
fn a_known_level_is_read_against_the_floor_a_named_emi_raises() {
    use crate::gap::residuals::{known_weight, level_under};
    let bias = |t: &mut Configs| t.sensors.depth.errors.bias += 0.015;
    let emi = |t: &mut Configs| t.sensors.depth.emi_v_rms_full_duty += 3.0;
    let level = |c: &Configs, m: &Measurement| {
        let clean = resim::simulate(c, m, None).unwrap();
        let floors = resim::noise_floor(c, m, &clean).unwrap();
        let setup = setup(m, c.clone(), &floors, Split::DEFAULT, &[]).unwrap();
        let depth = m
            .channels
            .iter()
            .position(|ch| ch.name == "depth_adc")
            .unwrap();
        let r = setup.residuals(c, &clean);
        let chi2 = setup
            .part_levels(&r, None)
            .into_iter()
            .find(|(i, _)| *i == depth)
            .map(|(_, l)| l)
            .unwrap();
        (chi2, floors[depth].clone().unwrap())
    };
    // The calibration's runs: the shared disagreement, no EMI, judged by the model's floor.
    let (_, mut c, m0) = crate::gap::resim::tests::manoeuvre_of(31, bias);
    c.shooting = crate::gap::anchor::Shooting::OPEN_LOOP;
    let (known, floor0) = level(&c, &m0);
    // A case: the same disagreement with an EMI, judged by the floor of the model with it.
    let (_, _, m1) = crate::gap::resim::tests::manoeuvre_of(31, |t| {
        bias(t);
        emi(t);
    });
    let mut with_emi = c.clone();
    emi(&mut with_emi);
    let (shown, floor1) = level(&with_emi, &m1);
    let w = known_weight(&floor0, &floor1);
    let read = level_under(known, w);
    // The manoeuvre runs its stern motor in about an eighth of its samples: there the EMI
    // floor is many times the old one, elsewhere the same.
    assert!(known > 2.0, "the shared disagreement shows: {known:.3}");
    assert!(w < 0.95, "the EMI raises the floor: w = {w:.3}");
    let close = |x: f64| (x - shown).abs() < 0.05 * (known - 1.0);
    assert!(
        close(read),
        "read {read:.3} against {shown:.3} shown (known {known:.3}, w {w:.3})"
    );
    assert!(
        !close(known),
        "the old level {known:.3} is not what shows, {shown:.3}"
    );
    assert_eq!(known_weight(&floor0, &floor0), 1.0);
    assert_eq!(level_under(known, 1.0), known);
}

/// The earlier names take a later winner somewhere new only where they move the readings of
/// its channels by a share of what the winner moves them: a depth offset named first leaves
/// the heading and track a sway-yaw coupling changes nearly as they were, a thruster lag of
/// 1.5 s more than the model's moves them. A noise source among the earlier names takes a
/// winner that moves its channel somewhere new whatever the readings show (the commands it
/// made the loop give are replayed whether it is named or not): a depth EMI beside the offset
/// takes a thrust curve there, which acts through the vertical thrusters, and leaves the
/// coupling's turns where they were.
#[test]
fn an_earlier_depth_offset_leaves_a_coupling_in_its_regime_and_a_lag_does_not() {
    let coupling = effects::by_name("sway_yaw_coupling").unwrap();
    let curve = effects::by_name("thrust_curve").unwrap();
    let emi = effects::by_name("depth_pwm_emi").unwrap();
    let moved = |earlier: &str, value: f64, noise: bool, winner: &'static Effect| {
        let earlier = effects::by_name(earlier).unwrap();
        let (_, c, m) = crate::gap::resim::tests::manoeuvre_of(13, |t| {
            effects::apply(coupling, &[2.0], t);
            effects::apply(earlier, &[value], t);
        });
        let clean0 = resim::simulate(&c, &m, None).unwrap();
        let mut named = c.clone();
        effects::apply(earlier, &[value], &mut named);
        let clean = resim::simulate(&named, &m, None).unwrap();
        let floors = resim::noise_floor(&named, &m, &clean).unwrap();
        let setup = setup(&m, named, &floors, Split::DEFAULT, &[]).unwrap();
        let win = fit_effects(&setup, &[winner], &mut |_| {}).remove(0);
        if winner == coupling {
            assert!(win.guards.all(), "after {}: {:?}", earlier.name, win.guards);
        }
        let named: Vec<&Effect> = if noise {
            vec![earlier, emi]
        } else {
            vec![earlier]
        };
        moved_to_new_regime(&setup, &named, &setup.residuals(&c, &clean0), &win)
    };
    assert!(
        !moved("depth_offset", 0.1, false, coupling),
        "a depth offset moves the turns"
    );
    assert!(
        moved("thruster_lag", 1.5, false, coupling),
        "a lag leaves the turns"
    );
    assert!(
        !moved("depth_offset", 0.1, true, coupling),
        "a depth EMI moves the turns"
    );
    assert!(
        moved("depth_offset", 0.1, true, curve),
        "a depth EMI chatters the thrusters a thrust curve acts through"
    );
}

/// A structural rival explains as much as a winner when the winner's lead over it on the
/// significance scale is under the margin, however far ahead it is unscaled (a thrust curve
/// 34.1 ahead of a net buoyancy after a depth EMI, 1.1 on the scale); a twin of the winner's
/// form must explain more by the margin on that scale.
#[test]
fn a_structural_rival_is_judged_on_the_significance_scale() {
    let fitted = |name: &str, gain: f64, scale: f64| {
        let mut c = Candidate::untestable(effects::by_name(name).unwrap(), 100.0, "");
        c.chi2_before = 10_000.0;
        c.chi2_after = 10_000.0 - gain;
        c.delta_bic_uncalibrated = gain - 7.0;
        c.noise_factor = scale;
        c.variance_factor = 1.0;
        c
    };
    let win = fitted("thrust_curve", 690.0, 30.0);
    assert!(rival::explains_as_much(
        &win,
        &fitted("net_buoyancy", 656.0, 30.0),
        false
    ));
    assert!(!rival::explains_as_much(
        &fitted("thrust_curve", 690.0, 1.0),
        &fitted("net_buoyancy", 656.0, 1.0),
        false
    ));
    assert!(!rival::explains_as_much(
        &win,
        &fitted("net_buoyancy", 300.0, 30.0),
        false
    ));
    let coupling = fitted("sway_yaw_coupling", 600.0, 2.0);
    assert!(!rival::explains_as_much(
        &coupling,
        &fitted("munk_moment", 610.0, 2.0),
        true
    ));
    assert!(rival::explains_as_much(
        &coupling,
        &fitted("munk_moment", 640.0, 2.0),
        true
    ));
}

/// Sensor effects of the mean type named first leave the vehicle's dynamics as they were, and
/// so does a water current, which moves the ground track but not the motion through the
/// water; a physics effect that changes the forces, or a noise source, among them does not.
#[test]
fn only_forces_or_noise_named_first_change_the_dynamics() {
    let e = |name| effects::by_name(name).unwrap();
    assert!(!earlier_change_dynamics(&[e("compass_hard_iron")]));
    assert!(!earlier_change_dynamics(&[
        e("compass_offset"),
        e("depth_offset"),
        e("velocity_sensor_scale"),
        e("sensor_latency"),
    ]));
    assert!(!earlier_change_dynamics(&[
        e("compass_hard_iron"),
        e("water_current")
    ]));
    assert!(earlier_change_dynamics(&[e("thruster_lag")]));
    assert!(earlier_change_dynamics(&[e("depth_pwm_emi")]));
    assert!(earlier_change_dynamics(&[
        e("water_current"),
        e("thruster_imbalance")
    ]));
}

/// A fit whose start rides a wall the base run does not reach leaves the start's contacts out
/// of its search ([`search_contacts`]); a start that touches nothing new leaves nothing more
/// out. Its fitted point, back within the base's reach, is scored on what the base leaves out.
#[test]
fn a_start_that_touches_where_the_base_does_not_is_left_out_of_its_search() {
    let (_, mut c, m) = crate::gap::resim::tests::manoeuvre(7);
    c.shooting = crate::gap::anchor::Shooting::DEFAULT;
    let effect = effects::by_name("thrust_gain").unwrap();
    let stronger = [5.0 * effect.scales[0]];
    // The far wall of the axis the track runs furthest along, moved in from the far end of
    // the track until twice the thrust reaches it and the base still does not.
    let (axis, _, far) = crate::gap::resim::tests::furthest_axis(&m);
    let touches = |cfg: &Configs| !resim::simulate(cfg, &m, None).unwrap().contacts.is_empty();
    let walled = (0..30)
        .map(|i| {
            let mut w = c.clone();
            w.world.pool_m[axis] = far + 1.5 - 0.05 * f64::from(i);
            w
        })
        .find(|w| {
            let mut s = w.clone();
            effects::apply(effect, &stronger, &mut s);
            !touches(w) && touches(&s)
        })
        .expect("a wall the stronger thrust reaches and the base does not");
    let clean = resim::simulate(&walled, &m, None).unwrap();
    let floors = resim::noise_floor(&walled, &m, &clean).unwrap();
    let setup = setup(&m, walled, &floors, Split::DEFAULT, &[]).unwrap();
    let r0 = setup.residuals(&setup.base, &setup.clean);
    let kept = memo::Evaluations::new(&setup, effect, &r0);
    let at = |x: &DVector<f64>| kept.at(&[x[0] * effect.scales[0]]);
    let select = |r: &Residuals| r.training_vector();
    let touching = kept.at(&stronger).and_then(|e| e.contacts).unwrap();
    let from_stronger = [DVector::from_element(1, 5.0)];
    assert_eq!(
        search_contacts(&setup, &from_stronger, at, select),
        Some(touching)
    );
    let from_zero = [
        DVector::from_element(1, 0.0),
        DVector::from_element(1, 0.25),
    ];
    assert_eq!(search_contacts(&setup, &from_zero, at, select), None);
    let scored = fit_part(&setup, effect, &r0, Some(true), &from_stronger, &kept).unwrap();
    assert_eq!(scored.chi2_before, r0.chi2(true));
}

/// Re-anchored, a fit is scored where neither the base nor its fitted point touched the pool:
/// a hidden thrust gain drives the vehicle into a wall the base model does not reach, and the
/// right fit reaches it too; the contact's samples are left out of its chi-square before and
/// after alike, as they are of its held-out blocks.
#[test]
fn a_fit_is_scored_where_neither_the_base_nor_its_point_touched() {
    let effect = effects::by_name("thrust_gain").unwrap();
    let (_, _, plain) = crate::gap::resim::tests::manoeuvre(7);
    let (axis, _, far) = crate::gap::resim::tests::furthest_axis(&plain);
    let wall = far + 0.5;
    let (_, mut c, m) = crate::gap::resim::tests::manoeuvre_of(7, |t| {
        t.world.pool_m[axis] = wall;
        effects::apply(effect, &[1.0], t);
    });
    c.world.pool_m[axis] = wall;
    c.shooting = crate::gap::anchor::Shooting::DEFAULT;
    let clean = resim::simulate(&c, &m, None).unwrap();
    let floors = resim::noise_floor(&c, &m, &clean).unwrap();
    let setup = setup(&m, c, &floors, Split::DEFAULT, &[]).unwrap();
    let r0 = setup.residuals(&setup.base, &setup.clean);
    let kept = memo::Evaluations::new(&setup, effect, &r0);
    let scored = fit_part(
        &setup,
        effect,
        &r0,
        Some(true),
        &lsq::axis_scan(1, &START_SCAN),
        &kept,
    )
    .unwrap();
    let touched = kept.at(&scored.params).and_then(|e| e.contacts).unwrap();
    assert_ne!(
        touched, setup.clean.contacts,
        "the fitted point reaches the wall"
    );
    let left_out = left_out_where_touched(&r0, Some(&touched)).chi2(true);
    assert!(
        left_out < r0.chi2(true),
        "the contact holds training samples"
    );
    assert_eq!(scored.chi2_before, left_out);
    assert!((scored.params[0] - 1.0).abs() < 0.2, "{:?}", scored.params);
}

/// A fit evaluates its starts as its search takes them, inside the box: a scan point beyond an
/// effect's bound is clamped onto it before the contacts of the best start are read, so the
/// contacts left out are those of the point the search begins from, and no run is made at a
/// point the effect's bounds exclude.
#[test]
fn a_fit_evaluates_its_starts_inside_the_bounds() {
    let effect = effects::by_name("thrust_curve").unwrap();
    let starts = lsq::axis_scan(1, &START_SCAN);
    let (low, high) = effect.bounds[0];
    assert!(
        starts
            .iter()
            .any(|x| !(low..=high).contains(&(x[0] * effect.scales[0]))),
        "the scan reaches beyond the bounds of {}",
        effect.name
    );
    let (_, c, m) = crate::gap::resim::tests::manoeuvre_of(7, |t| {
        effects::apply(effect, &[0.3], t);
    });
    let clean = resim::simulate(&c, &m, None).unwrap();
    let floors = resim::noise_floor(&c, &m, &clean).unwrap();
    let setup = setup(&m, c, &floors, Split::DEFAULT, &[]).unwrap();
    let r0 = setup.residuals(&setup.base, &setup.clean);
    let kept = memo::Evaluations::new(&setup, effect, &r0);
    let scored = fit_part(&setup, effect, &r0, Some(true), &starts, &kept).unwrap();
    let outside: Vec<Vec<f64>> = kept
        .points()
        .into_iter()
        .filter(|p| !(low..=high).contains(&p[0]))
        .collect();
    assert!(
        outside.is_empty(),
        "evaluated outside [{low}, {high}]: {outside:?}"
    );
    assert!((scored.params[0] - 0.3).abs() < 0.15, "{:?}", scored.params);
}

/// A depth sensor's offset and the height the hull floats at (`float_depth`, a discrepancy
/// term) are twins of form: on a run that spends most of its time afloat they move the depth
/// reading alike (a cosine of 0.9999 on this manoeuvre), and only the dives, where the reading
/// follows the offset and not the float, tell them apart. Fitted against a model that lacks a
/// hidden depth offset, the float depth explains a little more; that near tie refuses no depth
/// offset named after another effect (`structural_rival`), as none is refused named first. A
/// hull that truly floats 0.05 m deeper is fitted better by the float depth, by more than the
/// margin in chi-square; but the two fits differ only in the dives, where the model's own
/// process noise runs through many readings together, and along their difference that noise
/// is many times the floor: on the scale of the lead itself (`candidate::margin`) the float's
/// preference is within the margin, and a twin that does not lead by it refuses nothing (a
/// twin that does: `a_sway_yaw_moment_and_the_munk_moment_are_twins_of_form`).
#[test]
fn a_depth_offset_and_the_float_depth_are_twins_of_form() {
    let offset = effects::by_name("depth_offset").unwrap();
    let float = effects::by_name("float_depth").unwrap();
    let fitted = |truth| fitted_beside_twin(offset, float, truth);
    let (win, twin, rival, cosine) = fitted(|c| c.sensors.depth.errors.bias += 0.05);
    assert!(win.guards.all(), "{:?}", win.guards);
    assert!(cosine.is_some_and(|c| c > 0.999), "{cosine:?}");
    assert!(
        (twin.delta_bic_uncalibrated - win.delta_bic_uncalibrated).abs() < BIC_MARGIN,
        "a near tie: {} against {}",
        twin.delta_bic_uncalibrated,
        win.delta_bic_uncalibrated
    );
    assert!(
        rival.is_none_or(|r| r != "float_depth"),
        "the float depth refuses its twin"
    );
    let (stand_in, twin, rival, _) = fitted(|c| c.vehicle.cg_from_box_centre_m.z += 0.05);
    let gain = |c: &Candidate| c.chi2_before - c.chi2_after;
    assert!(
        gain(&twin) > gain(&stand_in) + BIC_MARGIN,
        "the float fits better: {} against {}",
        gain(&twin),
        gain(&stand_in)
    );
    let lead = crate::gap::candidate::margin(&stand_in, &twin);
    assert!(lead > -BIC_MARGIN, "on the lead's own scale: {lead}");
    assert!(
        rival.is_none_or(|r| r != "float_depth"),
        "a twin within the margin refuses nothing"
    );
    assert!(effects::twins(offset, float) && effects::twins(float, offset));
}

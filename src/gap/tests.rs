use super::*;

/// The gap measure is the mean over channels of chi2 over the known level, less 1: a run
/// as far off as the baseline runs has no gap, each channel counts once, and a known
/// level below the noise floor counts as the floor.
#[test]
fn the_gap_measure_is_the_channel_mean_over_known_levels() {
    assert_eq!(excess([(3.0, 3.0), (1.0, 1.0)].into_iter()), 0.0);
    assert!((excess([(6.0, 3.0), (1.0, 1.0)].into_iter()) - 0.5f64.sqrt()).abs() < 1e-12);
    assert!((excess([(2.0, 0.5)].into_iter()) - 1.0).abs() < 1e-12);
    assert_eq!(excess([(0.5, 1.0)].into_iter()), 0.0);
    assert_eq!(excess(std::iter::empty()), 0.0);
}

/// A wall contact is judged as the fits see it: a stretch of track far off where the
/// re-simulation touched the pool (and the contact's memory after it) makes the channel
/// disagree when the run has no contact there, and not when it has, with those samples
/// left out of the count.
#[test]
fn a_wall_contact_is_no_disagreement_of_its_own() {
    let (model, mut c, mut m) = resim::tests::manoeuvre(11);
    c.shooting = run::Shooting::DEFAULT;
    let x = m.channels.iter().position(|ch| ch.name == "x_m").unwrap();
    let (from, to) = (40.0, 50.0);
    // Zero at every segment start, where the track is re-anchored to the data.
    let segment = c.shooting.segment_s.unwrap();
    for (t, v) in &mut m.channels[x].samples {
        if (from..to).contains(t) {
            *v += 0.3 * (std::f64::consts::PI * t.rem_euclid(segment) / segment).sin();
        }
    }
    let mut run = resim::simulate(&c, &m, None).unwrap();
    assert!(run.contacts.is_empty(), "{:?}", run.contacts);
    let floors = resim::noise_floor(&c, &m, &run).unwrap();
    let x_stats = |run: &resim::Run| {
        stats_for(&model, &m, &c, run, &floors, &[])
            .into_iter()
            .find(|s| s.channel == "x_m")
            .unwrap()
    };
    let free = x_stats(&run);
    assert!(free.significant, "chi2/n {}", free.chi2_per_sample);
    run.contacts.push([from, to]);
    let touched = x_stats(&run);
    assert!(!touched.significant, "chi2/n {}", touched.chi2_per_sample);
    let left_out = m.channels[x]
        .samples
        .iter()
        .filter(|(t, _)| *t >= from - run::CONTACT_LEAD_S && *t < to + run::CONTACT_MEMORY_S)
        .count();
    assert_eq!(touched.samples + left_out, free.samples);
    assert!(touched.windows.iter().all(|w| w.1 <= from || w.0 >= to));
}

/// Runs of the model itself, nothing hidden, are no disagreement. The bench's open-loop
/// manoeuvre ends with a dive whose depth wanders under the thrust fluctuation: read with
/// the mean correlation time, `depth_adc` and `accel_x_adc` were significant in 5 of these
/// 16 runs (chi2/n up to 1.84 against a bound near 1.4); the chi-square's own spread over
/// the ensemble bounds them.
#[test]
fn runs_of_the_model_itself_are_no_disagreement() {
    let (model, mut c, _) = resim::tests::manoeuvre(101);
    c.shooting = run::Shooting::OPEN_LOOP;
    let mut floors = None;
    let mut flagged = Vec::new();
    for seed in 101..=116 {
        let (_, _, m) = resim::tests::manoeuvre(seed);
        let run = resim::simulate(&c, &m, None).unwrap();
        let floors = floors.get_or_insert_with(|| resim::noise_floor(&c, &m, &run).unwrap());
        let off: Vec<String> = stats_for(&model, &m, &c, &run, floors, &[])
            .into_iter()
            .filter(|s| s.significant)
            .map(|s| format!("{} {:.2}", s.channel, s.chi2_per_sample))
            .collect();
        if !off.is_empty() {
            flagged.push((seed, off));
        }
    }
    assert!(flagged.len() <= 1, "{flagged:?}");
}

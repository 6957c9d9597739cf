use super::*;

/// A later name must take a real part of what the earlier names left, and something must
/// be left: a sliver of a large rest, anything once the gap is at its known levels, or a
/// drop mostly below the channels' known levels is refused; a tenth or more, above them,
/// passes. Above and below are read channel by channel: a channel far off, brought to its
/// known level beside channels the model fits better than the calibration's runs, is an
/// excess explained, though the channels' mean ends below 1.
#[test]
fn a_later_name_must_take_a_real_share_of_what_is_left() {
    let one = |without: f64, with: f64| too_small_a_share(&[without], &[with]);
    // An accelerometer offset after an EMI: 1.242 -> 1.223 is 8 % of the 0.242 left.
    let sliver = one(1.242, 1.223).expect("a sliver is refused");
    assert!(sliver.contains("8 %"), "{sliver}");
    assert!(one(0.98, 0.96).is_some(), "nothing left to explain");
    assert!(one(1.0, 0.9).is_some(), "at the known levels");
    let hidden = too_small_a_share(&[1.72, 0.2], &[0.91, 0.2]).expect("the mean is 0.96");
    assert!(hidden.contains("no disagreement is left"), "{hidden}");
    // A compass offset beside a current: 5.66 -> 4.79 is 19 % of what is left.
    assert_eq!(one(5.66, 4.79), None);
    assert_eq!(one(2.0, 1.9), None, "exactly a tenth passes");
    assert_eq!(one(1.5, 1.0), None);
    // A drag mismatch after a thruster imbalance: 1.018 -> 0.841 is 0.018 above the
    // known levels and 0.159 below them.
    let below = one(1.018, 0.841).expect("mostly below the known levels");
    assert!(below.contains("0.159 of that below"), "{below}");
    // A coupling after a compass offset: 1.86 -> 0.99 is nearly all above them.
    assert_eq!(one(1.86, 0.99), None);
    // A depth channel at twice its known level, brought to 0.9 of it, beside a channel at
    // 0.3 of its own: the mean goes 1.15 -> 0.6, 0.5 of that above the channels' levels
    // and 0.05 below. Read on the mean alone, 0.4 of the drop would be below 1.
    assert_eq!(too_small_a_share(&[2.0, 0.3], &[0.9, 0.3]), None);
    // The same drop spread over channels already within their levels is refused.
    let spread = too_small_a_share(&[1.2, 1.1], &[0.7, 0.8]).expect("below the levels");
    assert!(spread.contains("0.250 of that below"), "{spread}");
}

/// A later name whose channels still hold an excess is judged there when the whole run's
/// mean is at or below its known levels: a water current after a paddle-wheel scale (the
/// channels of structure seed 196519's pair 78, the track's y at 4.1 of its known level)
/// is; a compass offset whose channels are all within their levels is not, nor is any name
/// while the whole run still holds an excess (then the whole run's share is read).
#[test]
fn an_excess_hidden_in_the_mean_is_read_where_the_effect_acts() {
    // The benchmark's channels: every modelled one but the surge speed.
    let names: Vec<&str> = resim::MODELLED
        .into_iter()
        .filter(|c| *c != "surge_mps")
        .collect();
    let left = [1.096, 4.105, 0.278, 0.683, 0.417, 0.308, 0.376, 0.142];
    let current = effects::by_name("water_current").unwrap();
    assert!(
        too_small_a_share(&left, &left).is_some(),
        "the run's mean is 0.93"
    );
    assert!(excess_only_where_it_acts(current, &names, &left));
    let offset = effects::by_name("compass_offset").unwrap();
    let within = [0.9, 0.95, 0.278, 0.683, 0.417, 0.308, 0.376, 0.142];
    assert!(!excess_only_where_it_acts(offset, &names, &within));
    let whole = [1.096, 4.105, 0.278, 0.683, 0.417, 0.308, 0.376, 6.0];
    assert!(!excess_only_where_it_acts(current, &names, &whole));
    assert!(!excess_only_where_it_acts(current, &names[..7], &left));
}

/// A first name must find an excess where it acts: an accelerometer gain whose channel is
/// at 0.850 of its known level (a null run of structure seed 204563, case 65) is refused
/// whatever the track holds; with its channel at 1.05 it is not, nor is a compass offset
/// whose channels hold the run's excess.
#[test]
fn a_first_name_must_find_an_excess_where_it_acts() {
    // The benchmark's channels: every modelled one but the surge speed.
    let names: Vec<&str> = resim::MODELLED
        .into_iter()
        .filter(|c| *c != "surge_mps")
        .collect();
    let gain = effects::by_name("accel_x_gain").unwrap();
    let before = [0.610, 1.247, 1.440, 1.436, 0.850, 0.939, 0.934, 0.938];
    let why = first_name_without_excess(gain, &names, &before).expect("refused");
    assert!(why.contains("0.850"), "{why}");
    let mut high = before;
    high[4] = 1.05;
    assert_eq!(first_name_without_excess(gain, &names, &high), None);
    let offset = effects::by_name("compass_offset").unwrap();
    assert_eq!(first_name_without_excess(offset, &names, &before), None);
    assert_eq!(first_name_without_excess(gain, &names[..7], &before), None);
    // A sonar channel's level is its echoes' likelihood: the fixture of a hidden incidence
    // cut puts it at 0.41 and 0.52 with the cut in the data.
    let sonar = effects::by_name("sonar_incidence_dropout").unwrap();
    let with_sonar: Vec<&str> = names
        .iter()
        .copied()
        .chain(["sonar1_m", "sonar2_m"])
        .collect();
    let levels: Vec<f64> = before.iter().copied().chain([0.41, 0.52]).collect();
    assert_eq!(first_name_without_excess(sonar, &with_sonar, &levels), None);
}

/// A winner in place of a refused one is judged on the channels it moves: a paddle-wheel
/// scale that takes its channel from 4.39 to 2.47 of its known level explains 57 % of what
/// is left there, whatever a depth channel it does not move still holds; an effect whose
/// channels hold nothing beyond their levels explains nothing.
#[test]
fn a_share_is_read_where_the_effect_acts() {
    let scale = effects::by_name("velocity_sensor_scale").unwrap();
    let names = ["x_m", "depth_adc", "paddle_speed_mps"];
    let share = share_where_it_acts(scale, &names, &[1.5, 7.75, 4.39], &[1.5, 7.75, 2.47]);
    assert!((share - 1.92 / 3.39).abs() < 1e-9, "{share}");
    assert_eq!(
        share_where_it_acts(scale, &names, &[1.5, 7.75, 0.9], &[1.5, 7.75, 0.8]),
        0.0
    );
    let depth = effects::by_name("depth_offset").unwrap();
    let lag = share_where_it_acts(depth, &names, &[1.5, 7.75, 4.39], &[1.5, 7.0, 2.47]);
    assert!((lag - 0.75 / 6.75).abs() < 1e-9, "{lag}");
}

/// A later name must take a real share of what is left where it acts as well: an
/// accelerometer offset whose channel is below its known level takes nothing there, though
/// the whole run's mean drops; an imbalance that buys track with heading takes under a
/// tenth of its channels' excess; a right second name passes.
#[test]
fn a_later_name_must_take_a_real_share_where_it_acts() {
    // The benchmark's channels: every modelled one but the surge speed.
    let names: Vec<&str> = resim::MODELLED
        .into_iter()
        .filter(|c| *c != "surge_mps")
        .collect();
    let offset = effects::by_name("accel_y_offset").unwrap();
    let without = [1.054, 1.343, 0.754, 0.796, 1.041, 0.953, 1.007, 1.216];
    let with = [1.040, 1.304, 0.758, 0.796, 1.041, 0.910, 1.007, 1.212];
    assert_eq!(
        too_small_a_share(&without, &with),
        None,
        "the whole run's mean drops"
    );
    let why = too_small_where_it_acts(offset, &names, &without, &with).expect("nothing left");
    assert!(
        why.contains("(accel_y_adc)") && why.contains("0.953"),
        "{why}"
    );
    let imbalance = effects::by_name("thruster_imbalance").unwrap();
    let without = [2.384, 3.639, 1.046, 0.623, 0.911, 0.934, 1.057, 1.939];
    let with = [2.143, 3.182, 1.419, 0.622, 0.911, 0.929, 1.057, 1.796];
    assert_eq!(
        too_small_a_share(&without, &with),
        None,
        "10.5 % of the whole"
    );
    let why = too_small_where_it_acts(imbalance, &names, &without, &with).expect("a sliver");
    assert!(
        why.contains("explains 10 %") || why.contains("explains 9 %"),
        "{why}"
    );
    // A velocity scale after a thrust gain, its paddle channel from 6.08 to 1.2.
    let scale = effects::by_name("velocity_sensor_scale").unwrap();
    let without = [1.2, 1.1, 0.9, 1.0, 1.0, 1.0, 1.0, 6.08];
    let with = [1.2, 1.1, 0.9, 1.0, 1.0, 1.0, 1.0, 1.2];
    assert_eq!(
        too_small_where_it_acts(scale, &names, &without, &with),
        None
    );
    let depth = effects::by_name("depth_offset").unwrap();
    assert_eq!(
        too_small_where_it_acts(depth, &names[..3], &without, &with),
        None
    );
}

/// A run with a hidden thruster imbalance of 0.15, the model without it, and the noise floor
/// of that model's re-simulation of the run.
struct ImbalanceRun {
    model: GapModel,
    base: Configs,
    m: Measurement,
    floors: Vec<Option<resim::Floor>>,
    /// The statistics of the channels the imbalance moves, against the model without it.
    moved: Vec<ChannelStats>,
}

fn imbalance_run(imbalance: &'static effects::Effect) -> ImbalanceRun {
    let (model, base, m) = resim::tests::manoeuvre_of(5, |c: &mut Configs| {
        effects::apply(imbalance, &[0.15], c);
    });
    let clean = resim::simulate(&base, &m, None).unwrap();
    let floors = resim::noise_floor(&base, &m, &clean).unwrap();
    let stats = stats_for(&model, &m, &base, &clean, &floors, &[]);
    let moved = moved_by(imbalance, &stats).into_iter().cloned().collect();
    ImbalanceRun {
        model,
        base,
        m,
        floors,
        moved,
    }
}

/// A later name needs a channel it moves still off: on a run with a hidden thruster
/// imbalance, against the model without it, the imbalance's channels are off and it may be
/// named after others; against the model with the imbalance in it, nothing it moves is
/// off, and it is refused, with each channel's figures; an effect whose channels the
/// imbalance leaves alone (a depth offset) finds nothing off either.
#[test]
fn a_later_name_needs_a_channel_it_moves_still_off() {
    let imbalance = effects::by_name("thruster_imbalance").unwrap();
    let depth = effects::by_name("depth_offset").unwrap();
    let run = imbalance_run(imbalance);
    let (model, base, m, floors) = (run.model, run.base, run.m, run.floors);
    let off = nothing_off_that_it_moves(&model, &m, imbalance, &base, &floors, &[], Judged::Alone)
        .unwrap();
    assert_eq!(off, None, "the imbalance's channels are off");
    let mut with = base.clone();
    effects::apply(imbalance, &[0.15], &mut with);
    let why = nothing_off_that_it_moves(&model, &m, imbalance, &with, &floors, &[], Judged::Alone)
        .unwrap()
        .expect("nothing left off once the imbalance is in the model");
    assert!(why.contains("compass_deg") && why.contains("x_m"), "{why}");
    assert!(
        nothing_off_that_it_moves(&model, &m, depth, &base, &floors, &[], Judged::Alone)
            .unwrap()
            .is_some(),
        "a depth offset finds its channel off, which the imbalance leaves alone"
    );
}

/// A later name's channels are judged against the bound a run with nothing new stays
/// under in those channels together, not against the report's bound for every channel at
/// once: on a run with a hidden thruster imbalance, against the model without it, each
/// channel the imbalance moves is set a report bound of twice its chi-square and a scatter
/// whose bound for the moved channels together is half of it (the track and heading are
/// far off, the surge acceleration is not). The imbalance finds its
/// channels off; with the scatter left out (a model written before it was kept), the
/// report's bound is all there is and it finds nothing off.
#[test]
fn a_later_name_is_judged_against_the_bound_for_its_own_channels() {
    let imbalance = effects::by_name("thruster_imbalance").unwrap();
    let run = imbalance_run(imbalance);
    let (mut model, base, m, floors, moved) = (run.model, run.base, run.m, run.floors, run.moved);
    assert!(moved.iter().any(|s| s.chi2_per_sample > 4.0), "{moved:?}");
    for s in &moved {
        let unit = crate::gap::model::RunScatter {
            log_mean: 0.0,
            log_sd: 0.1,
            runs: 3,
        };
        let to_half = unit.bound(moved.len()).unwrap().ln();
        let scatter = crate::gap::model::RunScatter {
            log_mean: (s.chi2_per_sample / 2.0).ln() - to_half,
            ..unit
        };
        model
            .discrepancy_bound
            .insert(s.channel.clone(), 2.0 * s.chi2_per_sample);
        model.discrepancy_scatter.insert(s.channel.clone(), scatter);
    }
    let off = nothing_off_that_it_moves(&model, &m, imbalance, &base, &floors, &[], Judged::Alone)
        .unwrap();
    assert_eq!(off, None, "the moved channels lie over their own bound");
    model.discrepancy_scatter.clear();
    let why = nothing_off_that_it_moves(&model, &m, imbalance, &base, &floors, &[], Judged::Alone)
        .unwrap()
        .expect("under the report's bound, nothing is off");
    assert!(why.contains("run bound"), "{why}");
}

/// The names after an exchange on a run with `hidden` at `value` and a thrust gain of
/// 0.15: a depth gain named first (its round's change taken as the depth offset's, so that
/// the two are look-alikes), then `later`'s candidates fitted with it in and the one named
/// `pick` taken as the later name. `None` when nothing is exchanged; with the first
/// round's guards. The test is of the exchange, given its rounds.
fn exchanged_after(
    hidden: &'static effects::Effect,
    value: f64,
    later: &[&'static effects::Effect],
    pick: &str,
) -> (Option<Vec<String>>, Vec<bool>) {
    let offset = effects::by_name("depth_offset").unwrap();
    let gain = effects::by_name("depth_gain").unwrap();
    let thrust = effects::by_name("thrust_gain").unwrap();
    let (_, c, m) = resim::tests::manoeuvre_of(7, move |c: &mut Configs| {
        effects::apply(hidden, &[value], c);
        effects::apply(thrust, &[0.15], c);
    });
    let clean = resim::simulate(&c, &m, None).unwrap();
    let floors = resim::noise_floor(&c, &m, &clean).unwrap();
    let setup = fit::setup(&m, c, &floors, fit::Split::DEFAULT, &[]).unwrap();
    let mut first = fit::fit_effects(&setup, &[gain, offset], &mut |_| {});
    let named_gain = first.iter().position(|c| c.name == "depth_gain").unwrap();
    let depth_gain = first[named_gain].clone();
    for c in first.iter_mut() {
        c.change.clone_from(&depth_gain.change);
    }
    let mut with_gain = setup.base.clone();
    effects::apply(gain, &depth_gain.values(), &mut with_gain);
    let later_setup = fit::setup(&m, with_gain, &floors, fit::Split::DEFAULT, &[]).unwrap();
    let mut second = fit::fit_effects(&later_setup, later, &mut |_| {});
    // The later round's held-out blocks, on this short manoeuvre, are too few for a thrust
    // gain beside a depth gain: its guards are taken as passed there, as a long run's are.
    for c in second.iter_mut() {
        c.guards.heldout = Some(true);
    }
    let picked = second.iter().find(|c| c.name == pick).unwrap().clone();
    let accepted = vec![depth_gain, picked];
    let guards: Vec<bool> = first.iter().map(|c| c.guards.all()).collect();
    let ex = exchange_lookalikes(&setup, &[first, second], &accepted);
    let names = ex.map(|e| e.accepted.iter().map(|c| c.name.clone()).collect());
    (names, guards)
}

/// An earlier name is exchanged for a look-alike of its round when the set with the
/// look-alike fits the data better with the later name in, and kept when it fits better
/// itself. On a run with a hidden depth offset and a thrust gain, a depth gain named first
/// gives way to the offset; with a hidden depth gain it stays.
#[test]
fn an_earlier_name_gives_way_to_its_look_alike_when_the_later_names_say_so() {
    let offset = effects::by_name("depth_offset").unwrap();
    let gain = effects::by_name("depth_gain").unwrap();
    let thrust = effects::by_name("thrust_gain").unwrap();
    let (names, guards) = exchanged_after(offset, 0.2, &[thrust], "thrust_gain");
    assert_eq!(
        names,
        Some(vec!["depth_offset".to_string(), "thrust_gain".to_string()]),
        "guards of the first round {guards:?}"
    );
    let (names, _) = exchanged_after(gain, 0.1, &[thrust], "thrust_gain");
    assert_eq!(names, None, "a depth gain that is there stays");
}

/// The later name the wrong earlier name led to is exchanged too: with a depth gain in
/// place of the hidden depth offset, a later round that took a water current (the thrust
/// gain its rival) still ends at the depth offset and the thrust gain, which fit the data
/// better together than the offset beside the current does.
#[test]
fn a_later_name_the_earlier_look_alike_led_to_gives_way_with_it() {
    let offset = effects::by_name("depth_offset").unwrap();
    let thrust = effects::by_name("thrust_gain").unwrap();
    let current = effects::by_name("water_current").unwrap();
    let (names, guards) = exchanged_after(offset, 0.2, &[thrust, current], "water_current");
    assert_eq!(
        names,
        Some(vec!["depth_offset".to_string(), "thrust_gain".to_string()]),
        "guards of the first round {guards:?}"
    );
}

/// A first name is refused when its channels lie within what runs with nothing new scatter
/// to: on a run with a hidden depth offset, against the model without it, with the depth
/// channel's bound set to twice its chi-square per sample, an offset that takes a fifth of the
/// depth excess is refused, as a later name is, and one that takes four fifths is refused too,
/// its one channel no further off judged together; with the bound at half the chi-square, the
/// channel is off and the small share is named too.
#[test]
fn a_first_name_taking_a_sliver_within_the_scatter_is_refused() {
    let depth = effects::by_name("depth_offset").unwrap();
    let (mut model, base, m) = resim::tests::manoeuvre_of(5, |c: &mut Configs| {
        effects::apply(depth, &[0.05], c);
    });
    let clean = resim::simulate(&base, &m, None).unwrap();
    let floors = resim::noise_floor(&base, &m, &clean).unwrap();
    let stats = stats_for(&model, &m, &base, &clean, &floors, &[]);
    let chi2 = stats
        .iter()
        .find(|s| s.channel == "depth_adc")
        .unwrap()
        .chi2_per_sample;
    assert!(chi2 > 4.0, "the hidden offset shows: {chi2}");
    let channels = ["x_m", "y_m", "compass_deg", "depth_adc"];
    let without = [1.0, 1.0, 1.0, 3.0];
    let mut bound_at = |factor: f64| {
        let unit = crate::gap::model::RunScatter {
            log_mean: 0.0,
            log_sd: 0.1,
            runs: 3,
        };
        let to_one = unit.bound(1).unwrap().ln();
        let scatter = crate::gap::model::RunScatter {
            log_mean: (factor * chi2).ln() - to_one,
            ..unit
        };
        model
            .discrepancy_bound
            .insert("depth_adc".into(), factor * chi2);
        model
            .discrepancy_scatter
            .insert("depth_adc".into(), scatter);
        model.clone()
    };
    let judge = |model: &GapModel, with: [f64; 4]| {
        first_name_within_the_scatter(
            model,
            &m,
            depth,
            &channels,
            &without,
            &with,
            &base,
            &floors,
            &[],
        )
        .unwrap()
    };
    let wide = bound_at(2.0);
    let why = judge(&wide, [1.0, 1.0, 1.0, 2.6]).expect("a fifth, within the scatter");
    assert!(why.contains("20 %") && why.contains("depth_adc"), "{why}");
    let why = judge(&wide, [1.0, 1.0, 1.0, 1.4]).expect("four fifths, within the scatter");
    assert!(
        why.contains("80 %") && why.contains("nor are they together"),
        "{why}"
    );
    let narrow = bound_at(0.5);
    assert_eq!(
        judge(&narrow, [1.0, 1.0, 1.0, 2.6]),
        None,
        "its channel off"
    );
}

/// A noise source named after others is held to the least share in the channel it moves, and
/// only there: the depth EMI a bridge thrust gain left (seed 203381, case 35: the depth channel
/// 1.727 -> 1.672 over its known level, 8 % of its excess, though 22 % of the whole run's) is
/// refused, the hidden EMI named after a hard iron (case 72: 1.620 -> 1.495, 20 %) is not, nor
/// is one where the whole run holds no excess but its channel does. A mean effect is still
/// read over the whole run, or, where only the channels it moves hold an excess, there.
#[test]
fn a_later_noise_source_must_take_a_real_share_of_its_channel() {
    let names = ["x_m", "y_m", "compass_deg", "depth_adc", "paddle_speed_mps"];
    let emi = effects::by_name("depth_pwm_emi").unwrap();
    assert_eq!(emi.kind, Kind::Variance);
    let without = [0.847, 0.971, 0.947, 1.727, 0.761];
    let with = [0.847, 0.971, 0.947, 1.672, 0.761];
    assert_eq!(
        too_small_a_share(&without, &with),
        None,
        "22 % of the whole"
    );
    let why = too_small_later_share(emi, Some(&names), &without, &with, false)
        .expect("a sliver of the depth channel");
    assert!(
        why.contains("(depth_adc)") && why.contains("explains 8 %"),
        "{why}"
    );
    assert_eq!(
        too_small_later_share(emi, None, &without, &with, false),
        None,
        "without the channels' names no channel is read alone"
    );
    let without = [0.385, 0.697, 1.597, 1.620, 0.929];
    let with = [0.385, 0.697, 1.597, 1.495, 0.929];
    assert_eq!(
        too_small_later_share(emi, Some(&names), &without, &with, false),
        None
    );
    let without = [0.6, 0.7, 0.9, 1.5, 0.8];
    let with = [0.6, 0.7, 0.9, 1.2, 0.8];
    assert!(
        too_small_a_share(&without, &with).is_some(),
        "no excess left"
    );
    assert_eq!(
        too_small_later_share(emi, Some(&names), &without, &with, false),
        None
    );
    let offset = effects::by_name("compass_offset").unwrap();
    let why = too_small_later_share(offset, Some(&names), &without, &with, false)
        .expect("a mean effect reads the whole run");
    assert!(why.contains("no disagreement is left"), "{why}");
    let why = too_small_later_share(offset, Some(&names), &without, &with, true)
        .expect("judged where it acts alone, where the compass holds nothing to take");
    assert!(
        why.starts_with("in the channels it moves (") && why.contains("compass_deg"),
        "{why}"
    );
}

/// A winner in place of one a structural term refused is held to most of what is left only
/// when it changes the residuals as that term does: a water current at right angles to the
/// lag's form (cosine -0.06, structure 666013 pair 3) meets the later-name rules alone; a
/// change along the term's, of either sign, or one that cannot be compared, is held; so is
/// every winner in place of one refused for another reason.
#[test]
fn a_winner_in_place_of_a_structural_refusal_is_held_only_when_it_changes_as_the_term_does() {
    let with_change = |name: &str, change: &[f64]| {
        let mut c =
            Candidate::untestable(effects::by_name(name).expect("a library effect"), 1.0, "");
        c.change = change.to_vec();
        c
    };
    let term = with_change("thruster_lag", &[1.0, 0.0, 0.0, 1.0]);
    let across = with_change("water_current", &[0.0, 1.0, 1.0, -0.1]);
    assert!(!held_as_stand_in(&across, Some(&term)));
    assert!(
        held_as_stand_in(&across, None),
        "refused for another reason"
    );
    let along = with_change("drag_mismatch", &[1.0, 0.2, 0.0, 1.0]);
    assert!(held_as_stand_in(&along, Some(&term)));
    let against = with_change("drag_mismatch", &[-1.0, 0.5, 0.5, -1.0]);
    assert!(
        held_as_stand_in(&against, Some(&term)),
        "a change along the term's, reversed"
    );
    // Cosine 0.45: under the bound, not held; 0.55: held.
    let c = |x: f64| with_change("drag_mismatch", &[x, (1.0 - x * x).sqrt(), 0.0, 0.0]);
    let unit = with_change("thruster_lag", &[1.0, 0.0, 0.0, 0.0]);
    assert!(!held_as_stand_in(&c(0.45), Some(&unit)));
    assert!(held_as_stand_in(&c(0.55), Some(&unit)));
    let unknown = with_change("water_current", &[]);
    assert!(
        held_as_stand_in(&unknown, Some(&term)),
        "no change to compare"
    );
}

/// A sensor effect named after a physics effect that moves its channel is asked whether its
/// value follows it whatever its share; a physics effect, a sensor effect after sensor effects
/// alone, or one whose channel the physics name does not move, only when it explains less than
/// half of what is left; a noise source never.
#[test]
fn a_sensor_name_after_a_physics_name_that_moves_its_channel_is_asked_whether_it_follows_it() {
    let e = |name: &str| effects::by_name(name).expect("a library effect");
    let (offset, gain, hard_iron) = (
        e("accel_x_offset"),
        e("thrust_gain"),
        e("compass_hard_iron"),
    );
    let (current, emi, depth, yaw) = (
        e("water_current"),
        e("depth_pwm_emi"),
        e("depth_offset"),
        e("yaw_damping"),
    );
    assert!(asks_constancy(offset, &[gain], 0.66));
    assert!(asks_constancy(hard_iron, &[hard_iron, current], 1.0));
    assert!(
        !asks_constancy(depth, &[yaw], 0.96),
        "the damping moves no depth"
    );
    assert!(asks_constancy(depth, &[yaw], 0.3));
    assert!(
        !asks_constancy(current, &[gain], 0.66),
        "a physics name keeps its share"
    );
    assert!(asks_constancy(current, &[gain], 0.3));
    assert!(
        !asks_constancy(offset, &[hard_iron], 0.66),
        "no physics named before it"
    );
    assert!(
        !asks_constancy(offset, &[emi], 0.66),
        "a noise source is no physics effect"
    );
    assert!(
        !asks_constancy(emi, &[gain], 0.1),
        "a noise source changes no mean"
    );
}

/// A first name that explains most of the excess where it acts is judged on the channels it
/// moves together: on a run with a hidden thruster imbalance, against the model without it,
/// each channel the imbalance moves is set a scatter of runs with nothing new that puts this
/// run at `t` of Student's t. At t = 2.5 in every channel none is off alone (with four runs,
/// the bound of one of three or more channels judged alone lies beyond t = 3.7), all are off
/// together, and the imbalance is named; at t = 0 they are where such runs lie, and it is refused with the
/// figure; a channel far above beside one as far below cancel.
#[test]
fn a_first_name_explaining_most_needs_its_channels_off_together() {
    let imbalance = effects::by_name("thruster_imbalance").unwrap();
    let run = imbalance_run(imbalance);
    let (mut model, base, m, floors, moved) = (run.model, run.base, run.m, run.floors, run.moved);
    assert!(moved.len() >= 3, "{moved:?}");
    let channels: Vec<&str> = moved.iter().map(|s| s.channel.as_str()).collect();
    let without = vec![3.0; channels.len()];
    let with = vec![1.2; channels.len()];
    let at = |model: &mut GapModel, t: &dyn Fn(usize) -> f64| {
        for (i, s) in moved.iter().enumerate() {
            let sd = 0.1;
            let scatter = crate::gap::model::RunScatter {
                log_mean: s.chi2_per_sample.ln() - t(i) * sd * (1.25_f64).sqrt(),
                log_sd: sd,
                runs: 4,
            };
            model.discrepancy_scatter.insert(s.channel.clone(), scatter);
        }
    };
    let judge = |model: &GapModel| {
        first_name_within_the_scatter(
            model,
            &m,
            imbalance,
            &channels,
            &without,
            &with,
            &base,
            &floors,
            &[],
        )
        .unwrap()
    };
    at(&mut model, &|_| 2.5);
    let refs: Vec<&ChannelStats> = moved.iter().collect();
    let together = off_together(&model, &refs).expect("every channel has a scatter");
    assert_eq!(together.channels, moved.len());
    assert!(together.off(), "{together:?}");
    assert_eq!(judge(&model), None, "off together, none alone");
    at(&mut model, &|_| 0.0);
    assert!(off_together(&model, &refs).unwrap().z.abs() < 1e-6);
    let why = judge(&model).expect("where runs with nothing new lie");
    assert!(
        why.contains("90 %") && why.contains("nor are they together ("),
        "{why}"
    );
    at(&mut model, &|i| if i < 2 { [4.0, -4.0][i] } else { 0.0 });
    let together = off_together(&model, &refs).unwrap();
    assert!(together.z.abs() < 1e-9 && !together.off(), "{together:?}");
    model.discrepancy_scatter.clear();
    assert_eq!(
        off_together(&model, &refs),
        None,
        "no scatter, no judgement"
    );
    assert_eq!(judge(&model), None, "without a scatter, not asked");
}

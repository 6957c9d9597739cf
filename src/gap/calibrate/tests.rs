use super::*;
use nalgebra::DMatrix;
use std::collections::BTreeMap;

fn fixture(case: &str) -> Run {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("pty-tests/fixtures/gap")
        .join(case);
    Run::load(&dir).expect("fixture loads")
}

fn model() -> GapModel {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/models/mako.toml");
    GapModel::load(&path).expect("model loads")
}

fn refused(baseline: &[Run], spread_from: &[Run]) -> String {
    match calibrate(&model(), baseline, &[], spread_from, &mut |_| {}) {
        Err(GapError::Data(msg)) => msg,
        Err(e) => panic!("expected a data error, got {e}"),
        Ok(_) => panic!("calibration accepted spread runs it cannot use"),
    }
}

/// A spread needs two or more runs the calibration was not fitted to; the error names
/// the flag, the run and what was expected, before any fitting starts.
#[test]
fn spread_runs_it_cannot_use_are_refused_naming_the_run() {
    let base = [fixture("null")];
    let one = refused(&base, &[fixture("drag-mismatch")]);
    assert!(one.contains("--spread-from"), "{one}");
    assert!(one.contains("drag-mismatch"), "{one}");
    assert!(one.contains("two or more"), "{one}");
    let overlap = refused(&base, &[fixture("drag-mismatch"), fixture("null")]);
    assert!(overlap.contains("--spread-from"), "{overlap}");
    assert!(overlap.contains("null"), "{overlap}");
    assert!(overlap.contains("not fitted to"), "{overlap}");
}

/// A sensor effect the joint fit drove onto its bound, and any effect the data do not
/// bound, are left out of the calibration with the reason; a physics effect on its bound
/// with a finite interval stays (the dynamics take the disagreement, not a sensor).
#[test]
fn unidentified_and_bound_sensor_effects_are_named() {
    let by = |n: &str| effects::by_name(n).unwrap();
    let chosen = [
        by("depth_gain"),
        by("thrust_gain"),
        by("compass_offset"),
        by("yaw_damping"),
    ];
    // In units of each typical size: depth_gain on its upper bound 0.5, thrust_gain
    // inside, compass_offset unmoved by the data, yaw_damping on its lower bound -0.9.
    let x = DVector::from_vec(vec![0.5 / 0.05, 0.1 / 0.2, 0.0, -0.9 / 0.2]);
    let mut j = DMatrix::zeros(8, 4);
    for r in 0..8 {
        j[(r, 0)] = 3.0 + r as f64;
        j[(r, 1)] = 5.0 - r as f64 * 0.5;
        j[(r, 3)] = 2.0 + (r % 3) as f64;
    }
    let fit = lsq::Fit {
        x: x.clone(),
        residuals: DVector::from_element(8, 0.1),
        jacobian: Some(j),
        evaluations: 0,
        at_bound: true,
        termination: levenberg_marquardt::TerminationReason::Converged {
            ftol: true,
            xtol: true,
        },
    };
    let out = unidentified_effects(&chosen, &x, &fit);
    let names: Vec<&str> = out.iter().map(|(e, _)| e.name).collect();
    assert_eq!(names, vec!["depth_gain", "compass_offset"], "{out:?}");
    assert!(out[0].1.contains("bound"), "{}", out[0].1);
    assert!(out[1].1.contains("do not bound"), "{}", out[1].1);
}

/// The robust residual's square is Huber's loss: `u^2` inside the threshold, `2 k |u| - k^2`
/// beyond it, continuous there and odd in `u`: a sample thirty spreads off costs 171 (what
/// thirteen spreads cost squared), not 900.
#[test]
fn the_robust_residual_squares_to_hubers_loss() {
    let k = HUBER_K;
    for u in [0.0, 0.5, -2.0, k] {
        assert_eq!(huber(u, k), u);
    }
    for u in [3.5, -7.0, 30.0] {
        let h = huber(u, k);
        assert!(
            (h * h - (2.0 * k * u.abs() - k * k)).abs() < 1e-9,
            "{u}: {h}"
        );
        assert_eq!(h.signum(), u.signum());
    }
    assert!((huber(k + 1e-9, k) - k).abs() < 1e-6);
    assert!((huber(30.0, k).powi(2) - 171.0).abs() < 1e-9);
}

/// The joint fit starts from the model as given, from the steeper thrust curve, and from the
/// camera marker 0.1 m ahead of and behind where it is stated, each start changing one
/// parameter alone: the marker and a sway in spins trade off, and from the stated marker
/// alone the fit can end with the marker on the wrong side of the centre.
#[test]
fn the_joint_fit_starts_from_the_marker_on_both_sides_of_the_centre() {
    let (chosen, _) = choose_effects(&crate::gap::resim::MODELLED);
    let all = starts(&chosen);
    let offset = |name: &str| {
        let mut k = 0;
        for e in &chosen {
            if e.name == name {
                return (k, e.scales[0]);
            }
            k += e.parameters.len();
        }
        panic!("{name} is not calibrated");
    };
    assert!(
        all[0].iter().all(|v| *v == 0.0),
        "the first start is the model as given"
    );
    let (marker, scale) = offset("camera_marker_position");
    let (curve, curve_scale) = offset("thrust_curve");
    let moved: Vec<(usize, f64)> = all[1..]
        .iter()
        .map(|x| {
            let nonzero: Vec<usize> = (0..x.len()).filter(|&i| x[i] != 0.0).collect();
            assert_eq!(nonzero.len(), 1, "each further start moves one parameter");
            (nonzero[0], x[nonzero[0]])
        })
        .collect();
    assert_eq!(
        moved,
        vec![
            (curve, 0.3 / curve_scale),
            (marker, 0.1 / scale),
            (marker, -0.1 / scale)
        ]
    );
}

fn per_run(channels: &[(&str, &[f64])]) -> BTreeMap<String, Vec<f64>> {
    channels
        .iter()
        .map(|(c, v)| (c.to_string(), v.to_vec()))
        .collect()
}

/// The bound one more run with nothing new stays under is the log-normal prediction bound
/// of the runs' chi-squares: exp(mean + t s sqrt(1 + 1/k)) of their logs, with Student's t
/// for k - 1 degrees of freedom at 1 - 0.05 / channels. Here one channel of four runs, so t is
/// t(0.95; 3) = 2.353 (tables), and the bound lies above every run's value.
#[test]
fn the_run_bound_is_the_log_normal_prediction_bound_of_the_runs() {
    let runs = [1.52, 2.21, 1.31, 1.37];
    let bounds = run_bounds(&per_run(&[("x_m", &runs)]));
    let logs: Vec<f64> = runs.iter().map(|v: &f64| v.ln()).collect();
    let m = logs.iter().sum::<f64>() / 4.0;
    let s = (logs.iter().map(|l| (l - m).powi(2)).sum::<f64>() / 3.0).sqrt();
    let want = (m + 2.353 * s * (1.25_f64).sqrt()).exp();
    assert_eq!(bounds.len(), 1);
    assert_eq!(bounds[0].0, "x_m");
    assert!(
        (bounds[0].1 - want).abs() < 1e-3 * want,
        "{bounds:?} against {want}"
    );
    assert!(bounds[0].1 > 2.21);
}

/// More channels judged at once widen each one's bound (a run disagrees when any channel
/// does); a channel measured on one run has no scatter and so no bound; runs that agree
/// exactly bound at their common value.
#[test]
fn the_run_bound_covers_all_channels_together_and_needs_two_runs() {
    let runs: &[f64] = &[1.52, 2.21, 1.31, 1.37];
    let alone = run_bounds(&per_run(&[("x_m", runs)]));
    let four = run_bounds(&per_run(&[
        ("x_m", runs),
        ("y_m", runs),
        ("depth_adc", runs),
        ("compass_deg", &[3.0]),
    ]));
    let x = |b: &[(String, f64)]| b.iter().find(|(c, _)| c == "x_m").map(|(_, v)| *v);
    assert!(x(&four) > x(&alone), "{four:?} against {alone:?}");
    assert!(four.iter().all(|(c, _)| c != "compass_deg"), "{four:?}");
    let same = run_bounds(&per_run(&[("y_m", &[2.0, 2.0, 2.0])]));
    assert!((same[0].1 - 2.0).abs() < 1e-12, "{same:?}");
}

/// The sway a turn makes (`Y_r`) is left as given: in a spin it moves the tracked marker as a
/// marker ahead of the centre of mass does, so the baseline runs would set it against the
/// marker's position and give the base model a sway in turns the hull does not have. The
/// marker itself is calibrated, and `Y_r` stays a structural rival of later names.
#[test]
fn the_sway_from_a_turn_is_left_to_the_marker_and_to_the_rivals() {
    let (chosen, _) = choose_effects(&crate::gap::resim::MODELLED);
    let names: Vec<&str> = chosen.iter().map(|e| e.name).collect();
    assert!(!names.contains(&"sway_from_yaw"), "{names:?}");
    assert!(names.contains(&"camera_marker_position"), "{names:?}");
    let coupling = effects::by_name("sway_yaw_coupling").unwrap();
    let rivals: Vec<&str> = effects::structural_rivals(coupling)
        .iter()
        .map(|e| e.name)
        .collect();
    assert!(rivals.contains(&"sway_from_yaw"), "{rivals:?}");
}

/// A vector in a plane strays the same in every direction: the water current's north and
/// east spreads are one pooled value, so three runs that strayed east leave no narrow north
/// spread. An effect of two unrelated parameters keeps one spread per parameter.
#[test]
fn a_vector_in_a_plane_has_one_spread_in_every_direction() {
    let by = |n: &str| effects::by_name(n).unwrap();
    let runs = vec![vec![-0.004, 0.001], vec![0.002, 0.008], vec![0.001, 0.012]];
    let current = spread_of(by("water_current"), &runs, 1.0);
    let pooled = ((16.0 + 4.0 + 1.0 + 1.0 + 64.0 + 144.0) / 6.0_f64).sqrt() * 1e-3;
    assert_eq!(current.len(), 2);
    for s in &current {
        assert!((s - pooled).abs() < 1e-12, "{current:?}, expected {pooled}");
    }
    let drag = spread_of(by("drag_mismatch"), &runs, 1.5);
    let rms = |j: usize| (runs.iter().map(|v| v[j] * v[j]).sum::<f64>() / 3.0 * 1.5).sqrt();
    assert_eq!(drag, vec![rms(0), rms(1)]);
}

/// A validation or spread run the calibrated model fits worse gets a warning naming it, its
/// role and the channels that grew most; one it fits better, and a baseline run, get none.
#[test]
fn a_run_the_calibration_fits_worse_is_warned_of() {
    let run = |role: RunRole, after: f64| RunGap {
        dir: "square-7".into(),
        role,
        gap_before: 6.08,
        gap_after: after,
        reduction_pct: 100.0 * (1.0 - after / 6.08),
        channels: vec![
            ("x_m".into(), 4.0, 9.5),
            ("y_m".into(), 3.0, 2.0),
            ("compass_deg".into(), 1.5, 2.1),
        ],
        carried_by: Vec::new(),
    };
    let w = run(RunRole::Validation, 7.55)
        .grown_warning()
        .expect("a warning");
    assert!(
        w.contains("validation run square-7") && w.contains("6.08 -> 7.55"),
        "{w}"
    );
    assert!(
        w.contains("x_m 4.00 -> 9.50, compass_deg 1.50 -> 2.10"),
        "{w}"
    );
    assert!(!w.contains("y_m"), "{w}");
    assert!(!w.contains("carry it"), "{w}");
    let carried = RunGap {
        carried_by: vec![("thrust_curve".into(), 4.1), ("net_buoyancy".into(), 6.9)],
        ..run(RunRole::Validation, 7.55)
    };
    let w = carried.grown_warning().expect("a warning");
    assert!(
        w.contains(
            "; the calibrated terms that carry it furthest: thrust_curve (gap 4.10 with it as \
             given), net_buoyancy (gap 6.90 with it as given)):"
        ),
        "{w}"
    );
    let w = run(RunRole::Spread, 7.55)
        .grown_warning()
        .expect("a warning");
    assert!(w.contains("spread run square-7"), "{w}");
    assert_eq!(run(RunRole::Validation, 1.2).grown_warning(), None);
    assert_eq!(run(RunRole::Baseline, 7.55).grown_warning(), None);
}

fn chi2(dir: &str, depth: f64, x: f64) -> known::RunChi2 {
    known::RunChi2 {
        dir: dir.into(),
        channels: [("depth_adc".to_string(), depth), ("x_m".to_string(), x)].into(),
    }
}

/// With spread runs (null runs of the programme later runs use) the known disagreement is
/// theirs and that of each validation run like them; a validation run of another programme,
/// far outside their scatter in one channel, is left out and named with that channel.
#[test]
fn a_validation_run_unlike_the_spread_runs_sets_no_known_level() {
    let spread = [
        chi2("square-1", 1.0, 3.0),
        chi2("square-2", 1.2, 2.8),
        chi2("square-3", 0.9, 3.2),
    ];
    let never = || -> Result<Vec<known::RunChi2>, GapError> { panic!("baseline runs read") };
    let unlike = [chi2("depth-hold", 401.0, 3.1)];
    let k = known::known_runs(&unlike, &spread, never).expect("known runs");
    assert_eq!(k.from, ["square-1", "square-2", "square-3"]);
    assert_eq!(k.levels["depth_adc"], [1.0, 1.2, 0.9]);
    assert_eq!(k.unfitted["x_m"], [3.0, 2.8, 3.2]);
    assert_eq!(k.unlike.len(), 1);
    let w = k.unlike[0].warning();
    assert!(
        w.contains("depth-hold") && w.contains("depth_adc 401.00 outside"),
        "{w}"
    );
    assert!(!w.contains("x_m"), "{w}");

    // Below the spread runs' scatter is unlike too: a validation run at the surface beside
    // cases that dive would lower the level they are judged against.
    let calm = [chi2("surface", 0.01, 3.0)];
    assert_eq!(
        known::known_runs(&calm, &spread, never)
            .expect("known")
            .unlike
            .len(),
        1
    );

    let like = [chi2("square-4", 1.1, 2.9)];
    let k = known::known_runs(&like, &spread, never).expect("known runs");
    assert!(k.unlike.is_empty());
    assert_eq!(k.from.len(), 4);
    assert_eq!(k.levels["depth_adc"], [1.0, 1.2, 0.9, 1.1]);
}

/// Without spread runs the validation runs give the known level and the bound, as before; with
/// neither the baseline runs give the level and no bound.
#[test]
fn without_spread_runs_the_validation_runs_then_the_baseline_runs_give_the_level() {
    let v = [chi2("mixed-4", 2.0, 3.0)];
    let k = known::known_runs(&v, &[], || panic!("baseline runs read")).expect("known");
    assert_eq!(k.from, ["mixed-4"]);
    assert_eq!(k.unfitted["depth_adc"], [2.0]);
    let k = known::known_runs(&[], &[], || Ok(vec![chi2("mixed-1", 1.5, 2.5)])).expect("known");
    assert_eq!(k.from, ["mixed-1"]);
    assert_eq!(k.levels["x_m"], [2.5]);
    assert!(k.unfitted.is_empty());
}

/// Net buoyancy is fitted only where the baseline runs dive: a run that stays afloat (a dip
/// of 3 s below its shallowest reading) leaves it at the model as given, with why; 60 s at
/// half a metre below lets it be fitted. Depth is read through the model's sensor.
#[test]
fn net_buoyancy_is_held_unless_the_baseline_runs_dive() {
    let run = fixture("null");
    let c = model().configs(&run.m.experiment, &run.dir).unwrap();
    let lsb = crate::sensors::AdcBoard::new(&c.sensors.adc, 0).lsb_v();
    let code =
        |depth_m: f64| c.sensors.adc.offset_lsb + depth_m * c.sensors.depth.volts_per_m / lsb;
    let with_depth = |deep_s: f64, depth_m: f64| {
        let mut m = run.m.clone();
        let ch = m
            .channels
            .iter_mut()
            .find(|ch| ch.name == "depth_adc")
            .expect("the fixture measures depth");
        ch.samples = (0..1800)
            .map(|i| {
                let t = f64::from(i) * 0.1;
                let z = if t >= 50.0 && t < 50.0 + deep_s {
                    depth_m
                } else {
                    0.3
                };
                (t, code(z))
            })
            .collect();
        m
    };
    let afloat = submerged_s(&c, &with_depth(3.0, 0.6));
    assert!((afloat - 3.0).abs() < 0.2, "{afloat}");
    let shallow = submerged_s(&c, &with_depth(60.0, 0.4));
    assert!(shallow < 0.2, "0.1 m below is not submerged: {shallow}");
    let dived = submerged_s(&c, &with_depth(60.0, 0.8));
    assert!((dived - 60.0).abs() < 0.2, "{dived}");
    let chosen = || {
        vec![
            effects::by_name("thrust_gain").unwrap(),
            effects::by_name("net_buoyancy").unwrap(),
        ]
    };
    let (kept, held) = hold_submerged_only(chosen(), afloat);
    assert_eq!(
        kept.iter().map(|e| e.name).collect::<Vec<_>>(),
        ["thrust_gain"]
    );
    assert_eq!(held.len(), 1);
    assert_eq!(held[0].effect, "net_buoyancy");
    assert!(
        held[0].why.contains("3.0 s") && held[0].why.contains("dives"),
        "{}",
        held[0].why
    );
    let (kept, held) = hold_submerged_only(chosen(), dived);
    assert_eq!(kept.len(), 2);
    assert!(held.is_empty());
}

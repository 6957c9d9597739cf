//! Summary observations (`summary.toml`, docs/gap.md): the thesis's own numbers as a test.
//!
//! - SubSim 2.4 (configs/models/subsim-2.4.toml, built from the thesis's fig 5.11 and eq 5.1/5.2)
//!   against Mako's measurements (configs/measurements/mako-2008/): the workflow must name the
//!   thrust as wrong and shrink the gap, and must say honestly what it could not explain.
//! - The shipped Mako model against the same numbers: nothing significant is missing.
//! - A thrust gain hidden in summary numbers computed from a truth model is found again.

use std::path::{Path, PathBuf};

use eyebot_hil::gap::effects;
use eyebot_hil::gap::model::{EnabledEffect, GapModel};
use eyebot_hil::gap::summary::{self, Summary, SummaryAnalysis};
use eyebot_hil::gap::{Verdict, format::ExperimentInfo, format::Initial};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn mako_numbers() -> Summary {
    Summary::load(&root().join("configs/measurements/mako-2008")).expect("summary loads")
}

fn analyse(model: &str, s: &Summary) -> SummaryAnalysis {
    let model = GapModel::load(&root().join(model)).expect("model loads");
    summary::analyse(&model, s, &mut |_, _| {}).expect("gap runs")
}

fn print(a: &SummaryAnalysis) {
    for o in &a.observations {
        println!(
            "{}: measured {:.3}, before {:?} (z {:?}), after {:?} (z {:?})",
            o.name, o.measured, o.simulated_before, o.z_before, o.simulated_after, o.z_after
        );
    }
    for e in &a.fitted.effects {
        println!("effect {} {:?} {:?}", e.effect.name, e.values, e.ci95);
    }
    println!(
        "gap {:.2} -> {:.2} ({:.0} %), unexplained {:?}",
        a.gap_before, a.gap_after, a.gap_reduction_pct, a.unexplained
    );
}

/// SubSim 2.4 against Mako: the thrust is named first and found too weak (the thesis's own
/// diagnosis of alpha, 5.1/5.4) and the gap shrinks by more than half. Nothing else is named: a
/// weaker reverse thrust would make SubSim circle on a spot turn as Mako does (4.7), but its
/// fit runs into the physical limit (a reversed motor giving no thrust at all) with an
/// unbounded interval, and SubSim has no linear drag term for the drag scale to act on. So the
/// report lists the top speed, the coast-down and the spot-turn circle as unexplained instead
/// of claiming a fit.
#[test]
fn subsim_2_4_against_mako_names_weak_thrust_and_shrinks_the_gap() {
    let s = mako_numbers();
    let a = analyse("configs/models/subsim-2.4.toml", &s);
    print(&a);
    assert_eq!(a.verdict, Verdict::Effect);
    assert!(a.few_observations, "6 numbers must be flagged as few");
    assert_eq!(a.accepted[0].name, "thrust_gain", "{:?}", a.rounds[0]);
    let gain = a
        .fitted
        .effects
        .iter()
        .find(|e| e.effect.name == "thrust_gain")
        .expect("thrust_gain fitted");
    assert!(
        gain.values[0] > 0.5,
        "SubSim's thrust must come out too weak: {:?}",
        gain.values
    );
    // No effect with an unbounded interval or a parameter on its bound is named.
    for e in &a.fitted.effects {
        assert!(
            e.ci95.iter().all(|c| c[0].is_finite() && c[1].is_finite()),
            "{} named with interval {:?}",
            e.effect.name,
            e.ci95
        );
        // Final values: after the joint refit of later rounds too.
        assert!(
            effects::inside_bounds(e.effect, &e.values),
            "{} named on its bound: {:?}",
            e.effect.name,
            e.values
        );
    }
    assert!(
        a.fitted
            .effects
            .iter()
            .all(|e| e.effect.name != "reverse_thrust_asymmetry"),
        "reverse thrust named at its physical limit"
    );
    // The gap shrinks, per observation where the thrust acts...
    assert!(
        a.gap_after < 0.5 * a.gap_before,
        "{} -> {}",
        a.gap_before,
        a.gap_after
    );
    let by = summary::by_name(&a);
    for name in ["turn time anticlockwise", "turn time clockwise"] {
        let o = by[name];
        let (b, af) = (o.z_before.expect("z"), o.z_after.expect("z"));
        assert!(af.abs() < b.abs(), "{name}: |z| {b} -> {af}");
    }
    // ...and what the library cannot fix is reported, not hidden.
    assert!(!a.consistent_after);
    for name in ["top speed", "spot-turn circle"] {
        assert!(
            a.unexplained.iter().any(|n| n == name),
            "{name} not among {:?}",
            a.unexplained
        );
    }
}

/// The shipped Mako model against the same numbers: no significant missing effect, and the
/// numbers agree within their uncertainties. (mako.toml was calibrated to these very numbers,
/// docs/calibration.md, so this is a consistency check of the workflow, not new evidence.)
#[test]
fn mako_model_against_mako_numbers_has_no_significant_missing_effect() {
    let s = mako_numbers();
    let a = analyse("configs/models/mako.toml", &s);
    print(&a);
    assert_eq!(
        a.verdict,
        Verdict::None,
        "named {:?}",
        a.accepted.iter().map(|e| &e.name).collect::<Vec<_>>()
    );
    assert!(a.consistent_after, "chi2 {}", a.chi2_after);
}

/// Summary numbers computed from a truth model (Mako with 25 % more thrust), with the
/// thesis's uncertainties: the hidden thrust gain ranks first and is fitted within 10 % of
/// 0.25, but most of its evidence is in the turn times, which a lower yaw damping explains
/// within the delta-BIC margin; the verdict is `ambiguous`, the thrust gain first, and
/// nothing is named.
#[test]
fn hidden_thrust_gain_in_summary_numbers_is_found() {
    let mut s = mako_numbers();
    let model = GapModel::load(&root().join("configs/models/mako.toml")).expect("model loads");
    let mut truth = model.clone();
    let effect = effects::by_name("thrust_gain").expect("in the library");
    truth.effects.push(EnabledEffect {
        effect,
        values: vec![0.25],
        ci95: vec![[0.25, 0.25]],
        delta_bic: None,
    });
    let info = ExperimentInfo {
        name: "truth".into(),
        description: String::new(),
        duration_s: 0.0,
        world: "worlds/pool.toml".into(),
        sensors: "sensors/mako-2008.toml".into(),
        initial: Initial::default(),
        camera_position_std_m: 0.0,
        camera_speed_std_mps: 0.0,
        camera_marker_body_m: [0.0; 2],
    };
    let c = truth.configs(&info, Path::new(".")).expect("configs");
    let values = summary::predict(&c, &s, None).expect("truth runs");
    for (o, v) in s.observations.iter_mut().zip(values) {
        o.value = v.expect("truth defines every quantity");
    }
    let a = summary::analyse(&model, &s, &mut |_, _| {}).expect("gap runs");
    print(&a);
    let round0: Vec<(&str, f64, bool)> = a.rounds[0]
        .iter()
        .map(|c| (c.name.as_str(), c.delta_bic_uncalibrated, c.guards.all()))
        .collect();
    assert_eq!(a.verdict, Verdict::Ambiguous, "{round0:?}");
    assert!(a.accepted.is_empty());
    let pair = a
        .ambiguous
        .clone()
        .expect("an ambiguous verdict names its pair");
    assert_eq!(pair[0], "thrust_gain", "{round0:?}");
    let win = &a.rounds[0][0];
    assert_eq!(win.name, "thrust_gain");
    assert!(
        (win.values()[0] - 0.25).abs() <= 0.025,
        "gain {:?}",
        win.values()
    );
    let behind = win.delta_bic_uncalibrated - a.rounds[0][1].delta_bic_uncalibrated;
    assert!(behind < 10.0, "{round0:?}");
}

/// configs/vehicles/subsim-2.4.toml derives its thrust from SubSim 2.4's reported 9 cm/s top
/// speed and its yaw damping from the reported 38.5 s per circle (thesis 5.1); read the
/// thesis's way, the model must give those numbers back (or the comments in the file lie).
#[test]
fn subsim_2_4_model_reproduces_subsim_s_own_reported_numbers() {
    let s = mako_numbers();
    let model = GapModel::load(&root().join("configs/models/subsim-2.4.toml")).expect("model");
    let info = ExperimentInfo {
        name: "subsim".into(),
        description: String::new(),
        duration_s: 0.0,
        world: "worlds/pool.toml".into(),
        sensors: "sensors/mako-2008.toml".into(),
        initial: Initial::default(),
        camera_position_std_m: 0.0,
        camera_speed_std_mps: 0.0,
        camera_marker_body_m: [0.0; 2],
    };
    let c = model.configs(&info, &model.base).expect("configs");
    let values = summary::predict(&c, &s, None).expect("runs");
    let get = |name: &str| {
        s.observations
            .iter()
            .zip(&values)
            .find(|(o, _)| o.name == name)
            .and_then(|(_, v)| *v)
            .expect("defined")
    };
    let top = get("top speed");
    let turn = get("turn time anticlockwise");
    println!("SubSim 2.4 model: top speed {top:.4} m/s, turn {turn:.2} s");
    assert!((top - 0.09).abs() <= 0.005, "top speed {top}");
    assert!((turn - 38.5).abs() <= 1.0, "turn time {turn}");
}

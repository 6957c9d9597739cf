use super::*;
use crate::gap::{effects, resim};

/// The benchmark's manoeuvre, measured on the shipped model, its re-simulation, and a layout
/// of the depth and heading channels sampled at 10 Hz over the run.
fn fixture() -> (Measurement, Run, Residuals) {
    let (_, c, m) = resim::tests::manoeuvre(5);
    let run = resim::simulate(&c, &m, None).unwrap();
    let mut layout = Residuals::default();
    let end = m.experiment.duration_s;
    for name in ["depth_adc", "compass_deg"] {
        let owner = m.channels.iter().position(|c| c.name == name).unwrap();
        for k in 0..(end * 10.0) as u32 {
            layout.values.push(0.0);
            layout.owner.push(owner);
            layout.training.push(true);
            layout.times.push(f64::from(k) * 0.1);
            layout.memory_s.push(0.0);
        }
    }
    (m, run, layout)
}

fn with_change(name: &str, change: Vec<f64>) -> Candidate {
    let mut c = Candidate::untestable(effects::by_name(name).unwrap(), 100.0, "");
    c.change = change;
    c
}

/// Two effects whose changes agree everywhere but in the heading channel while the vehicle
/// turns in place differ there alone: the contrast names that channel, the spot turn first
/// among the regimes with all of the difference, and windows that hold a spot turn.
#[test]
fn two_lookalikes_differ_where_their_changes_part() {
    let (m, run, layout) = fixture();
    let compass = m
        .channels
        .iter()
        .position(|c| c.name == "compass_deg")
        .unwrap();
    let turning = |t: f64| regime_of(&run, t).contains(&"spot turn".to_string());
    let a: Vec<f64> = vec![1.0; layout.values.len()];
    let b: Vec<f64> = layout
        .owner
        .iter()
        .zip(&layout.times)
        .map(|(&o, &t)| {
            if o == compass && turning(t) {
                -1.0
            } else {
                1.0
            }
        })
        .collect();
    let c = between(
        &with_change("yaw_damping", a),
        &with_change("sway_yaw_coupling", b),
        &layout,
        &m,
        &run,
    )
    .expect("the two changes differ");
    assert_eq!(
        c.pair,
        ["yaw_damping".to_string(), "sway_yaw_coupling".to_string()]
    );
    assert_eq!(c.channels, vec![("compass_deg".to_string(), 100.0)]);
    let first = c.regimes.first().expect("a regime holds the difference");
    assert_eq!(first.regime, "spot turn", "{c:?}");
    assert!((first.difference_pct - 100.0).abs() < 1e-9, "{c:?}");
    assert!(first.samples_pct < 100.0 / REGIME_MIN_ENRICHMENT, "{c:?}");
    assert!(
        c.windows.iter().all(|w| layout
            .times
            .iter()
            .any(|&t| t >= w.0 && t < w.1 && turning(t))),
        "{c:?}"
    );
    let text = text(&c);
    assert!(text.contains("compass_deg (100 %)"), "{text}");
    assert!(
        text.contains("spot turn (100 % of the difference"),
        "{text}"
    );
}

/// Two changes that are one, or that do not match the residuals' layout, give no contrast.
#[test]
fn no_contrast_without_a_difference() {
    let (m, run, layout) = fixture();
    let n = layout.values.len();
    let same = with_change("depth_offset", vec![1.0; n]);
    assert!(between(&same, &same, &layout, &m, &run).is_none());
    let short = with_change("depth_gain", vec![1.0; n - 1]);
    assert!(between(&same, &short, &layout, &m, &run).is_none());
}

/// A small linear yaw damping hidden in the benchmark's manoeuvre, whose turns are slow: the
/// quadratic yaw damping explains the same disagreement about as well, the analysis ends on
/// the tie (`ambiguous`, or carried past), and the report says where the two differ, in the
/// heading.
#[test]
fn a_tie_is_reported_with_where_its_two_effects_differ() {
    let damping = effects::by_name("yaw_damping").unwrap();
    let (model, _, m) = resim::tests::manoeuvre_of(7, |c| effects::apply(damping, &[0.1], c));
    let options = crate::gap::Options::default();
    let a = crate::gap::analyse_with(
        &model,
        &m,
        std::path::Path::new("."),
        options,
        &mut |_, _| {},
    )
    .unwrap();
    let ties = a.ties();
    assert_eq!(
        ties,
        vec![&[
            "yaw_damping".to_string(),
            "yaw_damping_quadratic".to_string()
        ]],
        "{:?}",
        a.verdict
    );
    assert_eq!(a.contrasts.len(), 1, "{:?}", a.contrasts);
    let c = &a.contrasts[0];
    assert_eq!(&c.pair, ties[0]);
    let total: f64 = c.channels.iter().map(|(_, s)| s).sum();
    assert!((99.0..=100.0 + 1e-9).contains(&total), "{c:?}");
    assert!(
        c.channels.iter().any(|(ch, _)| ch == "compass_deg"),
        "{c:?}"
    );
    let md = crate::gap::report::markdown(&a, &m);
    assert!(
        md.contains(
            "- where they differ: `yaw_damping` and `yaw_damping_quadratic` predict the run"
        ),
        "{md}"
    );
    let json = crate::gap::report::json(&a);
    assert_eq!(
        json["where_ties_differ"][0]["pair"][1],
        "yaw_damping_quadratic"
    );
}

//! Hidden-effect and null fixtures for `eyebot-hil gap`: the data in tests/fixtures/gap/<case>/
//! were written by `eyebot-hil gap generate` from the truth models in
//! tests/fixtures/gap/truth/ (which `gap` never reads). Each test runs the whole workflow
//! against the shipped model and checks the named effect, its parameters and the gap.

use std::path::Path;

use eyebot_hil::gap::{self, Verdict, format::Measurement, model::GapModel};

fn analyse(case: &str) -> gap::Analysis {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let dir = root.join("tests/fixtures/gap").join(case);
    let m = Measurement::load(&dir).expect("fixture loads");
    let model = GapModel::load(&root.join("configs/models/mako.toml")).expect("model loads");
    gap::analyse(&model, &m, &dir, &mut |_, _| {}).expect("gap runs")
}

/// A steady current (0.03 m/s north, -0.02 m/s east) hidden in the data is named, fitted
/// within 10 % and removes at least 80 % of the gap.
#[test]
fn hidden_water_current_is_named_and_fitted() {
    let a = analyse("water-current");
    assert_eq!(a.verdict, Verdict::Effect);
    let first = &a.accepted[0];
    assert_eq!(first.name, "water_current", "{:?}", a.rounds[0]);
    let north = first.parameters[0].1;
    let east = first.parameters[1].1;
    println!(
        "water_current: north {north:.4} (truth 0.03), east {east:.4} (truth -0.02), gap reduction {:.1} %",
        a.gap_reduction_pct
    );
    assert!((north - 0.03).abs() <= 0.003, "north {north}");
    assert!((east + 0.02).abs() <= 0.002, "east {east}");
    assert!(a.gap_reduction_pct >= 80.0, "{}", a.gap_reduction_pct);
    let (b, af) = (
        a.track_distance_before_m.expect("track"),
        a.track_distance_after_m.expect("track"),
    );
    assert!(af < 0.5 * b, "track distance {b} -> {af}");
}

/// Data from the model itself: nothing may be named.
#[test]
fn null_data_name_no_effect() {
    let a = analyse("null");
    assert_eq!(
        a.verdict,
        Verdict::None,
        "named {:?}",
        a.accepted.iter().map(|e| &e.name).collect::<Vec<_>>()
    );
}

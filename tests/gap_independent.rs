//! The reality-gap workflow on data this project did not make: measurements from the
//! independent Python vehicle and sensor model (`pty-tests/independent/`), a different model
//! form with its own damping laws, thrusters, sensors, discretisation and noise, recorded
//! while closed-loop programs ran on its measured sensors. The base model
//! (`configs/models/mako.toml`) starts out wrong in thrust, drag, yaw damping and sensor
//! gains, as it would against the real vehicle.
//!
//! The order is the thesis's: calibrate on baseline runs, then look for what is new. One
//! calibration (two baseline runs, with the between-run spread) is shared by the tests of
//! this file. The seeds are not the ones the method was developed on.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

use eyebot_hil::gap::calibrate::{self, Calibration, Run};
use eyebot_hil::gap::format::Measurement;
use eyebot_hil::gap::model::GapModel;
use eyebot_hil::gap::{self, Analysis, Verdict, effects};
use eyebot_test_support::TempDir;
use eyebot_test_support::tools::require_tool;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

/// Writes a three-minute run of `program` with `hidden` (and `size`, in the effect's unit)
/// into `dir/name`.
fn generate(dir: &Path, name: &str, seed: u64, hidden: &str, size: Option<&str>) -> PathBuf {
    generate_vehicle(dir, name, None, seed, hidden, size)
}

/// As [`generate`], for the vehicle of `structure_seed` (a start away from the stated one
/// included) when given, else the nominal vehicle.
fn generate_vehicle(
    dir: &Path,
    name: &str,
    structure_seed: Option<u64>,
    seed: u64,
    hidden: &str,
    size: Option<&str>,
) -> PathBuf {
    let python = require_tool("python3", "python3");
    let out = dir.join(name);
    let mut cmd = Command::new(python);
    cmd.arg(root().join("pty-tests/independent/mako_independent.py"))
        .args([
            "--program",
            "mixed",
            "--duration",
            "180",
            "--hidden",
            hidden,
        ])
        .arg("--seed")
        .arg(seed.to_string())
        .arg("--out")
        .arg(&out)
        .env("PYTHONDONTWRITEBYTECODE", "1");
    if let Some(s) = size {
        cmd.args(["--size", s]);
    }
    if let Some(k) = structure_seed {
        cmd.arg("--structure-seed").arg(k.to_string());
    }
    let status = cmd.status().expect("python3 runs");
    assert!(status.success(), "the independent model failed on {name}");
    out
}

/// The shared calibration: baseline runs 7301 and 7302, validated on 7303. The runs are
/// read into memory and their directory is removed before the calibration is shared (a
/// static is never dropped, so it must not hold a temporary directory).
fn calibrated() -> &'static Calibration {
    static CAL: OnceLock<Calibration> = OnceLock::new();
    CAL.get_or_init(|| calibration(&[]))
}

/// The calibration as the README's protocol has it: as [`calibrated`], and the between-run
/// spread measured on two null runs of the programme the cases run (`--spread-from`).
fn calibrated_with_spread() -> &'static Calibration {
    static CAL: OnceLock<Calibration> = OnceLock::new();
    CAL.get_or_init(|| calibration(&[7305, 7306]))
}

/// Calibrates on baseline runs 7301 and 7302, validated on 7303, with the between-run
/// spread from null runs of `spread_seeds` (none: from the baseline runs).
fn calibration(spread_seeds: &[u64]) -> Calibration {
    let dir = TempDir::new("gap-calibration");
    let runs = |prefix: &str, seeds: &[u64]| -> Vec<Run> {
        seeds
            .iter()
            .map(|s| {
                let d = generate(dir.path(), &format!("{prefix}-{s}"), *s, "none", None);
                Run::load(&d).expect("run loads")
            })
            .collect()
    };
    let base = runs("base", &[7301, 7302]);
    let validate = runs("validate", &[7303]);
    let spread = runs("spread", spread_seeds);
    let model = GapModel::load(&root().join("configs/models/mako.toml")).expect("model");
    calibrate::calibrate(&model, &base, &validate, &spread, &mut |_| {}).expect("calibrates")
}

/// Calibrates the shipped model on null runs 7311-7313 of the vehicle of `structure`
/// (written into `dir`, as `base-SEED`), validated on 7314.
fn calibrate_structure(dir: &Path, structure: u64) -> Calibration {
    let run = |name: &str, seed: u64| {
        let d = generate_vehicle(dir, name, Some(structure), seed, "none", None);
        Run::load(&d).expect("run loads")
    };
    let base: Vec<Run> = [7311, 7312, 7313]
        .iter()
        .map(|s| run(&format!("base-{s}"), *s))
        .collect();
    let validate = vec![run("validate-7314", 7314)];
    let model = GapModel::load(&root().join("configs/models/mako.toml")).expect("model");
    calibrate::calibrate(&model, &base, &validate, &[], &mut |_| {}).expect("calibrates")
}

/// The calibration's score on its validation run.
fn validation(c: &Calibration) -> &calibrate::RunGap {
    c.runs
        .iter()
        .find(|r| r.role == calibrate::RunRole::Validation)
        .expect("validation run scored")
}

/// `gap` with the calibrated model on a fresh run.
fn discover(name: &str, seed: u64, hidden: &str, size: Option<&str>) -> Analysis {
    let c = calibrated();
    let scratch = TempDir::new("gap-discover");
    let dir = generate(scratch.path(), name, seed, hidden, size);
    let m = Measurement::load(&dir).expect("run loads");
    let a = gap::analyse(&c.model, &m, &dir, &mut |_, _| {}).expect("gap runs");
    // Whatever the verdict: an accepted fit never grows the gap on the blocks it was not
    // fitted to.
    if !a.accepted.is_empty() {
        assert!(
            a.heldout_gap_after <= a.heldout_gap_before,
            "{name}: accepted {:?} grew the held-out gap {} -> {}",
            a.accepted.iter().map(|e| &e.name).collect::<Vec<_>>(),
            a.heldout_gap_before,
            a.heldout_gap_after
        );
        assert!(
            a.raw.heldout_after <= a.raw.heldout_before,
            "{name}: against the noise floor alone the held-out gap grew {} -> {}",
            a.raw.heldout_before,
            a.raw.heldout_after
        );
    }
    a
}

fn names(a: &Analysis) -> Vec<&str> {
    a.accepted.iter().map(|e| e.name.as_str()).collect()
}

/// What a failed naming assertion prints: what was named, the verdict and round 1's leaders.
fn explain(a: &Analysis) -> String {
    let round1: Vec<String> = a
        .rounds
        .first()
        .map(|r| r.as_slice())
        .unwrap_or_default()
        .iter()
        .take(4)
        .map(|c| {
            format!(
                "{} (dBIC {:.1}, held-out gain {:?}, signature {}, {:?})",
                c.name, c.delta_bic, c.heldout_gain, c.signature_pass, c.parameters
            )
        })
        .collect();
    format!(
        "named {:?}, verdict {:?}, refused {:?}; round 1: {}",
        names(a),
        a.verdict,
        a.refused,
        round1.join("; ")
    )
}

/// Calibration on two baseline runs more than halves the gap on a third run it never saw.
#[test]
fn calibration_halves_the_gap_on_a_run_it_was_not_fitted_to() {
    let c = calibrated();
    let held: Vec<_> = c
        .runs
        .iter()
        .filter(|r| r.role == calibrate::RunRole::Validation)
        .collect();
    assert_eq!(held.len(), 1);
    let r = held[0];
    assert!(
        r.reduction_pct >= 50.0,
        "validation run: gap {:.2} -> {:.2} ({:.0} % smaller)",
        r.gap_before,
        r.gap_after,
        r.reduction_pct
    );
    // The calibration found the shape of the thrust deficit built into the independent
    // model (about -11 % at full power, -27 % at half: half-range thrust 0.73 / 0.89 = 0.82
    // of full-range thrust, relative to the model's). The curve's shape is what these data
    // identify: its scale is not, because thrust, drag and added mass scaled together move
    // the hull alike and the buoyancy term absorbs the vertical pair's share (two fits
    // with the same gap on these runs put the scale 3 % and 15 % up).
    let value = |effect: &str| {
        c.parameters
            .iter()
            .find(|p| p.effect == effect)
            .unwrap_or_else(|| panic!("{effect} calibrated"))
            .value
    };
    let curve = value("thrust_curve");
    let shape = 0.5_f64.powf(curve);
    assert!(
        (shape - 0.73 / 0.89).abs() < 0.05,
        "half-range thrust x{shape:.3} of full-range (curve {curve:.3}); the truth 0.82"
    );
    assert!(!c.spread.is_empty(), "two baseline runs give a spread");
    // ... measured with one degree of freedom: the joint fit already used the other.
    assert_eq!(c.model.spread_dof, Some(1));
    // The model discrepancy: every discrepancy term of the library is calibrated, so the
    // independent hull's sway, yaw inertia, heave and buoyancy have a place of their own.
    for e in effects::LIBRARY
        .iter()
        .filter(|e| matches!(e.calibration, effects::Calibration::Discrepancy(_)))
    {
        assert!(
            c.parameters.iter().any(|p| p.effect == e.name),
            "discrepancy term {} not calibrated; calibrated: {:?}",
            e.name,
            c.parameters.iter().map(|p| &p.effect).collect::<Vec<_>>()
        );
    }
    // The calibrated model's known disagreement: every measured channel, each still above the
    // noise floor (the independent model's form is not the model's).
    assert_eq!(c.discrepancy.len(), r.channels.len(), "{:?}", c.discrepancy);
    assert!(
        c.discrepancy.iter().all(|(_, v)| *v > 1.0),
        "{:?}",
        c.discrepancy
    );
}

/// A vehicle of another structure: structure seed 52361 (no Munk moment, purely quadratic
/// surge drag, `Y_r` and `N_v` both positive, two thrusters saturating early, a start away
/// from the stated one). Calibration on three baseline runs shrinks a fourth run's gap by
/// the 60 % the workflow promises. On this vehicle the joint fit used to stop near the model
/// as given (10 % smaller: the accelerometers outweighed the other channels twenty to one and
/// the clamped search stalled on their bounds), then at 57 % (channels brought to chi2 = 1
/// each: a camera track below its floor outvoted the compass).
#[test]
fn calibration_shrinks_the_gap_of_a_vehicle_of_another_structure_by_60_percent() {
    let dir = TempDir::new("gap-structure");
    let c = calibrate_structure(dir.path(), 52361);
    let r = validation(&c);
    assert!(
        r.reduction_pct >= 60.0,
        "validation run: gap {:.2} -> {:.2} ({:.0} % smaller); channels {:?}",
        r.gap_before,
        r.gap_after,
        r.reduction_pct,
        r.channels
    );
}

/// A hull of another heave (structure seed 466433: 22 kg of heave added mass against the
/// model's 35, quadratic heave drag 77 against 50, vertical thrusters with their own curves)
/// leaves the depth sensor's gain where its datasheet and the vehicle put it. Baseline runs
/// inform that gain mostly through the model's heave, and with only the weak prior the
/// calibration put it at 0.17 [0.10, 0.24] on these runs (0.29 [0.20, 0.38] on the
/// benchmark's runs of this vehicle), whose sensor is 1.2 % off: the heave's error went into
/// the sensor, and every later depth offset came out a fifth short. The model file's
/// `[prior]` holds the gain to its datasheet.
#[test]
fn calibration_leaves_the_depth_sensor_gain_to_its_datasheet_on_a_hull_of_another_heave() {
    let dir = TempDir::new("gap-heave");
    let c = calibrate_structure(dir.path(), 466433);
    let truth: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("base-7311/truth.json")).expect("truth"),
    )
    .expect("truth parses");
    let vehicle_v_per_m = truth["sensors"]["depth_gain_v_per_m"]
        .as_f64()
        .expect("the vehicle's depth gain");
    let sensors: toml::Table =
        std::fs::read_to_string(root().join("configs/sensors/mako-2008.toml"))
            .expect("sensors")
            .parse()
            .expect("sensors parse");
    let shipped_v_per_m = sensors["depth"]["volts_per_m"]
        .as_float()
        .expect("the shipped depth gain");
    let gain_error = vehicle_v_per_m / shipped_v_per_m - 1.0;
    let gain = c
        .parameters
        .iter()
        .find(|p| p.effect == "depth_gain")
        .expect("the depth gain is calibrated");
    assert!(
        gain.ci95[0] <= gain_error && gain_error <= gain.ci95[1],
        "depth_gain {:.3} [{:.3}, {:.3}] against the vehicle's {gain_error:.3}",
        gain.value,
        gain.ci95[0],
        gain.ci95[1]
    );
    let r = validation(&c);
    assert!(
        r.reduction_pct >= 60.0,
        "validation run: gap {:.2} -> {:.2} ({:.0} % smaller)",
        r.gap_before,
        r.gap_after,
        r.reduction_pct
    );
}

/// A run with nothing hidden names nothing once the model is calibrated. It disagrees with
/// the model far beyond the noise floor, as every run of the independent model does, but no
/// more than runs with nothing new do: nothing is new, and the verdict says so. The verdict
/// needs the between-run spread (`--spread-from`): without it the known disagreement is the
/// one validation run's, and depth, which runs of this programme fit from 1.1 to 2.7 per
/// sample once the surface's stiffness and damping are calibrated, reads as still off.
#[test]
fn a_null_run_after_calibration_names_nothing() {
    let scratch = TempDir::new("gap-discover");
    let dir = generate(scratch.path(), "null-7304", 7304, "none", None);
    let m = Measurement::load(&dir).expect("run loads");
    let analyse = |c: &Calibration| gap::analyse(&c.model, &m, &dir, &mut |_, _| {});
    let a = analyse(calibrated()).expect("gap runs");
    assert!(a.accepted.is_empty(), "null run named {:?}", names(&a));
    let a = analyse(calibrated_with_spread()).expect("gap runs");
    assert!(a.accepted.is_empty(), "null run named {:?}", names(&a));
    // The calibration's discrepancy terms are never candidates.
    for c in a.rounds.iter().flatten() {
        let e = effects::by_name(&c.name).expect("a library effect");
        assert!(
            e.candidate(),
            "{} is a discrepancy term, not a candidate",
            c.name
        );
    }
    assert!(!a.rounds.is_empty());
    assert!(
        a.raw.heldout_before > 0.5,
        "against the noise floor alone the held-out gap is {}",
        a.raw.heldout_before
    );
    assert_eq!(
        a.verdict,
        Verdict::None,
        "still off: {:?}",
        a.unexplained
            .iter()
            .map(|u| (&u.channel, u.chi2_per_sample))
            .collect::<Vec<_>>()
    );
}

/// A water current twice the model's default size is named first, with its north component
/// within 0.01 m/s of the truth. The east component (-0.03 m/s) is not recovered: fits give
/// -0.005 to +0.001 m/s with intervals that exclude the truth (`docs/gap.md`, Limits), so it
/// is not asserted.
#[test]
fn a_hidden_water_current_is_named_first() {
    let a = discover("current-7305", 7305, "water_current", Some("0.04,-0.03"));
    assert_eq!(names(&a).first(), Some(&"water_current"), "{}", explain(&a));
    let p = &a.accepted[0].parameters;
    assert!((p[0].1 - 0.04).abs() < 0.01, "current {p:?}");
}

/// `gap-bench --pairs` hands the independent model two effects whose first size is negative
/// (`-0.3;8`), which an option parser reads as an option unless it is given as `--size=V`
/// (a campaign's shard once died on it). The run is written, both effects named in it.
#[test]
fn a_two_effect_case_with_a_negative_first_size_is_written() {
    use eyebot_hil::gap::bench::calibrated::Truth;
    use eyebot_hil::gap::bench::independent::{Independent, by_name};
    require_tool("python3", "python3");
    let scratch = TempDir::new("gap-pair-size");
    let program = root().join("pty-tests/independent/mako_independent.py");
    let truth = Independent::new(&program, None, false, 0).expect("the independent model exists");
    let gain = by_name("thrust_gain").expect("an independent effect");
    let offset = by_name("compass_offset").expect("an independent effect");
    let out = scratch.path().join("pair");
    truth
        .case(7310, &[(gain, &[-0.3]), (offset, &[8.0])], &out)
        .expect("the independent model takes both sizes");
    let m = Measurement::load(&out).expect("the run loads");
    assert!(
        m.experiment.name.contains("thrust_gain+compass_offset"),
        "{}",
        m.experiment.name
    );
}

/// With drawn programmes (`gap-bench --drawn-programs`) the cases and spread runs of a
/// campaign drive one programme of the model's kinds, drawn from the campaign's seeds, and
/// each baseline run one the model draws per run: campaigns do not all drive `mixed`, and a
/// calibration sees other programmes than its cases.
#[test]
fn drawn_programmes_give_the_cases_one_programme_and_the_baselines_their_own() {
    use eyebot_hil::gap::bench::calibrated::Truth;
    use eyebot_hil::gap::bench::independent::{Independent, program_kinds};
    require_tool("python3", "python3");
    let scratch = TempDir::new("gap-drawn-programs");
    let program = root().join("pty-tests/independent/mako_independent.py");
    let kinds = program_kinds(&program).expect("the model lists its programmes");
    for kind in [
        "mixed",
        "spins",
        "square",
        "heading_hold",
        "depth_hold",
        "wall_run",
    ] {
        assert!(
            kinds.iter().any(|k| k == kind),
            "{kind} missing from {kinds:?}"
        );
    }
    let drawn = |seed| {
        Independent::new(&program, Some(11), true, seed)
            .expect("the independent model exists")
            .case_program()
            .to_string()
    };
    let campaigns: Vec<String> = (1..=12).map(drawn).collect();
    assert_eq!(
        campaigns,
        (1..=12).map(drawn).collect::<Vec<_>>(),
        "drawn again"
    );
    let distinct: std::collections::BTreeSet<&String> = campaigns.iter().collect();
    assert!(
        distinct.len() >= 3,
        "twelve campaigns drew only {distinct:?}"
    );
    let truth = Independent::new(&program, Some(11), true, 5).expect("the model exists");
    let run_program = |dir: &Path| {
        let m = Measurement::load(dir).expect("the run loads");
        kinds
            .iter()
            .find(|k| {
                m.experiment
                    .name
                    .starts_with(&format!("independent-{k}-seed"))
            })
            .cloned()
            .unwrap_or_else(|| panic!("no programme of {kinds:?} in {}", m.experiment.name))
    };
    for seed in [7311, 7312] {
        let out = scratch.path().join(format!("case-{seed}"));
        truth.case(seed, &[], &out).expect("a null case is written");
        assert_eq!(run_program(&out), truth.case_program());
    }
    let baselines: std::collections::BTreeSet<String> = (0..8)
        .map(|i| {
            let out = scratch.path().join(format!("baseline-{i}"));
            truth
                .baseline(i, 7320 + i as u64, &out)
                .expect("a baseline run is written");
            run_program(&out)
        })
        .collect();
    assert!(
        baselines.len() >= 2,
        "eight baseline runs all drove {baselines:?}"
    );
}

/// A thrust loss of 20 % on every motor (a weak battery) is named first, as a loss.
#[test]
fn a_hidden_thrust_loss_is_named_first() {
    let a = discover("thrust-7306", 7306, "thrust_gain", Some("-0.2"));
    assert_eq!(names(&a).first(), Some(&"thrust_gain"), "{}", explain(&a));
    assert!(a.accepted[0].parameters[0].1 < 0.0);
}

/// Motor noise on the depth channel, three times the independent model's default, named
/// after a calibration that measured the baseline's own level of duty-correlated depth noise
/// (whatever its cause) and took it as the model's.
#[test]
fn a_hidden_depth_emi_is_named_after_calibration() {
    let a = discover("emi-7307", 7307, "depth_emi", Some("0.09"));
    assert_eq!(names(&a).first(), Some(&"depth_pwm_emi"), "{}", explain(&a));
}

/// The analysis of a copy of `dir` whose `experiment.toml` states another start: `edit`
/// changes the `[initial]` table.
fn discover_moved(name: &str, dir: &Path, edit: &dyn Fn(&mut toml::Table)) -> Analysis {
    let c = calibrated();
    let scratch = TempDir::new("gap-moved");
    let moved = scratch.path().join(name);
    std::fs::create_dir_all(&moved).expect("copy dir");
    for f in ["commands.csv", "measured.csv", "experiment.toml"] {
        std::fs::copy(dir.join(f), moved.join(f)).expect("copy");
    }
    let path = moved.join("experiment.toml");
    let mut doc: toml::Table = toml::from_str(&std::fs::read_to_string(&path).expect("read"))
        .expect("experiment.toml parses");
    let initial = doc
        .get_mut("initial")
        .and_then(toml::Value::as_table_mut)
        .expect("[initial]");
    edit(initial);
    std::fs::write(&path, toml::to_string(&doc).expect("writes")).expect("write");
    let m = Measurement::load(&moved).expect("moved run loads");
    gap::analyse(&c.model, &m, &moved, &mut |_, _| {}).expect("gap runs")
}

/// Regression (the start was trusted: a run whose `experiment.toml` put the vehicle at the
/// surface while it floated 0.27 m down carried a depth chi2/n of about 9,100 in its first
/// seconds): the same run with its stated start 0.3 m off in every direction and 20 deg off
/// in heading gives the same verdict and names, each value inside the other's interval.
#[test]
fn a_wrong_stated_start_gives_the_same_answer() {
    let scratch = TempDir::new("gap-start");
    let dir = generate(
        scratch.path(),
        "offset-7308",
        7308,
        "compass_offset",
        Some("8"),
    );
    let m = Measurement::load(&dir).expect("run loads");
    let a = gap::analyse(&calibrated().model, &m, &dir, &mut |_, _| {}).expect("gap runs");
    let shift = |t: &mut toml::Table, key: &str, by: f64| {
        let v = t.get(key).and_then(toml::Value::as_float).unwrap_or(0.0);
        t.insert(key.into(), toml::Value::Float(v + by));
    };
    let b = discover_moved("offset-7308-moved", &dir, &|t| {
        shift(t, "x_m", 0.3);
        shift(t, "y_m", -0.3);
        shift(t, "z_m", 0.3);
        shift(t, "heading_deg", 20.0);
    });
    assert_eq!(a.verdict, b.verdict);
    assert_eq!(names(&a), names(&b));
    for (x, y) in a.accepted.iter().zip(&b.accepted) {
        for ((_, va), ((_, vb), (_, ci))) in
            x.parameters.iter().zip(y.parameters.iter().zip(&y.ci95))
        {
            assert!(
                ci[0] <= *va && *va <= ci[1],
                "{}: {va} outside the moved run's {ci:?} (value {vb})",
                x.name
            );
        }
    }
    assert!(
        (a.excess_before - b.excess_before).abs() <= 0.05 * a.excess_before.max(0.1),
        "gap before {} vs {}",
        a.excess_before,
        b.excess_before
    );
}

/// Two hidden effects at once, a water current and a compass mounted 8 deg rotated: both
/// are named, their intervals cover the hidden sizes, and each has a share of the shrink.
#[test]
fn two_hidden_effects_are_both_named() {
    let a = discover(
        "two-7309",
        7309,
        "water_current+compass_offset",
        Some("0.04,-0.03;8"),
    );
    let named = names(&a);
    assert!(
        named.contains(&"water_current") && named.contains(&"compass_offset"),
        "{}",
        explain(&a)
    );
    // Each named effect's values come from the refit of both together; their intervals
    // cover the hidden sizes.
    for (name, truth) in [
        ("water_current", vec![0.04, -0.03]),
        ("compass_offset", vec![8.0]),
    ] {
        let c = a.accepted.iter().find(|c| c.name == name).unwrap();
        for ((p, ci), t) in c.ci95.iter().zip(&truth) {
            assert!(ci[0] <= *t && *t <= ci[1], "{name}.{p}: {ci:?} misses {t}");
        }
    }
    assert_eq!(a.shares_pct.len(), a.accepted.len());
    let total: f64 = a.shares_pct.iter().sum();
    assert!((total - 100.0).abs() < 1e-6, "{:?}", a.shares_pct);
}

/// The independent model's own checks (`pty-tests/independent/test_mako_independent.py`: the
/// pinned nominal runs, the structure family's draws, two hidden effects, the file format, a
/// hull carried by the current as it turns), so that the README's test command runs them.
#[test]
fn the_independent_models_own_checks_pass() {
    let python = require_tool("python3", "python3");
    let out = Command::new(python)
        .args(["-m", "unittest", "-q"])
        .current_dir(root().join("pty-tests/independent"))
        .env("PYTHONDONTWRITEBYTECODE", "1")
        .output()
        .expect("python3 runs");
    assert!(
        out.status.success(),
        "python3 -m unittest in pty-tests/independent failed:\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

/// One case of a structural campaign on the independent model, as `gap-bench --source
/// independent --structure-seed STRUCTURE --seed SEED --cases CASES --pairs PAIRS --shard
/// K/N` runs it (its own calibration first): the hidden effects, and every name `gap` gave.
fn structural_case(
    structure: u64,
    seed: u64,
    (cases, pairs): (usize, usize),
    (k, n): (usize, usize),
) -> (Option<String>, Vec<String>) {
    use eyebot_hil::gap::bench::{self, BenchOptions, Shard, Source};
    require_tool("python3", "python3");
    let opts = BenchOptions {
        source: Source::Independent,
        cases,
        seed,
        effects: Vec::new(),
        hidden: bench::independent::HIDDEN.iter().collect(),
        independent_path: root().join("pty-tests/independent/mako_independent.py"),
        structure_seed: Some(structure),
        drawn_programs: false,
        pairs,
        baselines: 3,
        bridge: Default::default(),
        keep: None,
    };
    let shard = Shard::new(k, n).expect("valid shard");
    let part = bench::run_part(&opts, shard, None, &mut |_, _, _, _| {}).expect("the case runs");
    assert_eq!(part.results.len(), 1, "shard {k}/{n} holds one case");
    let case = part.results.into_iter().next().expect("one case");
    (case.effect, case.named_all)
}

/// An exchange of an earlier name for its look-alike must shrink the gap by the measure the
/// report gives, every channel counted once, not the summed chi-square alone. On structure
/// 866197 (campaign seed 811733) pair case 78 hides a thrust gain and a compass offset; both
/// are named in their rounds. A thrust curve and a yaw damping in their place lower the summed
/// chi-square by about 1457 (the track's and accelerometers' many samples) while the channels'
/// mean over their known levels rises from 1.47 to 4.5: the pair named stays.
#[test]
fn an_exchange_that_raises_the_channels_mean_is_not_made() {
    let (hidden, named) = structural_case(866197, 811733, (5, 10), (79, 80));
    assert_eq!(hidden.as_deref(), Some("thrust_gain+compass_offset"));
    assert_eq!(named, ["thrust_gain", "compass_offset"]);
}

/// A first name's look-alike is tried in its place from a cosine of 0.8 between their changes
/// of the residuals (`gap::later::EXCHANGE_COSINE`), not only at 0.9, where two fits explain
/// one disagreement. On structure 910361 (campaign seed 855931) pair case 35 hides a thrust
/// gain of 29 sigma and a yaw damping. A thrust curve wins the first round, its change at
/// cosine 0.86 to the gain's, and a reverse-thrust asymmetry the second; exchanged for the
/// gain and the yaw damping, the channels' mean over their known levels falls from 4.5 to
/// 1.3: both hidden effects are named.
#[test]
fn a_first_name_gives_way_to_a_look_alike_that_parts_from_it() {
    let (hidden, named) = structural_case(910361, 855931, (0, 40), (36, 40));
    assert_eq!(hidden.as_deref(), Some("yaw_damping+thrust_gain"));
    assert_eq!(named, ["thrust_gain", "yaw_damping"]);
}

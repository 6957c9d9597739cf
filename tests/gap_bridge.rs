//! The bridge source of `gap-bench`: a C example, unchanged, recorded through a private
//! lockstep daemon with the bridge's vehicle, then converted to a measurement. A hidden
//! effect must reach the daemon (a water current carries the vehicle) and nothing of the
//! truth may reach the measurement's set-up (it names the model's own sensor and world
//! files).

use std::path::Path;

use eyebot_hil::gap::bench::bridge::{Bridge, BridgeOptions, HIDDEN};
use eyebot_hil::gap::bench::calibrated::Truth;
use eyebot_hil::gap::format::Measurement;
use eyebot_test_support::TempDir;
use eyebot_test_support::eyebot_c::{self, Target};

/// Mean of a channel's samples after `from_s`.
fn mean_after(m: &Measurement, channel: &str, from_s: f64) -> f64 {
    let ch = m
        .channels
        .iter()
        .find(|c| c.name == channel)
        .unwrap_or_else(|| panic!("no {channel} channel"));
    let v: Vec<f64> = ch
        .samples
        .iter()
        .filter(|(t, _)| *t >= from_s)
        .map(|(_, v)| *v)
        .collect();
    assert!(!v.is_empty(), "{channel}: no samples after {from_s} s");
    v.iter().sum::<f64>() / v.len() as f64
}

#[test]
fn a_hidden_current_reaches_the_daemon_and_the_measurement_names_the_model_files() {
    let programs = eyebot_c::build(
        env!("CARGO_TARGET_TMPDIR"),
        "gap-bridge",
        Target::Host,
        &[],
        &[],
    );
    let bridge = Bridge::new(&BridgeOptions {
        exe: Some(env!("CARGO_BIN_EXE_eyebot-hil").into()),
        programs: Some(programs),
    })
    .expect("the bridge source");
    let tmp = TempDir::new("gap-bridge");
    let current = HIDDEN
        .iter()
        .find(|h| h.name == "water_current")
        .expect("the bridge hides a current");
    let null_dir = tmp.path().join("null");
    let hidden_dir = tmp.path().join("current");
    bridge.case(4242, &[], &null_dir).expect("a null case");
    bridge
        .case(4242, &[(current, &[0.08, 0.0])], &hidden_dir)
        .expect("a case with a current");
    let null = Measurement::load(&null_dir).expect("null measurement");
    let hidden = Measurement::load(&hidden_dir).expect("current measurement");
    for m in [&null, &hidden] {
        for ch in ["x_m", "y_m", "compass_deg", "depth_adc", "paddle_speed_mps"] {
            assert!(
                m.channels
                    .iter()
                    .any(|c| c.name == ch && !c.samples.is_empty()),
                "{ch} missing"
            );
        }
        assert_eq!(m.experiment.world, "worlds/pool.toml");
        assert_eq!(m.experiment.sensors, "sensors/mako-2008.toml");
        assert!(
            m.commands.len() > 10,
            "the program's commands: {}",
            m.commands.len()
        );
    }
    // 0.08 m/s north for about a minute of the square course: metres, not centimetres.
    let drift = mean_after(&hidden, "x_m", 60.0) - mean_after(&null, "x_m", 60.0);
    assert!(
        drift > 2.0,
        "the current moved the vehicle {drift:.2} m north"
    );
    // The set-up files stay in the scratch directory of the case, never in the measurement.
    for dir in [&null_dir, &hidden_dir] {
        assert!(!Path::new(&dir.with_extension("bridge")).exists());
    }
}

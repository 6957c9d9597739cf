//! Every file in configs/sensors/ loads; bad values are reported at their line and key.

use eyebot_hil::config::{ConfigError, Directory};
use eyebot_hil::sensors::SensorsConfig;

fn dir() -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("configs/sensors")
}

#[test]
fn every_sensor_config_loads() {
    let mut n = 0;
    for entry in std::fs::read_dir(dir()).unwrap() {
        let name = entry.unwrap().file_name().to_string_lossy().into_owned();
        if name.ends_with(".toml") {
            SensorsConfig::load(&Directory::new(dir()), &name).unwrap_or_else(|e| panic!("{e}"));
            n += 1;
        }
    }
    assert!(n >= 2, "expected mako-2008 and mako-original, found {n}");
}

fn with(replace: &str, by: &str) -> Result<SensorsConfig, ConfigError> {
    let text = std::fs::read_to_string(dir().join("mako-2008.toml")).unwrap();
    assert!(text.contains(replace), "fixture lacks {replace}");
    SensorsConfig::from_text("edited.toml", &text.replacen(replace, by, 1))
}

#[test]
fn out_of_range_value_names_line_and_key() {
    let err = with("bits = 10 ", "bits = 40 ").unwrap_err();
    let msg = err.to_string();
    assert!(
        matches!(err, ConfigError::Invalid { line: Some(_), .. }),
        "{msg}"
    );
    assert!(msg.contains("adc.bits"), "{msg}");
}

#[test]
fn an_accelerometer_outside_the_hull_is_rejected_by_key() {
    let err = with(
        "position_body_m = [0.0, 0.0, 0.0]   # m, where the part sits",
        "position_body_m = [3.0, 0.0, 0.0]   # m, where the part sits",
    )
    .unwrap_err();
    assert!(
        err.to_string().contains("accelerometer.position_body_m.0"),
        "{err}"
    );
}

#[test]
fn unknown_key_is_rejected_with_its_line() {
    let err = with("[compass]\n", "[compass]\nfeild_ut = 3.0\n").unwrap_err();
    assert!(matches!(err, ConfigError::Syntax { .. }), "{err}");
    assert!(err.to_string().contains("feild_ut"), "{err}");
}

#[test]
fn two_devices_on_one_channel_is_an_error() {
    let err = with("velocity = 1\n", "velocity = 0\n").unwrap_err();
    assert!(err.to_string().contains("already wired"), "{err}");
}

#[test]
fn detection_table_must_have_matching_lengths() {
    let err = with("detection_percent = [99.0, ", "detection_percent = [").unwrap_err();
    assert!(err.to_string().contains("sonar.detection_percent"), "{err}");
}

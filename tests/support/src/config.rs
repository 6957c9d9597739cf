//! Daemon configurations written for a test: `configs/default.toml` with its model files
//! named by absolute path (so the file works from any directory) and lines replaced.

use std::path::PathBuf;

use eyebot_hil::config::DEFAULT_CONFIG;

/// The repository's `configs/` directory.
pub fn configs_dir() -> PathBuf {
    crate::workspace_root().join("configs")
}

/// The start line of `configs/default.toml` (2.5 m off the west wall, facing north).
pub const DEFAULT_START: &str = "position_m = [3.0, 2.5, 0.3]";

/// 1.5 m off the west wall, heading north, so the port-side transducers (1 and 2, pointing
/// 75 and 105 deg to port) see the wall at about (1.5 - 0.32) / sin 75 deg = 1.22 m.
pub const NEAR_WALL: (&str, &str) = (DEFAULT_START, "position_m = [3.0, 1.5, 0.5]");

/// Lockstep time in place of the default realtime.
pub const LOCKSTEP: (&str, &str) = ("time_mode = \"realtime\"", "time_mode = \"lockstep\"");

/// `configs/default.toml` with absolute model paths and each `(line, replacement)` of
/// `edits` applied to a line that must exist verbatim.
pub fn config_text(edits: &[(&str, &str)]) -> String {
    let configs = configs_dir();
    let mut text =
        std::fs::read_to_string(configs.join(DEFAULT_CONFIG)).expect("read configs/default.toml");
    for key in ["vehicle", "world", "sensors"] {
        let line = text
            .lines()
            .find(|l| l.starts_with(&format!("{key} = ")))
            .expect("the default config names its model files")
            .to_string();
        let name = line
            .split('"')
            .nth(1)
            .expect("a quoted model file name")
            .to_string();
        let absolute = format!("{key} = \"{}\"", configs.join(&name).display());
        text = text.replace(&line, &absolute);
    }
    for (from, to) in edits {
        assert!(
            text.lines().any(|l| l == *from),
            "config line `{from}` not found in configs/default.toml"
        );
        text = text.replace(from, to);
    }
    text
}

/// The edits that start the vehicle at `position_m` (north, east, down), heading
/// `heading_deg`: pass them to [`config_text`] through [`as_edits`].
pub fn start_at(position_m: [f64; 3], heading_deg: f64) -> [(String, String); 2] {
    [
        (
            DEFAULT_START.to_string(),
            format!(
                "position_m = [{:?}, {:?}, {:?}]",
                position_m[0], position_m[1], position_m[2]
            ),
        ),
        (
            "heading_deg = 0.0".to_string(),
            format!("heading_deg = {heading_deg:?}"),
        ),
    ]
}

/// Borrows owned edits as the `(&str, &str)` pairs [`config_text`] takes.
pub fn as_edits(edits: &[(String, String)]) -> Vec<(&str, &str)> {
    edits
        .iter()
        .map(|(a, b)| (a.as_str(), b.as_str()))
        .collect()
}

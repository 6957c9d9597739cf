//! Closed-loop recordings through the bridge: the project's C examples, unchanged, drive a
//! private lockstep daemon (`eyebot-hil check`, the daemon recording with `--record`) whose
//! vehicle, sensor and world files differ from the model's in form as well as in parameters
//! ([`FORM`]); each recording becomes a measurement through `gap convert` with the model's
//! own (nominal) sensor and world files and a seeded overhead-camera track, as a user with a
//! real vehicle would have it. A hidden effect is one more edit of those files ([`HIDDEN`],
//! [`edits_for`]), in the library effect's own parameters, so the right answer is exact.
//!
//! Calibration runs: `timer_square` (a square course at depth, the pilot and a 10 ms paddle
//! timer), `spot_turn`, `heading_hold`; the run it is scored on, the [`SPREAD_RUNS`] runs the
//! spread is measured on and every case: `timer_square`. The case loop and scoring are [`super::calibrated`]'s.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::sync::LazyLock;

use crate::config::{ConfigSource, Embedded};
use crate::gap::GapError;
use crate::gap::bench::calibrated::{Hidden, Truth, io};
use crate::gap::convert::{ConvertOptions, convert};
pub use crate::gap::edit::{Change, Edit, File, edit};
use crate::gap::effects;

/// Simulated length of a case (s): `timer_square` dives, flies its four legs and surfaces
/// (about 97 s; the programs that do not end by themselves are stopped here).
pub const DURATION_S: u32 = 110;
/// The program of every case and of the run calibration is scored on.
pub const CASE_PROGRAM: &str = "timer_square";
/// The calibration runs' programs, in order (the last is the run it is scored on).
pub const BASELINE_PROGRAMS: [&str; 4] =
    ["timer_square", "spot_turn", "heading_hold", "timer_square"];
/// Null runs of [`CASE_PROGRAM`] the between-run spread is measured on: the calibration
/// runs are three programmes, whose differences in model error are no spread of a case.
pub const SPREAD_RUNS: usize = 3;
/// The overhead camera's noise on the converted track (m, 1 sigma).
pub const CAMERA_STD_M: f64 = 0.01;

/// Where the bridge source finds its programs.
#[derive(Debug, Clone, Default)]
pub struct BridgeOptions {
    /// The `eyebot-hil` executable that runs the daemon; default: this program.
    pub exe: Option<PathBuf>,
    /// A directory with host builds of the C examples (`make -C firmware-protocol/c
    /// OUT=DIR`); default: built into a scratch directory with `make`.
    pub programs: Option<PathBuf>,
}

/// How the bridge's vehicle and sensors differ from the model's files, before anything is
/// hidden. Terms the model lacks (form): a sway force from yaw rate (`Y_r`), a thrust curve
/// that is not linear in the on-fraction, a slower depth filter with another lever arm, a
/// stronger soft iron, more sway damping and less sway added mass. Terms it has, other
/// values (parameters): thrust, deadband, surge and yaw damping, `N_v`, hard iron, the
/// imbalance, the noise levels.
pub const FORM: [Edit; 22] = [
    edit(File::Vehicle, "damping.sway_yaw[0]", Change::Set(-3.0)),
    edit(File::Vehicle, "damping.sway_yaw[1]", Change::Set(-6.0)),
    edit(File::Vehicle, "thrusters.exponent", Change::Set(1.3)),
    // The common dead band: the model file gives no motor a dead band of its own.
    edit(File::Vehicle, "thrusters.deadband", Change::Set(0.15)),
    edit(File::Vehicle, "thrusters.forward_max_n", Change::Scale(0.9)),
    edit(
        File::Vehicle,
        "thrusters.fluctuation_rel_std",
        Change::Set(0.05),
    ),
    edit(File::Vehicle, "thruster[1].gain", Change::Set(0.95)),
    edit(File::Vehicle, "damping.linear[0]", Change::Scale(0.7)),
    edit(File::Vehicle, "damping.quadratic[0]", Change::Scale(1.3)),
    edit(File::Vehicle, "damping.linear[1]", Change::Scale(1.2)),
    edit(File::Vehicle, "damping.linear[5]", Change::Scale(1.25)),
    edit(File::Vehicle, "added_mass.sway_kg", Change::Scale(0.85)),
    edit(File::Sensors, "compass.soft_iron[0][0]", Change::Set(1.04)),
    edit(File::Sensors, "compass.soft_iron[0][1]", Change::Set(0.02)),
    edit(File::Sensors, "compass.soft_iron[1][0]", Change::Set(0.02)),
    edit(File::Sensors, "compass.soft_iron[1][1]", Change::Set(0.97)),
    edit(File::Sensors, "compass.hard_iron_ut[0]", Change::Set(4.0)),
    edit(File::Sensors, "compass.field_noise_ut", Change::Set(0.45)),
    edit(File::Sensors, "depth.low_pass_cutoff_hz", Change::Set(4.0)),
    edit(File::Sensors, "depth.position_body_m[2]", Change::Set(0.18)),
    edit(File::Sensors, "adc.noise_v_rms", Change::Scale(1.5)),
    edit(File::Sensors, "velocity.pulse_fraction", Change::Set(0.4)),
];

/// The effects the bridge source hides, by their library names, in the library's order.
pub static HIDDEN: LazyLock<Vec<Hidden>> = LazyLock::new(|| {
    effects::LIBRARY
        .iter()
        .filter_map(|e| {
            let h = e.hidden?;
            Some(Hidden::of(e, e.name, h.factor))
        })
        .collect()
});

/// Default sizes of the hidden effects, in the library effect's parameters (a factor where
/// the size is one).
pub fn default_sizes() -> Vec<(String, Vec<f64>)> {
    effects::LIBRARY
        .iter()
        .filter_map(|e| Some((e.name.to_string(), e.hidden?.bridge_size.to_vec())))
        .collect()
}

/// The effect the bridge source calls `name`.
pub fn by_name(name: &str) -> Result<&'static Hidden, GapError> {
    HIDDEN.iter().find(|h| h.name == name).ok_or_else(|| {
        GapError::Data(format!(
            "--effects: `{name}` is not an effect the bridge source hides; known: {}",
            HIDDEN.iter().map(|h| h.name).collect::<Vec<_>>().join(", ")
        ))
    })
}

/// The edits that hide `name` with `size` (the library effect's parameters, as
/// [`crate::gap::effects::apply`] applies them to the model).
pub fn edits_for(name: &str, size: &[f64]) -> Vec<Edit> {
    effects::by_name(name)
        .and_then(|e| e.hidden)
        .map_or_else(Vec::new, |h| (h.bridge)(size))
}

/// One step of an edit's key.
enum Step<'a> {
    Key(&'a str),
    Index(usize),
}

/// Applies `e` to a parsed file; errors name the key.
pub fn apply_edit(doc: &mut toml::Table, e: &Edit) -> Result<(), GapError> {
    let bad = |why: &str| {
        GapError::Data(format!(
            "bridge set-up: `{}` in {}: {why}",
            e.key,
            e.file.embedded()
        ))
    };
    // `a.b[1][0]` is Key("a"), Key("b"), Index(1), Index(0).
    let mut steps = Vec::new();
    for part in e.key.split('.') {
        let (name, rest) = part.split_once('[').unwrap_or((part, ""));
        steps.push(Step::Key(name));
        for idx in rest.split('[') {
            let idx = idx.trim_end_matches(']');
            if !idx.is_empty() {
                steps.push(Step::Index(idx.parse().map_err(|_| bad("bad index"))?));
            }
        }
    }
    let Some((first, rest)) = steps.split_first() else {
        return Err(bad("empty key"));
    };
    let Step::Key(k) = first else {
        return Err(bad("starts with an index"));
    };
    let mut here = doc
        .entry((*k).to_string())
        .or_insert(placeholder(rest.first()));
    for (i, step) in rest.iter().enumerate() {
        let make = placeholder(rest.get(i + 1));
        here = match (step, here) {
            (Step::Key(k), toml::Value::Table(t)) => t.entry((*k).to_string()).or_insert(make),
            (Step::Index(n), toml::Value::Array(a)) => {
                while a.len() <= *n {
                    a.push(make.clone());
                }
                &mut a[*n]
            }
            _ => return Err(bad("the path does not match the file's structure")),
        };
    }
    let old = match here {
        toml::Value::Float(f) => *f,
        toml::Value::Integer(n) => *n as f64,
        _ => return Err(bad("not a number")),
    };
    *here = toml::Value::Float(match e.change {
        Change::Set(v) => v,
        Change::Scale(f) => old * f,
        Change::Add(d) => old + d,
    });
    Ok(())
}

/// What a missing step of a path is created as: a table before a key, an array before an
/// index, a number at the end.
fn placeholder(next: Option<&Step<'_>>) -> toml::Value {
    match next {
        None => toml::Value::Float(0.0),
        Some(Step::Index(_)) => toml::Value::Array(Vec::new()),
        Some(Step::Key(_)) => toml::Value::Table(toml::Table::new()),
    }
}

/// The course start of `program`: open water for its manoeuvres (`heading_hold` runs 40 s
/// north at full thrust, so it starts at the south end).
fn start_of(program: &str) -> &'static str {
    match program {
        "heading_hold" => "[3.0, 6.25, 0.0]",
        _ => "\"centre\"",
    }
}

/// The bridge as a truth source.
pub struct Bridge {
    exe: PathBuf,
    programs: PathBuf,
    /// Holds a scratch build of the examples for as long as the source lives.
    _built: Option<super::calibrated::Scratch>,
}

impl Bridge {
    /// Finds (or builds) the example programs; errors name what is missing.
    pub fn new(opts: &BridgeOptions) -> Result<Self, GapError> {
        let exe = match &opts.exe {
            Some(p) => p.clone(),
            None => std::env::current_exe().map_err(io(Path::new("eyebot-hil")))?,
        };
        let (programs, built) = match &opts.programs {
            Some(dir) => (dir.clone(), None),
            None => {
                let scratch = super::calibrated::Scratch::new("bridge-programs", 0)?;
                build_examples(&scratch.0)?;
                (scratch.0.clone(), Some(scratch))
            }
        };
        for p in BASELINE_PROGRAMS.iter().chain([&CASE_PROGRAM]) {
            if !programs.join(p).is_file() {
                return Err(GapError::Data(format!(
                    "--programs {}: no `{p}` there; build the examples with `make -C \
                     firmware-protocol/c OUT={}`",
                    programs.display(),
                    programs.display()
                )));
            }
        }
        Ok(Self {
            exe,
            programs,
            _built: built,
        })
    }

    /// Records `program` with the bridge set-up plus `edits` and writes the converted
    /// measurement to `out`.
    fn record(&self, program: &str, seed: u64, edits: &[Edit], out: &Path) -> Result<(), GapError> {
        let work = out.with_extension("bridge");
        if work.exists() {
            std::fs::remove_dir_all(&work).map_err(io(&work))?;
        }
        std::fs::create_dir_all(&work).map_err(io(&work))?;
        let write = |name: &str, text: &str| {
            let path = work.join(name);
            std::fs::write(&path, text).map_err(io(&path))
        };
        for file in [File::Vehicle, File::Sensors, File::World] {
            let text = Embedded.read(file.embedded())?;
            let mut doc: toml::Table = toml::from_str(&text).map_err(|e| {
                GapError::Data(format!("{}: {e}", Embedded.describe(file.embedded())))
            })?;
            for e in FORM.iter().chain(edits).filter(|e| e.file == file) {
                apply_edit(&mut doc, e)?;
            }
            let text = toml::to_string(&doc)
                .map_err(|e| GapError::Data(format!("bridge set-up {}: {e}", file.file_name())))?;
            write(file.file_name(), &text)?;
        }
        let name = crate::config::DEFAULT_CONFIG;
        let mut daemon: toml::Table = toml::from_str(&Embedded.read(name)?)
            .map_err(|e| GapError::Data(format!("{}: {e}", Embedded.describe(name))))?;
        for file in [File::Vehicle, File::Sensors, File::World] {
            let key = match file {
                File::Vehicle => "vehicle",
                File::Sensors => "sensors",
                File::World => "world",
            };
            daemon.insert(key.into(), toml::Value::String(file.file_name().into()));
        }
        let text = toml::to_string(&daemon)
            .map_err(|e| GapError::Data(format!("bridge set-up daemon.toml: {e}")))?;
        write("daemon.toml", &text)?;
        write(
            "scenario.toml",
            &format!(
                "name = \"{program}\"\nconfig = \"daemon.toml\"\nseed = {seed}\nstart = {}\n\
                 duration_s = {DURATION_S}\nwall_limit_s = 900\n",
                start_of(program)
            ),
        )?;
        let check = work.join("check");
        let run = Command::new(&self.exe)
            .arg("check")
            .arg(work.join("scenario.toml"))
            .arg("--out")
            .arg(&check)
            .arg("--")
            .arg(self.programs.join(program))
            .stdin(Stdio::null())
            .output()
            .map_err(io(&self.exe))?;
        if !run.status.success() {
            let log = std::fs::read_to_string(check.join("daemon.log")).unwrap_or_default();
            return Err(GapError::Data(format!(
                "{} check ... -- {program} (seed {seed}): {}: {} {}",
                self.exe.display(),
                run.status,
                String::from_utf8_lossy(&run.stdout).trim(),
                log.lines().last().unwrap_or("")
            )));
        }
        let conv = convert(
            &check.join("rec"),
            &ConvertOptions {
                vehicle: Some(File::Vehicle.embedded().into()),
                sensors: Some(File::Sensors.embedded().into()),
                world: Some(File::World.embedded().into()),
                camera_std_m: Some(CAMERA_STD_M),
                seed: seed ^ 0xca3e_a000,
            },
        )?;
        conv.measurement.write(out)?;
        std::fs::remove_dir_all(&work).map_err(io(&work))
    }
}

/// Builds the examples on the host with `make` (needs make and a C compiler).
fn build_examples(out: &Path) -> Result<(), GapError> {
    let src = concat!(env!("CARGO_MANIFEST_DIR"), "/firmware-protocol/c");
    let mut programs: Vec<&str> = BASELINE_PROGRAMS.to_vec();
    programs.sort_unstable();
    programs.dedup();
    let run = Command::new("make")
        .arg("-s")
        .arg("-C")
        .arg(src)
        .arg(format!("OUT={}", out.display()))
        .arg(format!("EXAMPLES={}", programs.join(" ")))
        .output()
        .map_err(|e| {
            GapError::Data(format!(
                "cannot run `make` (needed to build the C examples in {src}): {e}"
            ))
        })?;
    if !run.status.success() {
        return Err(GapError::Data(format!(
            "make -C {src}: {}: {}",
            run.status,
            String::from_utf8_lossy(&run.stderr).trim()
        )));
    }
    Ok(())
}

impl Truth for Bridge {
    fn default_sizes(&self) -> Result<Vec<(String, Vec<f64>)>, GapError> {
        Ok(default_sizes())
    }

    fn spread_runs(&self) -> usize {
        SPREAD_RUNS
    }

    fn baseline(&self, index: usize, seed: u64, out: &Path) -> Result<(), GapError> {
        let program = BASELINE_PROGRAMS[index.min(BASELINE_PROGRAMS.len() - 1)];
        self.record(program, seed, &[], out)
    }

    fn case(&self, seed: u64, hidden: &[(&Hidden, &[f64])], out: &Path) -> Result<(), GapError> {
        let edits: Vec<_> = hidden
            .iter()
            .flat_map(|(h, size)| edits_for(h.name, size))
            .collect();
        self.record(CASE_PROGRAM, seed, &edits, out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gap::effects;

    /// Every hidden effect has a default size and edits, and is the library effect of its
    /// name.
    #[test]
    fn every_hidden_effect_has_edits_and_a_size() {
        let sizes = default_sizes();
        for h in HIDDEN.iter() {
            assert_eq!(h.library, Some(h.name));
            assert!(effects::by_name(h.name).is_some(), "{}", h.name);
            let size = sizes
                .iter()
                .find(|(n, _)| n == h.name)
                .map(|(_, s)| s)
                .unwrap_or_else(|| panic!("{}: no default size", h.name));
            assert!(!edits_for(h.name, size).is_empty(), "{}", h.name);
        }
    }

    /// Every edit applies to the embedded file it names, and the edited files still load
    /// as configurations.
    #[test]
    fn the_bridge_set_up_and_every_hidden_effect_load() {
        use crate::physics::VehicleConfig;
        use crate::sensors::SensorsConfig;
        for h in HIDDEN.iter() {
            let size = &effects::by_name(h.name)
                .unwrap()
                .hidden
                .unwrap()
                .bridge_size;
            let edits = edits_for(h.name, size);
            for file in [File::Vehicle, File::Sensors, File::World] {
                let mut doc: toml::Table =
                    toml::from_str(&Embedded.read(file.embedded()).unwrap()).unwrap();
                for e in FORM.iter().chain(&edits).filter(|e| e.file == file) {
                    apply_edit(&mut doc, e).unwrap_or_else(|err| panic!("{}: {err}", h.name));
                }
                let text = toml::to_string(&doc).unwrap();
                match file {
                    File::Vehicle => {
                        let d = crate::config::Document::new("vehicle.toml", &text);
                        VehicleConfig::from_document(&d).unwrap();
                    }
                    File::Sensors => {
                        SensorsConfig::from_text("sensors.toml", &text).unwrap();
                    }
                    File::World => {
                        let d = crate::config::Document::new("world.toml", &text);
                        crate::physics::WorldConfig::from_document(&d).unwrap();
                    }
                }
            }
        }
    }

    /// Loads the bridge set-up's three files with `edits` on top.
    fn loaded(edits: &[Edit]) -> crate::gap::effects::Configs {
        let text = |file: File| {
            let mut doc: toml::Table =
                toml::from_str(&Embedded.read(file.embedded()).unwrap()).unwrap();
            for e in FORM.iter().chain(edits).filter(|e| e.file == file) {
                apply_edit(&mut doc, e).unwrap();
            }
            toml::to_string(&doc).unwrap()
        };
        let v = text(File::Vehicle);
        let w = text(File::World);
        crate::gap::effects::Configs::new(
            crate::physics::VehicleConfig::from_document(&crate::config::Document::new("v", &v))
                .unwrap(),
            crate::physics::WorldConfig::from_document(&crate::config::Document::new("w", &w))
                .unwrap(),
            crate::sensors::SensorsConfig::from_text("s", &text(File::Sensors)).unwrap(),
        )
    }

    /// A hidden effect's edits make exactly the configuration the library effect makes of
    /// the bridge set-up, so the library's parameters are the right answer. The paddle
    /// wheel is the exception by design: the bridge changes the wheel (pulses per metre),
    /// the library the program's factor; the program's speed changes by the same factor.
    #[test]
    fn hidden_edits_are_the_library_effect() {
        for h in HIDDEN.iter() {
            let size = &effects::by_name(h.name)
                .unwrap()
                .hidden
                .unwrap()
                .bridge_size;
            let hidden = loaded(&edits_for(h.name, size));
            let mut applied = loaded(&[]);
            let truth = crate::gap::bench::calibrated::library_truth(h, size);
            effects::apply(effects::by_name(h.name).unwrap(), &truth, &mut applied);
            if h.name == "velocity_sensor_scale" {
                let (a, b) = (&hidden.sensors.velocity, &applied.sensors.velocity);
                assert!(
                    (a.pulses_per_metre / b.pulses_per_metre - 1.0).abs() > 0.2,
                    "the wheel changed"
                );
                // Pulses per metre of water times the program's factor: the speed it reads.
                assert!(
                    (a.pulses_per_metre * a.firmware_scale - b.pulses_per_metre * b.firmware_scale)
                        .abs()
                        < 1e-9,
                    "the same speed factor"
                );
                continue;
            }
            assert!(
                hidden == applied,
                "{}: the edits differ from the library's",
                h.name
            );
        }
    }

    /// A programs directory without the examples is an error that names the missing
    /// program and the command that builds it.
    #[test]
    fn missing_programs_are_named_with_the_build_command() {
        let empty = crate::scratch::dir("bridge-programs");
        let err = Bridge::new(&BridgeOptions {
            exe: Some("eyebot-hil".into()),
            programs: Some(empty.path().to_path_buf()),
        })
        .err()
        .expect("an empty directory has no programs")
        .to_string();
        assert!(err.contains("no `timer_square`"), "{err}");
        assert!(err.contains("make -C firmware-protocol/c"), "{err}");
    }

    /// An edit scales, adds to, sets and creates numbers along dotted and indexed paths, and
    /// names the key when the path does not fit the file.
    #[test]
    fn edits_follow_their_paths() {
        let mut doc: toml::Table =
            toml::from_str("[damping]\nlinear = [1.0, 2.0]\n[[thruster]]\ngain = 2\n").unwrap();
        let v = File::Vehicle;
        apply_edit(&mut doc, &edit(v, "damping.linear[1]", Change::Scale(1.5))).unwrap();
        apply_edit(&mut doc, &edit(v, "thruster[0].gain", Change::Add(0.5))).unwrap();
        apply_edit(&mut doc, &edit(v, "damping.sway_yaw[1]", Change::Set(-6.0))).unwrap();
        apply_edit(&mut doc, &edit(v, "compass.errors.bias", Change::Add(3.0))).unwrap();
        let back: toml::Table = toml::from_str(&toml::to_string(&doc).unwrap()).unwrap();
        assert_eq!(back["damping"]["linear"][1].as_float(), Some(3.0));
        assert_eq!(back["thruster"][0]["gain"].as_float(), Some(2.5));
        assert_eq!(back["damping"]["sway_yaw"][0].as_float(), Some(0.0));
        assert_eq!(back["damping"]["sway_yaw"][1].as_float(), Some(-6.0));
        assert_eq!(back["compass"]["errors"]["bias"].as_float(), Some(3.0));
        let err = apply_edit(&mut doc, &edit(v, "damping.linear.x", Change::Set(1.0)))
            .unwrap_err()
            .to_string();
        assert!(err.contains("damping.linear.x"), "{err}");
    }
}

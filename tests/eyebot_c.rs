//! The example control programs of `firmware-protocol/c/examples`, built from `cargo test`,
//! run against the bridge in lockstep and judged from the recorded ground truth.

use std::time::Duration;

use eyebot_test_support::Recording;
use eyebot_test_support::eyebot_c::{self, Target, assert_same_run, run_to_end, start_daemon};
use eyebot_test_support::recording::StateRow;

const BIN: &str = env!("CARGO_BIN_EXE_eyebot-hil");
const TMP: &str = env!("CARGO_TARGET_TMPDIR");
const TIMEOUT: Duration = Duration::from_secs(300);

/// Depth of a body-frame point (m, forward-starboard-down from the centre of mass).
fn point_depth_m(s: &StateRow, body_m: [f64; 3]) -> f64 {
    let (sr, cr) = s.roll_rad.sin_cos();
    let (sp, cp) = s.pitch_rad.sin_cos();
    s.z_m - sp * body_m[0] + cp * sr * body_m[1] + cp * cr * body_m[2]
}

/// North/east position of a body-frame point (yaw only; roll and pitch stay small).
fn point_north_east_m(s: &StateRow, body_m: [f64; 2]) -> (f64, f64) {
    let (sy, cy) = s.yaw_rad.sin_cos();
    (
        s.x_m + cy * body_m[0] - sy * body_m[1],
        s.y_m + sy * body_m[0] + cy * body_m[1],
    )
}

fn run(name: &str, program: &str, start: Option<([f64; 3], f64)>) -> (Recording, String) {
    run_seed(name, program, start, 1)
}

fn run_seed(
    name: &str,
    program: &str,
    start: Option<([f64; 3], f64)>,
    seed: u64,
) -> (Recording, String) {
    let out = eyebot_c::build(TMP, "examples", Target::Host, &[], &[]);
    let daemon = start_daemon(BIN, name, start, seed);
    run_to_end(daemon, Target::Host, &out.join(program), &[], TIMEOUT)
}

/// Thesis 4.5: the compass heading hold drives straight: lateral deviation under 0.3 m over
/// the first 10 m (default start: 2.5 m off the west wall facing north, 20 m of water ahead).
#[test]
fn heading_hold_drives_straight() {
    let (rec, _) = run("heading_hold", "heading_hold", None);
    let s0 = &rec.states[0];
    let mut deviation_m: f64 = 0.0;
    let mut reached = false;
    for s in &rec.states {
        let along = s.x_m - s0.x_m;
        if along > 10.0 {
            reached = true;
            break;
        }
        deviation_m = deviation_m.max((s.y_m - s0.y_m).abs());
    }
    eprintln!("heading hold: max lateral deviation {deviation_m:.3} m over 10 m");
    assert!(reached, "did not travel 10 m");
    assert!(deviation_m < 0.3, "lateral deviation {deviation_m:.3} m");
    assert!(rec.states.iter().all(|s| !s.contact), "touched the pool");
}

/// Depth sensor position in the body frame (configs/sensors/mako-2008.toml, [depth]).
const DEPTH_SENSOR_BODY_M: [f64; 3] = [-0.45, 0.0, 0.15];
/// dive_hold.c's target and run time.
const DIVE_TARGET_M: f64 = 1.0;
/// Settling: judged from here to the end of the 90 s run.
const DIVE_SETTLED_S: f64 = 40.0;

/// The PID dive reaches the target depth (at the sensor) and holds it within 5 cm after
/// settling.
#[test]
fn dive_reaches_and_holds_depth() {
    let (rec, _) = run("dive_hold", "dive_hold", None);
    let settled: Vec<f64> = rec
        .states
        .iter()
        .filter(|s| s.t_s >= DIVE_SETTLED_S && s.t_s <= 89.0)
        .map(|s| point_depth_m(s, DEPTH_SENSOR_BODY_M))
        .collect();
    assert!(settled.len() > 100, "run too short: {} rows", settled.len());
    let worst = settled
        .iter()
        .map(|d| (d - DIVE_TARGET_M).abs())
        .fold(0.0, f64::max);
    let peak = rec
        .states
        .iter()
        .map(|s| point_depth_m(s, DEPTH_SENSOR_BODY_M))
        .fold(0.0, f64::max);
    eprintln!("dive: worst error after {DIVE_SETTLED_S} s {worst:.3} m, deepest {peak:.3} m");
    assert!(worst < 0.05, "depth error {worst:.3} m after settling");
}

/// Thesis 4.7: the spot turn turns (at least one full clockwise turn, heading unwrapped).
#[test]
fn spot_turn_turns_clockwise() {
    let (rec, stdout) = run("spot_turn", "spot_turn", None);
    let mut turned = 0.0;
    for w in rec.states.windows(2) {
        let mut d = w[1].yaw_rad - w[0].yaw_rad;
        d = (d + std::f64::consts::PI).rem_euclid(2.0 * std::f64::consts::PI)
            - std::f64::consts::PI;
        turned += d;
    }
    eprintln!("spot turn: {:.0} deg\n{stdout}", turned.to_degrees());
    assert!(
        turned.to_degrees() > 360.0,
        "turned {:.0} deg",
        turned.to_degrees()
    );
    assert!(
        stdout.contains("second calibration reading: ok"),
        "{stdout}"
    );
}

/// Where the wall-following course starts (configs/worlds/pool.toml [wall_following]).
const WALL_START: ([f64; 3], f64) = ([2.0, 1.5, 0.5], 0.0);
/// Pool length (configs/worlds/pool.toml): the north wall is at x = 25 m, the west at y = 0.
const POOL_LENGTH_M: f64 = 25.0;
/// Port transducers in the body frame (configs/sensors/mako-2008.toml).
const PORT_TRANSDUCERS_M: [[f64; 2]; 2] = [[0.25, -0.32], [-0.25, -0.32]];

/// The sonar three-reading pattern reads the port wall (1.2 m off at the course start).
#[test]
fn sonar_three_readings_see_the_port_wall() {
    let (rec, stdout) = run("sonar_three", "sonar_three", Some(WALL_START));
    let s = &rec.states[0];
    let truth_m = PORT_TRANSDUCERS_M
        .iter()
        .map(|p| point_north_east_m(s, *p).1)
        .fold(f64::MAX, f64::min);
    let first: f64 = stdout
        .lines()
        .next()
        .and_then(|l| l.split_whitespace().nth(1))
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no reading in {stdout:?}"));
    eprintln!("sonar: port {first} m, true perpendicular distance {truth_m:.2} m\n{stdout}");
    // slant range along a beam 15 deg off the normal, 0.1 m resolution
    assert!(
        (first - truth_m / 15f64.to_radians().cos()).abs() <= 0.15,
        "port reading {first} m, truth {truth_m:.2} m"
    );
}

/// How a wall-following run went, judged from the ground truth.
struct WallRun {
    /// Shortest and longest distance (m) and when (s).
    lo: (f64, f64),
    hi: (f64, f64),
    contact: bool,
    /// Past the first corner: heading east along the north wall, more than 4 m from the
    /// west wall.
    passed: bool,
    end: (f64, f64, f64),
}

impl WallRun {
    fn judge(rec: &Recording) -> Self {
        let mut lo = (f64::MAX, 0.0);
        let mut hi = (0.0, 0.0);
        for s in &rec.states {
            let d = PORT_TRANSDUCERS_M
                .iter()
                .map(|p| {
                    let (n, e) = point_north_east_m(s, *p);
                    e.min(POOL_LENGTH_M - n)
                })
                .fold(f64::MAX, f64::min);
            if d < lo.0 {
                lo = (d, s.t_s);
            }
            if d > hi.0 {
                hi = (d, s.t_s);
            }
        }
        let last = rec.states.last().expect("states");
        let heading_deg = last.yaw_rad.to_degrees();
        Self {
            lo,
            hi,
            contact: rec.states.iter().any(|s| s.contact),
            passed: (45.0..135.0).contains(&heading_deg) && last.y_m > 4.0,
            end: (last.x_m, last.y_m, heading_deg),
        }
    }

    fn ok(&self) -> bool {
        !self.contact && self.passed && self.lo.0 >= 0.6 && self.hi.0 <= 1.4
    }

    fn describe(&self) -> String {
        format!(
            "distance {:.2} m (t {:.0} s) .. {:.2} m (t {:.0} s); contact {}; end at x {:.2} y \
             {:.2} heading {:.0} deg",
            self.lo.0,
            self.lo.1,
            self.hi.0,
            self.hi.1,
            self.contact,
            self.end.0,
            self.end.1,
            self.end.2
        )
    }
}

/// Thesis 4.8: the fuzzy wall follower (10 % thrust, 1 m off the port wall) passes the first
/// corner without contact and stays 1 m +- 0.4 m from the wall. The distance is the shorter
/// of the two port transducers' perpendicular distances to the west or north wall (the wall
/// on the port side before and after the corner).
#[test]
fn wall_follower_passes_the_first_corner() {
    let (rec, stdout) = run("wall_follower", "wall_follower", Some(WALL_START));
    let w = WallRun::judge(&rec);
    eprintln!("wall follower: {}\n{stdout}", w.describe());
    assert!(!w.contact, "touched the pool");
    assert!(w.passed, "did not pass the first corner");
    assert!(
        w.lo.0 >= 0.6 && w.hi.0 <= 1.4,
        "distance {:.2}..{:.2} m, outside 1 m +- 0.4 m",
        w.lo.0,
        w.hi.0
    );
}

/// Opt-in robustness sweep: the wall follower on seeds `EYEBOT_C_SEEDS` (`FIRST-LAST`,
/// default 1-20), judged like the test above; prints one line per seed and fails naming the
/// seeds that missed. Figures in docs/eyebot.md.
#[test]
#[ignore = "a sweep of many runs: EYEBOT_C_SEEDS=1-100 cargo test --test eyebot_c \
            wall_follower_seed_sweep -- --ignored --nocapture"]
fn wall_follower_seed_sweep() {
    let range = std::env::var("EYEBOT_C_SEEDS").unwrap_or_else(|_| "1-20".into());
    let (first, last) = range
        .split_once('-')
        .and_then(|(a, b)| Some((a.parse::<u64>().ok()?, b.parse::<u64>().ok()?)))
        .expect("EYEBOT_C_SEEDS=FIRST-LAST");
    let mut missed = Vec::new();
    let (mut lo, mut hi) = (f64::MAX, 0.0f64);
    for seed in first..=last {
        let (rec, _) = run_seed("wall_sweep", "wall_follower", Some(WALL_START), seed);
        let w = WallRun::judge(&rec);
        eprintln!("seed {seed}: {}", w.describe());
        lo = lo.min(w.lo.0);
        hi = hi.max(w.hi.0);
        if !w.ok() {
            missed.push(seed);
        }
    }
    let n = last - first + 1;
    eprintln!(
        "wall follower sweep: {} of {n} seeds within 1 m +- 0.4 m past the corner without \
         contact; distance over all runs {lo:.2} .. {hi:.2} m; missed {missed:?}",
        n - missed.len() as u64
    );
    assert!(missed.is_empty(), "seeds that missed: {missed:?}");
}

/// The same program, the same seed, in lockstep: the 68k build under qemu-m68k sends and
/// receives exactly the bytes the host build does, at the same simulated times.
#[test]
fn m68k_build_under_qemu_gives_the_host_transcript() {
    let host = eyebot_c::build(TMP, "transcript", Target::Host, &[], &[]);
    let m68k = eyebot_c::build(TMP, "transcript", Target::M68k, &[], &[]);
    for (program, start) in [
        ("sonar_three", Some(WALL_START)),
        ("heading_hold", None),
        ("wall_follower", Some(WALL_START)),
    ] {
        let mut transcripts = Vec::new();
        for (target, dir) in [(Target::Host, &host), (Target::M68k, &m68k)] {
            let daemon = start_daemon(BIN, &format!("transcript-{program}"), start, 7);
            let (rec, stdout) = run_to_end(daemon, target, &dir.join(program), &[], TIMEOUT);
            transcripts.push((rec.transcript(), stdout));
        }
        assert_same_run(
            &format!("{program}, host and m68k"),
            &transcripts[0],
            &transcripts[1],
        );
        eprintln!(
            "{program}: host and m68k transcripts equal ({} chunks)",
            transcripts[0].0.len()
        );
    }
}

/// The C99 standard headers (ISO/IEC 9899:1999, 7.1.2).
const C99_HEADERS: [&str; 24] = [
    "assert.h",
    "complex.h",
    "ctype.h",
    "errno.h",
    "fenv.h",
    "float.h",
    "inttypes.h",
    "iso646.h",
    "limits.h",
    "locale.h",
    "math.h",
    "setjmp.h",
    "signal.h",
    "stdarg.h",
    "stdbool.h",
    "stddef.h",
    "stdint.h",
    "stdio.h",
    "stdlib.h",
    "string.h",
    "tgmath.h",
    "time.h",
    "wchar.h",
    "wctype.h",
];

/// The examples contain no simulation-specific code: they include only `eyebot.h`
/// and standard C headers (and no other file of this project).
#[test]
fn examples_include_only_eyebot_h_and_standard_headers() {
    let dir = eyebot_c::c_source_dir().join("examples");
    let mut checked = 0;
    for entry in std::fs::read_dir(&dir).expect("examples directory") {
        let path = entry.expect("dir entry").path();
        if path.extension().and_then(|e| e.to_str()) != Some("c") {
            continue;
        }
        let text = std::fs::read_to_string(&path).expect("read example");
        for line in text.lines() {
            let Some(rest) = line.trim_start().strip_prefix('#') else {
                continue;
            };
            let Some(name) = rest.trim_start().strip_prefix("include") else {
                continue;
            };
            let name = name.trim();
            let ok = name == "\"eyebot.h\""
                || name
                    .strip_prefix('<')
                    .and_then(|n| n.strip_suffix('>'))
                    .is_some_and(|n| C99_HEADERS.contains(&n));
            assert!(ok, "{}: #include {name}", path.display());
        }
        checked += 1;
    }
    assert_eq!(checked, 6, "examples found in {}", dir.display());
}

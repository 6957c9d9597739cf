//! RoBIOS 6 programs written for other robots (`tests/robios6/`: a SubSim-style PSD wall
//! follower, a servo/encoder driver with line sensors on input latch 0, a camera and radio
//! demo, RoBIOS 6.3 demo calls in the style of the EyeBot M5's standard demos, a program of
//! two files that includes `"include/eyebot.h"`) build unchanged with the documented make
//! line for the host and the 68k; the devices Mako has not got fail as RoBIOS does; the
//! wall follower follows the pool wall in `check` on the sonar, host and qemu-m68k byte for
//! byte; the latch script reaches `OSReadInLatch`; the M5-style demo runs in `check`.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use eyebot_test_support::eyebot_c::{self, Target};
use eyebot_test_support::recording::first_difference;
use eyebot_test_support::{Recording, TempDir, require_tool, workspace_root};

const BIN: &str = env!("CARGO_BIN_EXE_eyebot-hil");
const TMP: &str = env!("CARGO_TARGET_TMPDIR");

fn program(name: &str) -> PathBuf {
    workspace_root().join("tests/robios6").join(name)
}

fn scenario(name: &str) -> PathBuf {
    workspace_root()
        .join("configs/checks")
        .join(format!("{name}.toml"))
}

/// Builds libeyebot, the single-file programs (`PROG`) and the two-file one (`NAME`,
/// `SOURCES`) for `target`, as docs/eyebot.md tells a user to.
fn build(target: Target) -> PathBuf {
    let singles = [
        program("subsim_wall.c"),
        program("quad_servo.c"),
        program("cam_radio.c"),
        program("missing_devices.c"),
        program("image_ops.c"),
        program("m5_demos.c"),
        program("threads_int.c"),
    ];
    let refs: Vec<&Path> = singles.iter().map(PathBuf::as_path).collect();
    let sources = format!(
        "SOURCES={} {}",
        program("multi_main.c").display(),
        program("multi_drive.c").display()
    );
    eyebot_c::build(
        TMP,
        "robios6",
        target,
        &refs,
        &["NAME=multi".into(), sources],
    )
}

fn run(target: Target, exe: &Path, env: &[(&str, &str)]) -> Output {
    let mut cmd = match target {
        Target::Host => Command::new(exe),
        Target::M68k => {
            let mut c = Command::new(require_tool("qemu-m68k", "qemu-user"));
            c.arg(exe);
            c
        }
    };
    for (k, v) in env {
        cmd.env(k, v);
    }
    cmd.env_remove("EYEBOT_LATCH").env_remove("EYEBOT_KEYS");
    cmd.output().expect("run the program")
}

fn check(scenario: &Path, out: &Path, program: &[&str]) -> Output {
    Command::new(BIN)
        .arg("check")
        .arg(scenario)
        .arg("--out")
        .arg(out)
        .arg("--")
        .args(program)
        .output()
        .expect("run eyebot-hil check")
}

fn text(o: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&o.stdout),
        String::from_utf8_lossy(&o.stderr)
    )
}

#[test]
fn robios6_programs_build_unchanged_for_the_host_and_the_68k() {
    for target in [Target::Host, Target::M68k] {
        let out = build(target);
        for name in [
            "subsim_wall",
            "quad_servo",
            "cam_radio",
            "missing_devices",
            "image_ops",
            "m5_demos",
            "threads_int",
            "multi",
        ] {
            assert!(
                out.join(name).is_file(),
                "{target:?}: {name} was not built in {}",
                out.display()
            );
        }
    }
}

/// What `missing_devices.c` prints in each of its two rounds: RoBIOS's failure values
/// (`SERVORelease`'s is RoBIOS's "totally wrong handle", 0x11110000), the
/// caller's buffers (stamp 42, pixels 9, parameters 1 2 3, v 1.5, x 2.5) untouched, and the
/// radio's received size (was 9) and status list count (was 7) set to 0.
const EXPECTED_ROUND: &str = "\
servo 0 -1 -1 0x11110000
quad 0 0 -1 -1 0 0.0 -1
vw 0 -1 -1 -1 -1 -1 -1 -1 -1 -1 0.0 -1 -1 -1 -1 v 1.5 x 2.5
bump 0 -1 stamp 42 -1
ir 0 -1 -1
cam 1 -1 -1 -1 -1 -1 pixel 9 9 -1 -1 -1 params 1 2 3
radio -1 -1 0 -1 size 0 -1 count 0 -1 -1 -1
irtv -1 0 0 0 -1 -1 -1 -1 -1
mic -1 -1 -1 buf 9
psd 0 start -1 get 9999
";

/// Each device family Mako has not got: the init call returns RoBIOS's failure value, every
/// call returns its error value without touching what it was given, the program goes on,
/// and the first call of each name says once on stderr which call and why.
#[test]
fn devices_mako_has_not_got_fail_as_robios_does_and_say_so_once() {
    let families: [(&str, &[&str]); 9] = [
        (
            "Mako has no servos",
            &["SERVOInit", "SERVOSet", "SERVOSetRaw", "SERVORelease"],
        ),
        (
            "Mako has no shaft encoders",
            &[
                "QUADInit",
                "QUADRead",
                "QUADReset",
                "QUADRelease",
                "QUADGetMotor",
                "QUADODORead",
                "QUADODOReset",
            ],
        ),
        (
            "Mako has no differential drive",
            &[
                "VWInit",
                "VWSetSpeed",
                "VWGetSpeed",
                "VWSetPosition",
                "VWGetPosition",
                "VWStartControl",
                "VWStopControl",
                "VWDriveStraight",
                "VWDriveTurn",
                "VWDriveCurve",
                "VWDriveRemain",
                "VWDriveDone",
                "VWDriveWait",
                "VWStalled",
                "VWRelease",
            ],
        ),
        (
            "Mako has no bumpers",
            &["BUMPInit", "BUMPCheck", "BUMPRelease"],
        ),
        (
            "Mako has no infrared sensors",
            &["IRInit", "IRRead", "IRRelease"],
        ),
        (
            "Mako's EyeBot has no camera",
            &[
                "CAMInit",
                "CAMGetFrame",
                "CAMGetColFrame",
                "CAMGetFrameMono",
                "CAMGetFrameRGB",
                "CAMGetFrameBayer",
                "CAMSet",
                "CAMGet",
                "CAMMode",
            ],
        ),
        (
            "Mako has no radio module",
            &[
                "RADIOInit",
                "RADIOSend",
                "RADIOCheck",
                "RADIORecv",
                "RADIOStatus",
                "RADIOSetIoctl",
                "RADIOGetIoctl",
                "RADIOTerm",
            ],
        ),
        (
            "Mako has no infrared remote-control receiver",
            &[
                "IRTVInit",
                "IRTVPressed",
                "IRTVRead",
                "IRTVGet",
                "IRTVFlushBuffer",
                "IRTVSetHoldDelay",
                "IRTVGetControlBit",
                "IRTVSetControlBit",
                "IRTVTerm",
            ],
        ),
        (
            "no microphone input",
            &["AURecordSample", "AUCheckRecord", "AUCaptureMic"],
        ),
    ];
    for target in [Target::Host, Target::M68k] {
        let out = build(target);
        let o = run(target, &out.join("missing_devices"), &[]);
        let said = text(&o);
        assert!(o.status.success(), "{target:?}: {:?}\n{said}", o.status);
        let stdout = String::from_utf8_lossy(&o.stdout);
        let expected = format!("{EXPECTED_ROUND}{EXPECTED_ROUND}done\n");
        assert_eq!(stdout, expected, "{target:?}");
        let stderr = String::from_utf8_lossy(&o.stderr);
        for (why, calls) in families {
            for call in calls {
                let lines: Vec<&str> = stderr
                    .lines()
                    .filter(|l| l.starts_with(&format!("eyebot: {call}: ")))
                    .collect();
                assert_eq!(
                    lines.len(),
                    1,
                    "{target:?} {call}: said {lines:?}\n{stderr}"
                );
                assert!(
                    lines[0].contains(why) && lines[0].contains("; returns "),
                    "{target:?} {call}: {}",
                    lines[0]
                );
            }
        }
        for said in [
            "eyebot: PSDInit(0x608): the HDT names no PSD so (it has PSD_LEFT,",
            "eyebot: PSDStart(0x40): not PSD handles from PSDInit",
            "eyebot: PSDGet(0x40): not one PSD handle from PSDInit; returns PSD_OUT_OF_RANGE",
        ] {
            assert!(stderr.contains(said), "{target:?}: {stderr}");
        }
    }
}

/// The (time s, distance mm) pairs of PSD_LEFT the wall follower printed ("t 12.3 s left
/// 1100 mm front 9999 mm").
fn left_readings(out: &str) -> Vec<(f64, i64)> {
    out.lines()
        .filter_map(|l| {
            let rest = l.strip_prefix("t ")?;
            let (t, rest) = rest.split_once(" s left ")?;
            let (mm, _front) = rest.split_once(" mm front ")?;
            Some((t.parse().ok()?, mm.parse().ok()?))
        })
        .collect()
}

/// The SubSim-style wall follower, knowing nothing of the multiplexer, follows the west wall
/// 1.5 m off on PSD_LEFT (transducer 1 over the sonar line) and passes its scenario; the
/// host and qemu-m68k runs send and receive the same bytes at the same times.
#[test]
fn subsim_wall_follower_follows_the_wall_on_the_sonar_host_and_m68k_alike() {
    let host = build(Target::Host);
    let m68k = build(Target::M68k);
    let qemu = require_tool("qemu-m68k", "qemu-user");
    let dir = TempDir::new("robios6-subsim");
    let host_out = dir.join("host");
    let o = check(
        &scenario("subsim_wall"),
        &host_out,
        &[host.join("subsim_wall").to_str().expect("utf-8 path")],
    );
    eprintln!("{}", text(&o));
    assert!(o.status.success(), "host:\n{}", text(&o));
    let m68k_out = dir.join("m68k");
    let o68 = check(
        &scenario("subsim_wall"),
        &m68k_out,
        &[
            qemu.to_str().expect("utf-8 path"),
            m68k.join("subsim_wall").to_str().expect("utf-8 path"),
        ],
    );
    assert!(o68.status.success(), "m68k:\n{}", text(&o68));
    let a = Recording::read(&host_out.join("rec")).transcript();
    let b = Recording::read(&m68k_out.join("rec")).transcript();
    assert!(a.len() > 100, "short transcript: {} chunks", a.len());
    assert!(
        a == b,
        "host and m68k recordings differ at {}",
        first_difference(&a, &b)
    );
    let printed = std::fs::read_to_string(host_out.join("program.out")).expect("program.out");
    let printed68 = std::fs::read_to_string(m68k_out.join("program.out")).expect("program.out");
    assert_eq!(printed, printed68, "the programs printed different text");
    // plausible sonar distances: each reading in range is the slant range from transducer 1
    // (0.32 m to port of the centre line, 75 deg to port of the bow) to the west wall at the
    // recorded pose, (east - 0.32 m) / cos(15 deg + yaw), within 0.25 m (readings come in
    // 0.1 m steps and are up to 2.5 s old); "nothing in range" is 9999
    let states = Recording::read(&host_out.join("rec")).states;
    let readings = left_readings(&printed);
    assert!(readings.len() >= 80, "{printed}");
    let mut in_range = 0;
    for &(t_s, mm) in &readings {
        if mm == 9999 {
            continue;
        }
        in_range += 1;
        let row = states
            .iter()
            .find(|r| r.t_s >= t_s)
            .expect("a state at the reading's time");
        let slant_m = (row.y_m - 0.32) / (row.yaw_rad + 15f64.to_radians()).cos();
        let error_m = mm as f64 / 1000.0 - slant_m;
        assert!(
            error_m.abs() <= 0.25,
            "at {t_s} s PSD_LEFT read {mm} mm, the wall is {slant_m:.3} m along the beam"
        );
    }
    assert!(
        in_range >= 20,
        "only {in_range} of {} readings in range: {readings:?}",
        readings.len()
    );
    eprintln!(
        "{in_range} of {} readings in range, each within 0.25 m of the slant range",
        readings.len()
    );
}

/// The latch script of a `check` scenario reaches OSReadInLatch: line sensors polled until
/// they leave 255 see the scripted line at 2.5 s and its end at 4 s.
#[test]
fn the_latch_script_drives_osreadinlatch_in_check() {
    let host = build(Target::Host);
    let dir = TempDir::new("robios6-latch");
    let o = check(
        &scenario("latch_line"),
        &dir.join("out"),
        &[host.join("quad_servo").to_str().expect("utf-8 path")],
    );
    eprintln!("{}", text(&o));
    assert!(o.status.success(), "{}", text(&o));
    let printed = std::fs::read_to_string(dir.join("out/program.out")).expect("program.out");
    assert!(
        printed.contains("latch 1 0xFF"),
        "latch 1 keeps its idle level: {printed}"
    );
}

/// A thread function handed to `OSSpawn` cast to `int`, as RoBIOS programs written for the
/// 68332 do, runs on the 64-bit host as on the 68k: the make line links programs at a fixed
/// address, where the cut pointer still names the function.
#[test]
fn a_thread_handed_to_osspawn_as_an_int_runs_on_the_host_and_the_68k() {
    let fixture = workspace_root().join("pty-tests/fixtures/robios6_threads_int.toml");
    for target in [Target::Host, Target::M68k] {
        let exe = build(target).join("threads_int");
        let mut program = vec![exe.to_str().expect("utf-8 path").to_string()];
        if target == Target::M68k {
            let qemu = require_tool("qemu-m68k", "qemu-user");
            program.insert(0, qemu.to_str().expect("utf-8 path").to_string());
        }
        let program: Vec<&str> = program.iter().map(String::as_str).collect();
        let dir = TempDir::new("robios6-threads-int");
        let o = check(&fixture, &dir.join("out"), &program);
        assert!(o.status.success(), "{target:?}: {}", text(&o));
        let printed = std::fs::read_to_string(dir.join("out/program.out")).expect("program.out");
        assert_eq!(printed, "worker ran 3 times\n", "{target:?}");
    }
}

/// A latch script the library cannot read ends the program with status 2, naming the
/// variable, the text and what was expected.
#[test]
fn a_bad_latch_script_is_refused_naming_it() {
    let host = build(Target::Host);
    for (script, said) in [
        ("0x1FF", "value not 0..255"),
        ("7:1", "latch not 0..3"),
        ("12@", "expected seconds >= 0 after '@'"),
        ("12;", "unexpected text"),
    ] {
        let mut cmd = Command::new(host.join("quad_servo"));
        let o = cmd
            .env("EYEBOT_LATCH", script)
            .env("EYEBOT_RUN_DIR", "/nonexistent-run-dir")
            .output()
            .expect("run quad_servo");
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(2), "{script}: {err}");
        assert!(
            err.contains("eyebot: EYEBOT_LATCH: ") && err.contains(said),
            "{script}: {err}"
        );
    }
}

/// RoBIOS's image processing calls on a picture with a vertical edge from 20 to 220 between
/// columns 40 and 41: Laplace 200 on both sides of the edge and 0 elsewhere (60 rows x 2
/// columns, 4680 flat pixels), Sobel (|Gx| + |Gy|) / 4 = 200, the 2 x 2 dither pattern, the
/// difference, the grey of (30, 60, 90); host and qemu-m68k alike.
#[test]
fn image_processing_calls_compute_their_operators() {
    let expected = "\
laplace 200 200 at edge 120 4680 border 0
sobel 0 200 200 0
dither 255 0 255 255
differ 0 200
grey 60
null -1
";
    for target in [Target::Host, Target::M68k] {
        let out = build(target);
        let o = run(target, &out.join("image_ops"), &[]);
        assert!(o.status.success(), "{target:?}: {}", text(&o));
        assert_eq!(String::from_utf8_lossy(&o.stdout), expected, "{target:?}");
    }
}

/// RoBIOS 6.3's demo calls (`m5_demos.c`: `AUCaptureMic()`, a `tone` array played note by
/// note with `AUTone`, `CAMInit(WIDE)` and `CAMInit(NORMAL)` checked against `NOCAM`,
/// `INITERROR` and `COLCAM`, `CAMSet(FPS0_9375, 0, 0)` and the rates down to `FPS0_46875`,
/// `VWInit(VW, 1)`) run on the host in `check`: each note starts when the last has sounded
/// out (120 ms = 12 ticks), and every device Mako has not got answers its failure value.
#[test]
fn robios63_demo_calls_run_on_mako_without_its_devices() {
    let host = build(Target::Host);
    let dir = TempDir::new("robios6-m5-demos");
    let out = dir.join("out");
    let o = check(
        &workspace_root().join("pty-tests/fixtures/robios6_m5_demos.toml"),
        &out,
        &[host.join("m5_demos").to_str().expect("utf-8 path")],
    );
    eprintln!("{}", text(&o));
    assert!(o.status.success(), "{}", text(&o));
    let printed = std::fs::read_to_string(out.join("program.out")).expect("program.out");
    assert_eq!(
        printed,
        "\
Demos 6.3
fanfare: 4 notes
Micro: -1
wide: No Camera
CAMSet slow -1
normal: No Camera
rates refused 3
no VW driver
done
"
    );
    let log = std::fs::read_to_string(out.join("program.err")).expect("program.err");
    let tones: Vec<&str> = log
        .lines()
        .filter(|l| l.starts_with("eyebot: sound: tone "))
        .collect();
    assert_eq!(
        tones,
        [
            "eyebot: sound: tone 523 Hz for 120 ms at t 0.00 s",
            "eyebot: sound: tone 659 Hz for 120 ms at t 0.12 s",
            "eyebot: sound: tone 784 Hz for 120 ms at t 0.24 s",
            "eyebot: sound: tone 1047 Hz for 240 ms at t 0.36 s",
        ],
        "{log}"
    );
    for said in [
        "eyebot: AUCaptureMic: the bridge has no microphone input; returns -1",
        "eyebot: CAMInit: Mako's EyeBot has no camera",
        "eyebot: CAMSet: Mako's EyeBot has no camera",
        "eyebot: VWInit: Mako has no differential drive",
    ] {
        assert!(log.contains(said), "{said}: {log}");
    }
}

//! The RoBIOS MK4 calls beyond the sensor link (timers, threads, semaphores, time of day,
//! machine calls, latches, LCD and sound), the build flags a student's program gets, and the
//! traps that must not end in silent success. Programs in `tests/mk4/` and
//! `firmware-protocol/c/examples/timer_square.c`, run in lockstep against the daemon.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

use eyebot_hil::gap::convert::{ConvertOptions, convert};
use eyebot_test_support::Daemon;
use eyebot_test_support::eyebot_c::{
    self, Target, assert_same_run, run_program, run_program_args, run_to_end, start_daemon,
    stop_daemon,
};
use eyebot_test_support::recording::first_difference;

const BIN: &str = env!("CARGO_BIN_EXE_eyebot-hil");
const TMP: &str = env!("CARGO_TARGET_TMPDIR");
const TIMEOUT: Duration = Duration::from_secs(120);

fn mk4_source(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/mk4")
        .join(name)
}

fn build(target: Target) -> PathBuf {
    let programs = [
        mk4_source("mk4_calls.c"),
        mk4_source("traps.c"),
        mk4_source("student_dive.c"),
    ];
    let refs: Vec<&Path> = programs.iter().map(PathBuf::as_path).collect();
    eyebot_c::build(TMP, "mk4", target, &refs, &[])
}

/// What `mk4_calls` prints on the LCD, line by line (times in ticks since its start).
/// Threads: C (priority 2) runs first and blocks on the semaphore; then round robin in spawn
/// order from C: the loop thread, A, B; B's OSSemV (after its last OSWait(3), at 49) wakes C,
/// which kills the loop thread; A ends at 55 and OSReschedule returns to main.
const MK4_CALLS_LCD: &str = "\
attach scale 3: handle; scale 0: 0
after OSWait(30): 10 calls at 3 6 9 12 15 18 21 24 27 30
detach: 1, again: 0
after detach and OSWait(10): 10 calls
OSMTInit: 0
spawn bad priority: NULL; uid of b: 2
threads: L@40 A@40 B@40 B@43 L@44 A@45 B@46 L@48 C@49 killed@49 A@50
main back at 55
yield: Y1@55 Z1@55 Y2@55 Z2@55
timer semaphore: P@62 P@69 P@76
OSSetTime: 0
OSGetTime after 150 ticks: 12:34:57 50
OSSetTime(25, 0, 0): -1
OSVersion: non-empty
OSMachineSpeed 35000000 type 1 (VEHICLE 1) name Mako id 1
latch: write 0 read 3 write 3 read 10 in 255
LCD:   3.142|  2.50|FF|0A|   42|set7| pos 3 4
tone done at once: 0, after 20 ticks: 1
warning 7
OSError (no deadend): 0
out pending: 0; flush out: 0; bad port: -1
end at 246
";

/// Each new call does what docs/eyebot.md says, on the host and under qemu-m68k, with the
/// same bytes on the wire.
#[test]
fn mk4_calls_behave_and_agree_host_and_m68k() {
    let host = build(Target::Host);
    let m68k = build(Target::M68k);
    let mut runs = Vec::new();
    for (target, dir) in [(Target::Host, &host), (Target::M68k, &m68k)] {
        let daemon = start_daemon(BIN, "mk4-calls", None, 5);
        let mut daemon = daemon;
        let run = run_program(&daemon, target, &dir.join("mk4_calls"), &[], TIMEOUT);
        let rec = stop_daemon(&mut daemon);
        assert!(
            run.status.success(),
            "{target:?}: {:?}\n{}",
            run.status,
            run.stderr
        );
        assert_eq!(
            run.stdout, MK4_CALLS_LCD,
            "{target:?} LCD; stderr:\n{}",
            run.stderr
        );
        // sound goes to the log with the program time: started at tick 226 (of the program's
        // clock; the daemon starts at 0 and the program at 0)
        assert!(
            run.stderr
                .contains("eyebot: sound: tone 440 Hz for 200 ms at t 2.26 s"),
            "{}",
            run.stderr
        );
        assert!(
            run.stderr.contains("eyebot: sound: beep at t 2.46 s"),
            "{}",
            run.stderr
        );
        runs.push((rec.transcript(), run.stdout));
    }
    // a short transcript (the program spends most calls off the wire), compared in full
    assert!(
        runs[0].0.len() > 20,
        "short transcript: {} chunks",
        runs[0].0.len()
    );
    assert!(
        runs[0].0 == runs[1].0,
        "mk4_calls: host and m68k transcripts differ at {}",
        first_difference(&runs[0].0, &runs[1].0)
    );
}

/// A run of `program ARG` against a fresh daemon: (exit code, stdout, stderr).
fn run_mode(dir: &Path, program: &str, arg: &str) -> (Option<i32>, String, String) {
    let mut daemon = start_daemon(BIN, &format!("mk4-{arg}"), None, 1);
    let run = run_program_args(
        &daemon,
        Target::Host,
        &dir.join(program),
        &[arg],
        &[],
        TIMEOUT,
    );
    daemon.stop();
    (run.status.code(), run.stdout, run.stderr)
}

/// The calls that end a program end it with their status and a message naming them.
#[test]
fn ending_calls_end_the_program_with_a_reason() {
    let host = build(Target::Host);
    for (arg, code, message) in [
        ("panic", 6, "OSPanic(\"out of air\"): program stopped"),
        (
            "error",
            6,
            "OSError(\"sensor dead\", 3, deadend): program stopped",
        ),
        (
            "wait_in_timer",
            4,
            "OSWait/OSSleep called inside a timer function",
        ),
        ("deadlock", 4, "every thread is blocked"),
    ] {
        let (status, _, stderr) = run_mode(&host, "mk4_calls", arg);
        assert_eq!(status, Some(code), "{arg}: {stderr}");
        assert!(stderr.contains(message), "{arg}: {stderr}");
    }
}

/// "Press GO" with no key script, and a motor driven without MOTORInit: both end the program
/// with a non-zero status and a message that names the call.
#[test]
fn silent_traps_fail_loudly() {
    let host = build(Target::Host);
    let (status, stdout, stderr) = run_mode(&host, "traps", "key");
    assert_eq!(status, Some(5), "{stdout}{stderr}");
    assert!(
        stdout.contains("press GO") && !stdout.contains("going"),
        "{stdout}"
    );
    assert!(
        stderr.contains("KEYWait(0x8) waits for a key but the key script is empty")
            && stderr.contains("EYEBOT_KEYS"),
        "{stderr}"
    );
    let (status, stdout, stderr) = run_mode(&host, "traps", "motor");
    assert_eq!(status, Some(4), "{stdout}{stderr}");
    assert!(!stdout.contains("drove"), "{stdout}");
    assert!(
        stderr.contains("MOTORDrive(handle 1): not a motor handle from MOTORInit"),
        "{stderr}"
    );
}

/// A program as students wrote it (void main, M_PI, an unused variable, floats for ints)
/// compiles with its warnings shown, not fatal, and runs unchanged: it dives.
#[test]
fn a_student_program_builds_with_warnings_and_runs() {
    let host = build(Target::Host);
    // Rebuild just that program to see what the compiler said: `-W` takes its source as new,
    // so the library the other tests link against is left alone.
    let source = mk4_source("student_dive.c");
    let output = eyebot_c::run_make(
        Command::new("make")
            .arg("-C")
            .arg(eyebot_c::c_source_dir())
            .arg(format!("OUT={}", host.display()))
            .arg(format!("PROG={}", source.display()))
            .arg("-W")
            .arg(&source)
            .arg(host.join("student_dive")),
    );
    let said = String::from_utf8_lossy(&output.stderr);
    assert!(output.status.success(), "{said}");
    for warning in ["return type of 'main' is not 'int'", "unused variable"] {
        let plain = said.replace(['\u{2018}', '\u{2019}'], "'");
        assert!(
            plain.contains(warning),
            "expected the warning {warning:?}:\n{said}"
        );
    }
    let daemon = start_daemon(BIN, "student", None, 2);
    let run = run_program(
        &daemon,
        Target::Host,
        &host.join("student_dive"),
        &[],
        TIMEOUT,
    );
    let mut daemon = daemon;
    let rec = stop_daemon(&mut daemon);
    eprintln!("{}{}", run.stdout, run.stderr);
    assert!(
        run.stdout.starts_with("Dive!\n") && run.stdout.ends_with("done\n"),
        "{}",
        run.stdout
    );
    let deepest = rec.states.iter().map(|s| s.z_m).fold(0.0, f64::max);
    assert!(deepest > 0.6, "deepest {deepest:.2} m: it did not dive");
}

/// The timer-and-threads square course: host and 68k give the same bytes in lockstep, the
/// course is flown (four legs, depth held after the descent), and the speed figure is printed.
#[test]
fn timer_square_flies_its_course_host_and_m68k_alike() {
    let host = eyebot_c::build(TMP, "timer-square", Target::Host, &[], &[]);
    let m68k = eyebot_c::build(TMP, "timer-square", Target::M68k, &[], &[]);
    let mut runs = Vec::new();
    for (target, dir) in [(Target::Host, &host), (Target::M68k, &m68k)] {
        // the middle of the pool: the square and the glide while surfacing stay off the walls
        let daemon = start_daemon(BIN, "timer-square", Some(([12.5, 6.25, 0.3], 0.0)), 3);
        let started = Instant::now();
        let (rec, stdout) = run_to_end(daemon, target, &dir.join("timer_square"), &[], TIMEOUT);
        let wall = started.elapsed().as_secs_f64();
        let sim = rec.states.last().map_or(0.0, |s| s.t_s);
        eprintln!(
            "timer_square {target:?}: {sim:.1} s simulated in {wall:.2} s wall ({:.0}x, daemon \
             start and stop included)",
            sim / wall
        );
        if target == Target::Host {
            judge_square(&rec, &stdout);
        }
        runs.push((rec.transcript(), stdout));
    }
    assert_same_run("timer_square, host and m68k", &runs[0], &runs[1]);
}

/// The library's TIME_STEP buffer (PROTOCOL.md 2.9) never shows a program a value the bus
/// would not have delivered: with the buffer (the default) and without it (`EYEBOT_STEP=0`,
/// one ADC_READ/COMPASS_READ per call) a program that reads every tick, in a pattern that
/// changes so the buffer both hits and misses, prints the same values and the vehicle
/// follows the same path (ground truth equal bit for bit); with the buffer, host and
/// qemu-m68k builds give the same bytes. `timer_square` and `sonar_three` (which waits for
/// the sonar with TIME_STEP's stop on sonar output) print the same with and without it too.
/// `gap convert` makes the same commands and channels of both recordings.
#[test]
fn the_step_buffer_shows_what_the_bus_would_have_shown() {
    let programs = [mk4_source("read_ahead.c")];
    let refs: Vec<&Path> = programs.iter().map(PathBuf::as_path).collect();
    let host = eyebot_c::build(TMP, "read-ahead", Target::Host, &refs, &[]);
    let m68k = eyebot_c::build(TMP, "read-ahead", Target::M68k, &refs, &[]);
    let wall_start = Some(([2.0, 1.5, 0.5], 0.0));
    let mut runs = Vec::new();
    for (program, start, target, dir, step) in [
        ("read_ahead", None, Target::Host, &host, "0"),
        ("read_ahead", None, Target::Host, &host, "1"),
        ("read_ahead", None, Target::M68k, &m68k, "1"),
        ("timer_square", None, Target::Host, &host, "0"),
        ("timer_square", None, Target::Host, &host, "1"),
        ("sonar_three", wall_start, Target::Host, &host, "0"),
        ("sonar_three", wall_start, Target::Host, &host, "1"),
    ] {
        let mut daemon = start_daemon(BIN, &format!("step-{program}-{step}"), start, 5);
        let run = run_program(
            &daemon,
            target,
            &dir.join(program),
            &[("EYEBOT_STEP", step)],
            TIMEOUT,
        );
        assert!(
            run.status.success(),
            "{program}: {}{}",
            run.stdout,
            run.stderr
        );
        let (rec, stdout) = (stop_daemon(&mut daemon), run.stdout);
        // What `gap convert` makes of the recording: the same commands and channels whether
        // they travelled in THRUSTER_SET_ALL/ADC_VALUE/COMPASS_HEADING or TIME_STEP/STEP.
        let converted = convert(daemon.record_dir(), &ConvertOptions::default())
            .ok()
            .map(|c| (c.measurement.commands, c.measurement.channels));
        let states: Vec<_> = rec
            .states
            .iter()
            .map(eyebot_test_support::recording::state_bits)
            .collect();
        let step_types = rec
            .stream("sensor", eyebot_test_support::recording::Direction::Rx)
            .windows(3)
            .filter(|w| w[0] == 0xEB && w[1] == 0x90 && w[2] == 0x43)
            .count();
        runs.push((
            program,
            target,
            step,
            rec.transcript(),
            stdout,
            states,
            step_types,
            converted,
        ));
    }
    for pair in runs.chunks(2).take(1).chain(runs[3..].chunks(2)) {
        let (a, b) = (&pair[0], &pair[1]);
        assert_eq!(a.6, 0, "{}: EYEBOT_STEP=0 sends no TIME_STEP", a.0);
        assert!(
            b.6 > 10,
            "{}: the buffer was used ({} TIME_STEPs)",
            b.0,
            b.6
        );
        // read_ahead prints a line per tick, timer_square its legs and "done", sonar_three
        // one line per reading of its three.
        let least = match a.0 {
            "read_ahead" => 300,
            "sonar_three" => 3,
            _ => 5,
        };
        assert!(a.4.lines().count() >= least, "{}: {}", a.0, a.4);
        assert_eq!(a.4, b.4, "{}: values differ with the buffer", a.0);
        assert!(a.5.len() > 100, "{}: {} state rows", a.0, a.5.len());
        assert!(
            a.5 == b.5,
            "{}: ground truth differs with the buffer at row {:?}",
            a.0,
            a.5.iter().zip(&b.5).position(|(x, y)| x != y)
        );
    }
    for pair in [&runs[0..2], &runs[3..5]] {
        let (a, b) = (&pair[0], &pair[1]);
        let (commands, channels) = a.7.as_ref().expect("the recording converts");
        assert!(commands.len() > 10, "{}: {} commands", a.0, commands.len());
        // A depth sample per read; a heading per compass conversion (every 0.4 s: the reads
        // between two conversions repeat the first, and `gap convert` keeps it once).
        for (name, least) in [("depth_adc", 100), ("compass_deg", 20)] {
            let n = channels
                .iter()
                .find(|c| c.name == name)
                .map_or(0, |c| c.samples.len());
            assert!(n >= least, "{}: {n} {name} samples", a.0);
        }
        assert!(
            a.7 == b.7,
            "{}: gap convert gives other commands or channels with the buffer",
            a.0
        );
    }
    assert_same_run(
        "read_ahead with the buffer, host and m68k",
        &(runs[1].3.clone(), runs[1].4.clone()),
        &(runs[2].3.clone(), runs[2].4.clone()),
    );
}

/// Depth sensor in the body frame (configs/sensors/mako-2008.toml [depth]).
const DEPTH_SENSOR_BODY_M: [f64; 3] = [-0.45, 0.0, 0.15];

fn judge_square(rec: &eyebot_test_support::Recording, stdout: &str) {
    assert!(stdout.matches("leg ").count() >= 4, "{stdout}");
    assert!(
        stdout.contains("leg 4: heading") && stdout.ends_with("done\n"),
        "{stdout}"
    );
    // the thrusters stop after the last leg and Mako floats up
    let surfacing_s: f64 = stdout
        .lines()
        .find_map(|l| {
            l.strip_prefix("surfacing at ")?
                .strip_suffix(" s")?
                .parse()
                .ok()
        })
        .unwrap_or_else(|| panic!("no \"surfacing at T s\" line: {stdout}"));
    // depth at the sensor within 0.1 m of 0.8 m once down (from 20 s on) until then
    let worst = rec
        .states
        .iter()
        .filter(|s| s.t_s >= 20.0 && s.t_s <= surfacing_s)
        .map(|s| {
            let (sr, cr) = s.roll_rad.sin_cos();
            let (sp, cp) = s.pitch_rad.sin_cos();
            let z = s.z_m - sp * DEPTH_SENSOR_BODY_M[0]
                + cp * sr * DEPTH_SENSOR_BODY_M[1]
                + cp * cr * DEPTH_SENSOR_BODY_M[2];
            (z - 0.8).abs()
        })
        .fold(0.0, f64::max);
    eprintln!("timer_square: worst depth error from 20 s to {surfacing_s} s {worst:.3} m");
    assert!(
        worst < 0.1,
        "depth error {worst:.3} m from 20 s to {surfacing_s} s"
    );
    // at the surface by the end: the centre of mass above its holding depth (about 0.65 m)
    let last = rec.states.last().map_or(f64::NAN, |s| s.z_m);
    assert!(
        last < 0.4,
        "centre of mass at {last:.3} m when the program ended"
    );
    // the paddle-wheel timer measured a speed (the display thread printed it)
    assert!(
        stdout
            .lines()
            .any(|l| l.contains("speed") && !l.ends_with("speed 0 cm/s")),
        "{stdout}"
    );
    if let Some(s) = rec.states.iter().find(|s| s.contact) {
        panic!(
            "touched the pool at t {:.1} s, x {:.2} y {:.2} m, yaw {:.0} deg",
            s.t_s,
            s.x_m,
            s.y_m,
            s.yaw_rad.to_degrees()
        );
    }
}

/// Real time: a control step run by a 10 ms timer (three reads and two thruster commands,
/// each a round trip to the bridge) runs on the host clock: about 100 times a second, never
/// more often than the ticks that passed. How close to 100 Hz depends on the machine's load;
/// the figure is printed here and recorded in docs/performance.md.
#[test]
fn a_timer_control_loop_runs_on_the_host_clock_in_real_time() {
    let host = eyebot_c::build(TMP, "rate", Target::Host, &[&mk4_source("rate100.c")], &[]);
    let mut daemon = Daemon::options(BIN, "rate100").realtime().start();
    let run = run_program(
        &daemon,
        Target::Host,
        &host.join("rate100"),
        &[
            ("EYEBOT_TIME_MODE", "realtime"),
            ("EYEBOT_TIMEOUT_MS", "100"),
        ],
        TIMEOUT,
    );
    daemon.stop();
    eprintln!("{}{}", run.stdout, run.stderr);
    assert!(run.status.success(), "{:?}: {}", run.status, run.stderr);
    let numbers: Vec<u32> = run
        .stdout
        .split_whitespace()
        .filter_map(|w| w.parse().ok())
        .collect();
    let [steps, ticks, _longest] = numbers[..] else {
        panic!("unexpected output {:?}", run.stdout);
    };
    assert!(
        (300..=600).contains(&ticks),
        "ran {ticks} ticks for OSWait(300)"
    );
    assert!(
        steps <= ticks,
        "{steps} steps in {ticks} ticks: faster than the timer"
    );
    // a broken timer runs once per OSWait or never; under load (a CI machine shared with
    // other builds) steps are skipped, so this bound is loose on purpose
    assert!(
        steps >= ticks / 10,
        "{steps} steps in {ticks} ticks: the timer is not running every tick"
    );
}

/// On demand: lockstep speed (simulated seconds per wall second) of the shipped examples and
/// where the wall time goes: requests the program sent on the sensor link per 10 ms tick, and
/// wall time per request. Each program runs against a fresh daemon in two modes, in the same
/// run: the baseline without TIME_STEP (`EYEBOT_STEP=0`: one round trip per reading,
/// thrusters and TIME_ADVANCE) and the default with it, alternating, `LOCKSTEP_SPEED_ROUNDS`
/// times each (default 3): on a shared host one run's wall time depends on what else is
/// scheduled, so the best and the median run of each mode are printed; the ratio is step /
/// baseline of the best runs. Figures in docs/eyebot.md ("Lockstep speed").
#[test]
#[ignore = "a benchmark: cargo test --test eyebot_c_mk4 lockstep_speed -- --ignored \
            --nocapture"]
fn lockstep_speed() {
    let host = eyebot_c::build(TMP, "speed", Target::Host, &[], &[]);
    let wall_start = Some(([2.0, 1.5, 0.5], 0.0));
    let rounds: usize = std::env::var("LOCKSTEP_SPEED_ROUNDS")
        .ok()
        .and_then(|v| v.parse().ok())
        .filter(|&n| n > 0)
        .unwrap_or(3);
    eprintln!("{rounds} runs per program and mode; x real: best, median");
    eprintln!(
        "{:<14} {:>4} {:>7} {:>7} {:>7} {:>7} {:>9} {:>9} {:>8} {:>7}",
        "program",
        "step",
        "sim s",
        "wall s",
        "x best",
        "x med",
        "requests",
        "req/tick",
        "us/req",
        "ratio"
    );
    for (program, start) in [
        ("dive_hold", None),
        ("heading_hold", None),
        ("spot_turn", None),
        ("sonar_three", wall_start),
        ("wall_follower", wall_start),
        ("timer_square", None),
    ] {
        // per mode: simulated seconds, requests, wall seconds of each round
        let mut runs: [(f64, f64, Vec<f64>); 2] = Default::default();
        for round in 0..rounds {
            for (mode, step) in ["0", "1"].into_iter().enumerate() {
                let tag = format!("speed-{program}-{step}-{round}");
                let mut daemon = start_daemon(BIN, &tag, start, 1);
                let started = Instant::now();
                let run = run_program(
                    &daemon,
                    Target::Host,
                    &host.join(program),
                    &[("EYEBOT_STEP", step)],
                    TIMEOUT,
                );
                let wall = started.elapsed().as_secs_f64();
                // the status snapshot is refreshed every 100 ms
                std::thread::sleep(Duration::from_millis(250));
                let status = daemon.status_command(&[]);
                let rec = stop_daemon(&mut daemon);
                assert!(run.status.success(), "{program}: {}", run.stderr);
                let sim = rec.states.last().map_or(0.0, |s| s.t_s);
                let requests: f64 = status
                    .lines()
                    .find(|l| l.starts_with("sensor"))
                    // name, path "A -> B", rx bytes, tx bytes, rx frames
                    .and_then(|l| l.split_whitespace().nth(6))
                    .and_then(|v| v.parse().ok())
                    .unwrap_or_else(|| panic!("no sensor rx frames in {status}"));
                runs[mode].0 = sim;
                runs[mode].1 = requests;
                runs[mode].2.push(wall);
            }
        }
        let mut baseline = 0.0;
        for (mode, (sim, requests, walls)) in runs.iter_mut().enumerate() {
            walls.sort_by(f64::total_cmp);
            let (best, median) = (walls[0], walls[walls.len() / 2]);
            let speed = *sim / best;
            if mode == 0 {
                baseline = speed;
            }
            eprintln!(
                "{program:<14} {mode:>4} {sim:>7.1} {best:>7.2} {speed:>7.0} {:>7.0} \
                 {requests:>9.0} {:>9.2} {:>8.1} {:>7.2}",
                *sim / median,
                *requests / (*sim * 100.0),
                best * 1e6 / *requests,
                speed / baseline
            );
        }
    }
}

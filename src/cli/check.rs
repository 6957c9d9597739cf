//! `eyebot-hil check SCENARIO.toml -- PROGRAM [ARGS...]`: a user's CI test in one command.
//!
//! Starts a private daemon in lockstep in a fresh directory, runs the program against it with
//! the environment set, stops at the scenario's end time, keeps the recording, judges the
//! recorded ground truth and the program's output against the scenario's criteria, and exits
//! 0 on pass and 1 on fail, naming each failed criterion with the time and the value. The
//! scenario format is in docs/eyebot.md ("Checking a program in CI").

use std::ffi::OsString;
use std::io::{BufRead as _, BufReader, Write as _};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, ExitStatus, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use clap::Args;
use serde::Deserialize;

use super::CliError;
use crate::cli::output::outln;
use crate::record::StateRow;

/// Run a control program against a private lockstep daemon and judge it by a scenario.
#[derive(Debug, Args)]
pub struct CheckArgs {
    /// The scenario: start, seed, duration, key script and pass criteria (TOML).
    pub scenario: PathBuf,
    /// Also write the verdict as JUnit XML to FILE.
    #[arg(long, value_name = "FILE")]
    pub junit: Option<PathBuf>,
    /// Directory for the run (daemon log, recording, program output); emptied first if a
    /// previous check made it. Default: `check-NAME` in the working directory.
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// The program and its arguments, after `--` (e.g. `-- ./dive_hold` or
    /// `-- qemu-m68k ./dive_hold`).
    #[arg(last = true, required = true, value_name = "PROGRAM")]
    pub program: Vec<OsString>,
}

/// A scenario file.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Scenario {
    /// Shown in the verdict and the JUnit suite; default the file's stem.
    #[serde(default)]
    pub name: Option<String>,
    /// Daemon configuration, relative to the scenario file; default the embedded one.
    #[serde(default)]
    pub config: Option<PathBuf>,
    #[serde(default = "default_seed")]
    pub seed: u64,
    /// A course start name, or `[north_m, east_m, heading_deg]`; default the config's.
    #[serde(default)]
    pub start: Option<StartSpec>,
    /// Simulated seconds the program runs (EYEBOT_STOP_S).
    pub duration_s: u32,
    /// Wall seconds after which a program that has not ended fails; default
    /// max(10, duration_s).
    #[serde(default)]
    pub wall_limit_s: Option<f64>,
    /// EYEBOT_KEYS for the program.
    #[serde(default)]
    pub keys: Option<String>,
    /// EYEBOT_LATCH for the program: the input latches' script.
    #[serde(default)]
    pub latch: Option<String>,
    #[serde(default, rename = "criterion")]
    pub criteria: Vec<Criterion>,
}

fn default_seed() -> u64 {
    1
}

#[derive(Debug, Deserialize)]
#[serde(untagged)]
pub enum StartSpec {
    Name(String),
    Pose([f64; 3]),
}

/// A pass criterion over the recorded ground truth (`state.csv`) or the program's output.
#[derive(Debug, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum Criterion {
    /// Depth of the centre of mass within [min_m, max_m] at every sample from after_s on (to
    /// until_s, default the end).
    DepthBand {
        after_s: f64,
        #[serde(default)]
        until_s: Option<f64>,
        min_m: f64,
        max_m: f64,
    },
    /// The centre of mass inside the box at some time no later than by_s.
    Region {
        north_m: [f64; 2],
        east_m: [f64; 2],
        #[serde(default)]
        by_s: Option<f64>,
    },
    /// The centre of mass at least min_m from each side wall at every sample.
    WallDistance { min_m: f64 },
    /// The hull never touches the pool.
    NoContact,
    /// Mean surge speed over [after_s, until_s (default the end)] within [min_mps, max_mps].
    SpeedBand {
        after_s: f64,
        #[serde(default)]
        until_s: Option<f64>,
        min_mps: f64,
        max_mps: f64,
    },
    /// True heading within [min_deg, max_deg] (clockwise; the band may wrap through 0) at
    /// every sample from after_s on.
    HeadingBand {
        after_s: f64,
        min_deg: f64,
        max_deg: f64,
    },
    /// The program's LCD output (stdout) contains the text.
    LcdText { contains: String },
}

impl Criterion {
    fn label(&self) -> String {
        match self {
            Criterion::DepthBand {
                after_s,
                until_s,
                min_m,
                max_m,
            } => format!(
                "depth_band {min_m}..{max_m} m after {after_s} s{}",
                until_s.map(|t| format!(" to {t} s")).unwrap_or_default()
            ),
            Criterion::Region {
                north_m,
                east_m,
                by_s,
            } => format!(
                "region north {}..{} m, east {}..{} m{}",
                north_m[0],
                north_m[1],
                east_m[0],
                east_m[1],
                by_s.map(|t| format!(" by {t} s")).unwrap_or_default()
            ),
            Criterion::WallDistance { min_m } => format!("wall_distance >= {min_m} m"),
            Criterion::NoContact => "no_contact".into(),
            Criterion::SpeedBand {
                after_s,
                until_s,
                min_mps,
                max_mps,
            } => format!(
                "speed_band {min_mps}..{max_mps} m/s from {after_s} s{}",
                until_s.map(|t| format!(" to {t} s")).unwrap_or_default()
            ),
            Criterion::HeadingBand {
                after_s,
                min_deg,
                max_deg,
            } => format!("heading_band {min_deg}..{max_deg} deg after {after_s} s"),
            Criterion::LcdText { contains } => format!("lcd_text {contains:?}"),
        }
    }

    /// `Ok(summary)` or `Err(the time and value that failed it)`.
    fn judge(&self, states: &[StateRow], pool: (f64, f64), lcd: &str) -> Result<String, String> {
        match self {
            Criterion::DepthBand {
                after_s,
                until_s,
                min_m,
                max_m,
            } => {
                let until = until_s.unwrap_or(f64::INFINITY);
                let rows: Vec<&StateRow> = states
                    .iter()
                    .filter(|s| s.t_s >= *after_s && s.t_s <= until)
                    .collect();
                if rows.is_empty() {
                    return Err(match until_s {
                        Some(u) if *u < *after_s => {
                            format!("until_s {u} s is before after_s {after_s} s")
                        }
                        _ => format!("the run ended before {after_s} s"),
                    });
                }
                if let Some(s) = rows.iter().find(|s| s.z_m < *min_m || s.z_m > *max_m) {
                    return Err(format!("at t {:.2} s depth {:.3} m", s.t_s, s.z_m));
                }
                let (lo, hi) = min_max(rows.iter().map(|s| s.z_m));
                Ok(format!("depth {lo:.3}..{hi:.3} m"))
            }
            Criterion::Region {
                north_m,
                east_m,
                by_s,
            } => {
                let limit = by_s.unwrap_or(f64::INFINITY);
                match states.iter().find(|s| {
                    s.t_s <= limit
                        && (north_m[0]..=north_m[1]).contains(&s.x_m)
                        && (east_m[0]..=east_m[1]).contains(&s.y_m)
                }) {
                    Some(s) => Ok(format!("reached at t {:.2} s", s.t_s)),
                    None => {
                        let last = states.iter().rfind(|s| s.t_s <= limit);
                        Err(match last {
                            Some(s) => format!(
                                "not reached; at t {:.2} s the vehicle was at north {:.2} m, \
                                 east {:.2} m",
                                s.t_s, s.x_m, s.y_m
                            ),
                            None => "no state recorded".into(),
                        })
                    }
                }
            }
            Criterion::WallDistance { min_m } => {
                let distance =
                    |s: &StateRow| s.x_m.min(pool.0 - s.x_m).min(s.y_m).min(pool.1 - s.y_m);
                match states.iter().find(|s| distance(s) < *min_m) {
                    Some(s) => Err(format!(
                        "at t {:.2} s {:.3} m from a wall (north {:.2}, east {:.2})",
                        s.t_s,
                        distance(s),
                        s.x_m,
                        s.y_m
                    )),
                    None => {
                        let (lo, _) = min_max(states.iter().map(distance));
                        Ok(format!("closest {lo:.3} m"))
                    }
                }
            }
            Criterion::NoContact => match states.iter().find(|s| s.contact) {
                Some(s) => Err(format!(
                    "contact at t {:.2} s (north {:.2}, east {:.2})",
                    s.t_s, s.x_m, s.y_m
                )),
                None => Ok("no contact".into()),
            },
            Criterion::SpeedBand {
                after_s,
                until_s,
                min_mps,
                max_mps,
            } => {
                let until = until_s.unwrap_or(f64::INFINITY);
                let v: Vec<f64> = states
                    .iter()
                    .filter(|s| s.t_s >= *after_s && s.t_s <= until)
                    .map(|s| s.u_mps)
                    .collect();
                if v.is_empty() {
                    return Err(format!("no state from {after_s} s on"));
                }
                let mean = v.iter().sum::<f64>() / v.len() as f64;
                if (*min_mps..=*max_mps).contains(&mean) {
                    Ok(format!("mean surge {mean:.3} m/s"))
                } else {
                    Err(format!("mean surge {mean:.3} m/s from t {after_s} s"))
                }
            }
            Criterion::HeadingBand {
                after_s,
                min_deg,
                max_deg,
            } => {
                let inside = |h: f64| {
                    let h = h.rem_euclid(360.0);
                    let (a, b) = (min_deg.rem_euclid(360.0), max_deg.rem_euclid(360.0));
                    if a <= b {
                        (a..=b).contains(&h)
                    } else {
                        h >= a || h <= b
                    }
                };
                let rows: Vec<&StateRow> = states.iter().filter(|s| s.t_s >= *after_s).collect();
                if rows.is_empty() {
                    return Err(format!("the run ended before {after_s} s"));
                }
                match rows.iter().find(|s| !inside(s.yaw_rad.to_degrees())) {
                    Some(s) => Err(format!(
                        "at t {:.2} s heading {:.1} deg",
                        s.t_s,
                        s.yaw_rad.to_degrees().rem_euclid(360.0)
                    )),
                    None => Ok("inside".into()),
                }
            }
            Criterion::LcdText { contains } => {
                if lcd.contains(contains.as_str()) {
                    Ok("seen".into())
                } else {
                    let last = lcd.lines().last().unwrap_or("");
                    Err(format!("not in the LCD output (last line {last:?})"))
                }
            }
        }
    }
}

fn min_max(values: impl Iterator<Item = f64>) -> (f64, f64) {
    values.fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), v| {
        (lo.min(v), hi.max(v))
    })
}

/// One judged line of the verdict.
struct Verdict {
    label: String,
    result: Result<String, String>,
}

fn err_io(doing: &'static str, path: &Path, source: std::io::Error) -> CliError {
    CliError::Io {
        doing,
        path: path.to_path_buf(),
        source,
    }
}

/// Marks a directory made by `check`, so a later check may empty it.
const MARKER: &str = ".eyebot-hil-check";

fn fresh_dir(dir: &Path) -> Result<(), CliError> {
    if dir.exists() {
        if !dir.join(MARKER).exists() {
            return Err(CliError::Usage(format!(
                "{}: exists and was not made by `check`; name another with --out",
                dir.display()
            )));
        }
        std::fs::remove_dir_all(dir).map_err(|e| err_io("remove", dir, e))?;
    }
    std::fs::create_dir_all(dir).map_err(|e| err_io("create", dir, e))?;
    std::fs::write(dir.join(MARKER), "").map_err(|e| err_io("write", &dir.join(MARKER), e))
}

pub fn main(args: CheckArgs) -> Result<(), CliError> {
    let text =
        std::fs::read_to_string(&args.scenario).map_err(|e| err_io("read", &args.scenario, e))?;
    let scenario: Scenario = toml::from_str(&text).map_err(|e| {
        CliError::Usage(format!(
            "{}: not a scenario: {}",
            args.scenario.display(),
            e.to_string().trim_end()
        ))
    })?;
    let name = scenario.name.clone().unwrap_or_else(|| {
        args.scenario
            .file_stem()
            .map_or("scenario".into(), |s| s.to_string_lossy().into_owned())
    });
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| PathBuf::from(format!("check-{name}")));
    fresh_dir(&out)?;
    let out = std::fs::canonicalize(&out).map_err(|e| err_io("resolve", &out, e))?;
    let base = args.scenario.parent().unwrap_or(Path::new("."));

    let mut daemon = start_daemon(&scenario, base, &out)?;
    let started = Instant::now();
    let program = run_program(&scenario, &args.program, &out);
    let wall_s = started.elapsed().as_secs_f64();
    stop(&mut daemon);
    let program = program?;

    let states = crate::record::read_state(&out.join("rec")).map_err(|e| {
        CliError::Usage(format!(
            "the recording in {}: {e}",
            out.join("rec").display()
        ))
    })?;
    let reached_s = states.last().map_or(0.0, |s| s.t_s);
    let lcd = std::fs::read_to_string(out.join("program.out")).unwrap_or_default();
    let pool = pool_of(&scenario, base)?;

    let mut verdicts = vec![Verdict {
        label: "program".into(),
        result: program.judge(scenario.duration_s, reached_s, wall_s),
    }];
    for c in &scenario.criteria {
        verdicts.push(Verdict {
            label: c.label(),
            result: c.judge(&states, pool, &lcd),
        });
    }
    let failed = verdicts.iter().filter(|v| v.result.is_err()).count();
    for v in &verdicts {
        match &v.result {
            Ok(s) => outln!("pass  {}: {s}", v.label),
            Err(s) => outln!("FAIL  {}: {s}", v.label),
        }
    }
    outln!(
        "{name}: {} ({} of {} criteria failed; {reached_s:.2} s simulated in {wall_s:.2} s; run \
         kept in {})",
        if failed == 0 { "pass" } else { "FAIL" },
        failed,
        verdicts.len(),
        out.display()
    );
    if let Some(path) = &args.junit {
        write_junit(path, &name, &verdicts, wall_s)?;
    }
    if failed > 0 {
        return Err(CliError::CheckFailed {
            failed,
            total: verdicts.len(),
        });
    }
    Ok(())
}

/// The pool's length and width (m), for `wall_distance`.
fn pool_of(scenario: &Scenario, base: &Path) -> Result<(f64, f64), CliError> {
    let overrides = crate::daemon::config::Overrides::default();
    let path = scenario.config.as_ref().map(|c| base.join(c));
    let loaded = super::run::load_config(path.as_ref(), &overrides)?;
    let world = crate::physics::load_world(loaded.source.as_ref(), &loaded.config.world)?;
    Ok((world.pool_m.x, world.pool_m.y))
}

fn start_daemon(scenario: &Scenario, base: &Path, out: &Path) -> Result<Child, CliError> {
    let exe = std::env::current_exe().map_err(|e| err_io("find", Path::new("eyebot-hil"), e))?;
    let log = std::fs::File::create(out.join("daemon.log"))
        .map_err(|e| err_io("create", &out.join("daemon.log"), e))?;
    let mut cmd = Command::new(exe);
    cmd.current_dir(out)
        .args([
            "run",
            "--time-mode",
            "lockstep",
            "--record",
            "rec",
            "--run-dir",
            "run",
        ])
        .arg("--seed")
        .arg(scenario.seed.to_string())
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(log);
    if let Some(config) = &scenario.config {
        let path = std::fs::canonicalize(base.join(config))
            .map_err(|e| err_io("read", &base.join(config), e))?;
        cmd.arg("--config").arg(path);
    }
    match &scenario.start {
        Some(StartSpec::Name(n)) => {
            cmd.arg("--start").arg(n);
        }
        Some(StartSpec::Pose([n, e, h])) => {
            cmd.arg("--start").arg(format!("{n},{e},{h}"));
        }
        None => {}
    }
    let mut child = cmd
        .spawn()
        .map_err(|e| err_io("run", Path::new("eyebot-hil run"), e))?;
    let Some(stdout) = child.stdout.take() else {
        return Err(CliError::Usage("the daemon's stdout is not a pipe".into()));
    };
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines() {
            let Ok(line) = line else { break };
            if line.starts_with("ready") {
                let _ = tx.send(());
            }
        }
    });
    if rx.recv_timeout(Duration::from_secs(30)).is_err() {
        let _ = child.kill();
        let _ = child.wait();
        let log = std::fs::read_to_string(out.join("daemon.log")).unwrap_or_default();
        return Err(CliError::Usage(format!(
            "the daemon did not become ready: {}",
            log.lines().last().unwrap_or("(no log)")
        )));
    }
    Ok(child)
}

fn stop(daemon: &mut Child) {
    let pid = nix::unistd::Pid::from_raw(daemon.id() as i32);
    let _ = nix::sys::signal::kill(pid, nix::sys::signal::Signal::SIGINT);
    let deadline = Instant::now() + Duration::from_secs(20);
    while Instant::now() < deadline {
        if let Ok(Some(_)) = daemon.try_wait() {
            return;
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let _ = daemon.kill();
    let _ = daemon.wait();
}

/// How the program ended.
enum Ended {
    Exited(ExitStatus),
    TimedOut(f64),
}

struct ProgramEnd {
    ended: Ended,
    stderr_tail: String,
}

impl ProgramEnd {
    fn judge(&self, duration_s: u32, reached_s: f64, wall_s: f64) -> Result<String, String> {
        let tail = if self.stderr_tail.is_empty() {
            String::new()
        } else {
            format!(": {}", self.stderr_tail)
        };
        match &self.ended {
            Ended::TimedOut(limit) => Err(format!(
                "did not reach {duration_s} s of simulated time within {limit} s of wall time \
                 (it reached {reached_s:.2} s: the program hangs or stopped calling the bridge)"
            )),
            Ended::Exited(status) if status.success() => Ok(format!(
                "ended with status 0 at {reached_s:.2} s simulated, {wall_s:.2} s wall"
            )),
            Ended::Exited(status) => Err(match status.code() {
                Some(code) => format!("exit status {code} at t {reached_s:.2} s{tail}"),
                None => format!("killed by a signal at t {reached_s:.2} s ({status}){tail}"),
            }),
        }
    }
}

fn run_program(
    scenario: &Scenario,
    program: &[OsString],
    out: &Path,
) -> Result<ProgramEnd, CliError> {
    let Some((exe, rest)) = program.split_first() else {
        return Err(CliError::Usage("no program after --".into()));
    };
    let stdout_path = out.join("program.out");
    let stderr_path = out.join("program.err");
    let stdout =
        std::fs::File::create(&stdout_path).map_err(|e| err_io("create", &stdout_path, e))?;
    let stderr =
        std::fs::File::create(&stderr_path).map_err(|e| err_io("create", &stderr_path, e))?;
    let mut cmd = Command::new(exe);
    cmd.args(rest)
        .env("EYEBOT_RUN_DIR", out.join("run"))
        .env("EYEBOT_TIME_MODE", "lockstep")
        // in lockstep a resend would change the run: wait generously instead
        .env("EYEBOT_TIMEOUT_MS", "3000")
        .env("EYEBOT_STOP_S", scenario.duration_s.to_string())
        .env_remove("EYEBOT_LCD")
        .stdin(Stdio::null())
        .stdout(stdout)
        .stderr(stderr);
    match &scenario.keys {
        Some(k) => cmd.env("EYEBOT_KEYS", k),
        None => cmd.env_remove("EYEBOT_KEYS"),
    };
    match &scenario.latch {
        Some(l) => cmd.env("EYEBOT_LATCH", l),
        None => cmd.env_remove("EYEBOT_LATCH"),
    };
    let mut child = cmd
        .spawn()
        .map_err(|e| CliError::Usage(format!("cannot start {}: {e}", Path::new(exe).display())))?;
    let limit = scenario
        .wall_limit_s
        .unwrap_or_else(|| f64::from(scenario.duration_s).max(10.0));
    let deadline = Instant::now() + Duration::from_secs_f64(limit.max(0.1));
    let ended = loop {
        match child.try_wait() {
            Ok(Some(status)) => break Ended::Exited(status),
            Ok(None) if Instant::now() >= deadline => {
                let _ = child.kill();
                let _ = child.wait();
                break Ended::TimedOut(limit);
            }
            Ok(None) => std::thread::sleep(Duration::from_millis(10)),
            Err(e) => return Err(err_io("wait for", Path::new(exe), e)),
        }
    };
    let stderr_tail = std::fs::read_to_string(&stderr_path)
        .unwrap_or_default()
        .lines()
        .last()
        .unwrap_or("")
        .to_string();
    Ok(ProgramEnd { ended, stderr_tail })
}

/// The verdicts as a JUnit XML report (one test suite, one test case per criterion),
/// written by `quick-junit`.
fn junit_report(name: &str, verdicts: &[Verdict], wall_s: f64) -> quick_junit::Report {
    use quick_junit::{NonSuccessKind, Report, TestCase, TestCaseStatus, TestSuite};
    let mut suite = TestSuite::new(name);
    suite.set_time(std::time::Duration::from_secs_f64(wall_s.max(0.0)));
    for v in verdicts {
        let status = match &v.result {
            Ok(_) => TestCaseStatus::success(),
            Err(why) => {
                let mut status = TestCaseStatus::non_success(NonSuccessKind::Failure);
                status.set_message(why.as_str());
                status
            }
        };
        let mut case = TestCase::new(v.label.as_str(), status);
        case.set_classname(name);
        if let Ok(said) = &v.result {
            case.set_system_out(said.as_str());
        }
        suite.add_test_case(case);
    }
    let mut report = Report::new(name);
    report.add_test_suite(suite);
    report
}

fn write_junit(path: &Path, name: &str, verdicts: &[Verdict], wall_s: f64) -> Result<(), CliError> {
    let xml = junit_report(name, verdicts, wall_s)
        .to_string()
        .map_err(|e| err_io("write", path, std::io::Error::other(e)))?;
    let mut f = std::fs::File::create(path).map_err(|e| err_io("create", path, e))?;
    f.write_all(xml.as_bytes())
        .map_err(|e| err_io("write", path, e))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A verdict with markup and control characters in its text gives well-formed XML that
    /// says the same (a hand-written escape once missed control characters).
    #[test]
    fn junit_reports_escape_whatever_a_verdict_says() {
        let verdicts = [
            Verdict {
                label: "depth <0.8> & \"more\"".into(),
                result: Err("at t 3 s: depth 0.5 m\u{1b}[31m <- bell \u{7}".into()),
            },
            Verdict {
                label: "no_contact".into(),
                result: Ok("no contact in 60 s".into()),
            },
        ];
        let xml = junit_report("dive & hold", &verdicts, 1.5)
            .to_string()
            .unwrap();
        assert!(!xml.contains('\u{1b}') && !xml.contains('\u{7}'), "{xml}");
        assert!(xml.contains("name=\"dive &amp; hold\""), "{xml}");
        assert!(
            xml.contains("tests=\"2\"") && xml.contains("failures=\"1\""),
            "{xml}"
        );
        assert!(
            xml.contains("depth &lt;0.8&gt; &amp; &quot;more&quot;"),
            "{xml}"
        );
        assert!(
            xml.contains("<failure message=\"at t 3 s: depth 0.5 m"),
            "{xml}"
        );
        assert!(xml.contains("no contact in 60 s"), "{xml}");
    }

    fn criterion(text: &str) -> Criterion {
        toml::from_str(text).expect("criterion parses")
    }

    /// `depth_band` judges the samples from `after_s` to `until_s` only, and says so when the
    /// window is empty because `until_s` comes first.
    #[test]
    fn depth_band_ends_at_until_s() {
        let states: Vec<StateRow> = (0..100)
            .map(|i| StateRow {
                t_s: f64::from(i),
                z_m: if i < 80 { 0.65 } else { 0.25 },
                ..StateRow::default()
            })
            .collect();
        let band = "kind = \"depth_band\"\nafter_s = 20.0\nmin_m = 0.55\nmax_m = 0.75\n";
        let whole = criterion(band);
        let err = whole.judge(&states, (25.0, 12.5), "").unwrap_err();
        assert!(err.contains("at t 80.00 s depth 0.250 m"), "{err}");
        let held = criterion(&format!("{band}until_s = 75.0\n"));
        assert_eq!(
            held.judge(&states, (25.0, 12.5), ""),
            Ok("depth 0.650..0.650 m".to_string())
        );
        assert!(
            held.label().ends_with("after 20 s to 75 s"),
            "{}",
            held.label()
        );
        let backwards = criterion(&format!("{band}until_s = 10.0\n"));
        let err = backwards.judge(&states, (25.0, 12.5), "").unwrap_err();
        assert!(err.contains("until_s 10 s is before after_s 20 s"), "{err}");
    }
}

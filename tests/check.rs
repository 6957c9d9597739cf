//! `eyebot-hil check SCENARIO -- PROGRAM`: the shipped examples pass their scenarios
//! (`firmware-protocol/c/examples/scenarios/`) on the host and under qemu-m68k with the same
//! verdict and recording; a broken example fails naming the criterion; a program that never
//! calls the bridge fails within the scenario's wall limit; `--junit` writes the verdict.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::time::{Duration, Instant};

use eyebot_test_support::eyebot_c::{self, Target};
use eyebot_test_support::recording::first_difference;
use eyebot_test_support::{Recording, TempDir, require_tool};

const BIN: &str = env!("CARGO_BIN_EXE_eyebot-hil");
const TMP: &str = env!("CARGO_TARGET_TMPDIR");

fn scenario(name: &str) -> PathBuf {
    eyebot_c::c_source_dir()
        .join("examples/scenarios")
        .join(format!("{name}.toml"))
}

/// `eyebot-hil check SCENARIO --out OUT [EXTRA] -- PROGRAM...`.
fn check(scenario: &Path, out: &Path, extra: &[&str], program: &[&str]) -> Output {
    Command::new(BIN)
        .arg("check")
        .arg(scenario)
        .arg("--out")
        .arg(out)
        .args(extra)
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

const EXAMPLES: [&str; 6] = [
    "dive_hold",
    "heading_hold",
    "spot_turn",
    "sonar_three",
    "wall_follower",
    "timer_square",
];

#[test]
fn shipped_examples_pass_their_scenarios_on_the_host_and_under_qemu() {
    let host = eyebot_c::build(TMP, "check", Target::Host, &[], &[]);
    let m68k = eyebot_c::build(TMP, "check", Target::M68k, &[], &[]);
    let qemu = require_tool("qemu-m68k", "qemu-user");
    let dir = TempDir::new("check-examples");
    for name in EXAMPLES {
        let host_out = dir.join(format!("{name}-host"));
        let o = check(
            &scenario(name),
            &host_out,
            &[],
            &[host.join(name).to_str().expect("utf-8 path")],
        );
        assert!(o.status.success(), "{name} (host):\n{}", text(&o));
        let m68k_out = dir.join(format!("{name}-m68k"));
        let o68 = check(
            &scenario(name),
            &m68k_out,
            &[],
            &[
                qemu.to_str().expect("utf-8 path"),
                m68k.join(name).to_str().expect("utf-8 path"),
            ],
        );
        assert!(o68.status.success(), "{name} (m68k):\n{}", text(&o68));
        let a = Recording::read(&host_out.join("rec")).transcript();
        let b = Recording::read(&m68k_out.join("rec")).transcript();
        assert!(
            a == b,
            "{name}: host and m68k recordings differ at {}",
            first_difference(&a, &b)
        );
        // the verdict lines (not the wall times and directories) are the same
        let verdict = |o: &Output| -> Vec<String> {
            String::from_utf8_lossy(&o.stdout)
                .lines()
                .filter(|l| l.starts_with("pass  ") && !l.starts_with("pass  program"))
                .map(str::to_string)
                .collect()
        };
        assert_eq!(verdict(&o), verdict(&o68), "{name}: verdicts differ");
        eprintln!("{name}: pass on host and m68k, {} chunks equal", a.len());
    }
}

#[test]
fn a_broken_dive_hold_fails_naming_the_depth_criterion() {
    let dir = TempDir::new("check-broken");
    let source = std::fs::read_to_string(eyebot_c::c_source_dir().join("examples/dive_hold.c"))
        .expect("read dive_hold.c");
    let wrong = "double error = depth - TARGET_M; /* wrong sign */";
    let broken = source.replace("double error = TARGET_M - depth;", wrong);
    assert!(
        broken.contains(wrong),
        "dive_hold.c changed: the test's edit no longer applies"
    );
    let path = dir.write("dive_broken.c", broken);
    let built = eyebot_c::build(TMP, "check-broken", Target::Host, &[&path], &[]);
    let junit = dir.join("junit.xml");
    let o = check(
        &scenario("dive_hold"),
        &dir.join("out"),
        &["--junit", junit.to_str().expect("utf-8 path")],
        &[built.join("dive_broken").to_str().expect("utf-8 path")],
    );
    let said = text(&o);
    eprintln!("{said}");
    assert_eq!(o.status.code(), Some(1), "{said}");
    assert!(
        said.contains("FAIL  depth_band 0.8..0.9 m after 40 s: at t "),
        "{said}"
    );
    assert!(said.contains("check failed: 1 of 4 criteria"), "{said}");
    let xml = std::fs::read_to_string(&junit).expect("junit file");
    assert!(
        xml.contains("<testsuite name=\"dive_hold\" tests=\"4\"") && xml.contains("failures=\"1\""),
        "{xml}"
    );
    let case = xml
        .split("<testcase ")
        .find(|c| c.contains("name=\"depth_band 0.8..0.9 m after 40 s\""))
        .unwrap_or_else(|| panic!("no depth_band case: {xml}"));
    assert!(case.contains("<failure message=\"at t "), "{xml}");
}

#[test]
fn a_program_that_never_calls_the_bridge_fails_within_the_wall_limit() {
    let dir = TempDir::new("check-silent");
    let scenario = dir.write(
        "silent.toml",
        "duration_s = 60\nwall_limit_s = 2.0\n\n[[criterion]]\nkind = \"no_contact\"\n",
    );
    let started = Instant::now();
    let o = check(&scenario, &dir.join("out"), &[], &["sleep", "100"]);
    let took = started.elapsed();
    let said = text(&o);
    eprintln!("{said}");
    assert_eq!(o.status.code(), Some(1), "{said}");
    assert!(
        said.contains(
            "FAIL  program: did not reach 60 s of simulated time within 2 s of wall time (it \
             reached 0.00 s"
        ),
        "{said}"
    );
    assert!(took < Duration::from_secs(20), "check took {took:?}");
}

#[test]
fn a_bad_scenario_is_refused_naming_the_file() {
    let dir = TempDir::new("check-bad");
    let scenario = dir.write(
        "bad.toml",
        "duration_s = 5\n[[criterion]]\nkind = \"depth_bnad\"\n",
    );
    let o = check(&scenario, &dir.join("out"), &[], &["true"]);
    let said = text(&o);
    assert!(!o.status.success(), "{said}");
    assert!(
        said.contains("bad.toml: not a scenario") && said.contains("depth_bnad"),
        "{said}"
    );
}

//! Peak memory of `eyebot-hil replay` on hostile logs, against a plain log in the same run.
//!
//! `cargo bench --bench replay_memory` writes each input into a temporary directory (removed
//! afterwards), runs `eyebot-hil replay --dry-run --stats INPUT` as a child process and reads
//! its peak RSS from `wait4`'s `ru_maxrss`. `/dev/zero` never ends, so that run is stopped
//! with SIGTERM after 3 s (which also shows that a read of a device gives way to a signal).
//! The target is a peak below 64 MiB for every input; the process exits 1 if one is above.

use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

const BIN: &str = env!("CARGO_BIN_EXE_eyebot-hil");
const LIMIT_KIB: i64 = 64 * 1024;

/// Runs `replay --dry-run --stats input`; returns (peak RSS KiB, exit code or signal, seconds).
fn run(input: &Path, stop_after: Option<Duration>) -> (i64, String, f64) {
    let started = Instant::now();
    // Reaped by `wait4` below, which also gives the peak RSS; `Child::wait` cannot.
    #[allow(clippy::zombie_processes)]
    let child = Command::new(BIN)
        .args(["replay", "--dry-run", "--stats"])
        .arg(input)
        .stdin(Stdio::null())
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .expect("spawn eyebot-hil replay");
    let pid = child.id() as libc::pid_t;
    if let Some(after) = stop_after {
        std::thread::sleep(after);
        // SAFETY: signalling our own child by its pid.
        unsafe {
            libc::kill(pid, libc::SIGTERM);
        }
    }
    let mut status = 0;
    // SAFETY: an all-zero rusage is a valid value for wait4 to fill.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    // SAFETY: waits for our own child; the pointers are to live locals.
    let got = unsafe { libc::wait4(pid, &mut status, 0, &mut usage) };
    assert_eq!(got, pid, "wait4");
    let how = if libc::WIFEXITED(status) {
        format!("exit {}", libc::WEXITSTATUS(status))
    } else {
        format!("signal {}", libc::WTERMSIG(status))
    };
    (usage.ru_maxrss, how, started.elapsed().as_secs_f64())
}

fn write_lines(path: &Path, count: u64, line: impl Fn(u64) -> String, gzip: bool) {
    let file = std::io::BufWriter::with_capacity(1 << 20, std::fs::File::create(path).unwrap());
    let mut out: Box<dyn Write> = if gzip {
        Box::new(flate2::write::GzEncoder::new(
            file,
            flate2::Compression::best(),
        ))
    } else {
        Box::new(file)
    };
    for i in 0..count {
        out.write_all(line(i).as_bytes()).unwrap();
    }
    out.flush().unwrap();
}

fn main() {
    let tmp = tempfile::Builder::new()
        .prefix("eyebot-hil-bench-replay-memory-")
        .tempdir()
        .expect("temporary directory");
    let at = |name: &str| tmp.path().join(name);
    let mut inputs: Vec<(&str, PathBuf, Option<Duration>)> = Vec::new();

    let plain = at("plain.log");
    write_lines(
        &plain,
        1_000_000,
        |i| format!("{}.000 $SDDPT,1.{},0.3*00\r\n", i, i % 10),
        false,
    );
    inputs.push(("baseline: 1 Mi timestamped sentences", plain, None));

    let blank = at("blank.log");
    write_lines(&blank, 16 << 20, |_| "\n".into(), false);
    inputs.push(("16 Mi blank lines", blank, None));

    let gz = at("blank.gz");
    {
        // 1 GiB of line feeds in 1 MiB blocks (about 1 MB compressed).
        let file = std::fs::File::create(&gz).unwrap();
        let mut enc = flate2::write::GzEncoder::new(file, flate2::Compression::best());
        let block = vec![b'\n'; 1 << 20];
        for _ in 0..1024 {
            enc.write_all(&block).unwrap();
        }
        enc.finish().unwrap();
    }
    inputs.push(("gzip bomb: 1 GiB of blank lines", gz, None));

    let comments = at("comments.log");
    write_lines(&comments, 4 << 20, |i| format!("# comment {i}\n"), false);
    inputs.push(("4 Mi comment lines", comments, None));

    let types = at("types.log");
    write_lines(&types, 2_000_000, |i| format!("$X{i:07},1*00\r\n"), false);
    inputs.push(("2 M distinct sentence addresses", types, None));

    let cr = at("cr.log");
    write_lines(&cr, 1_000_000, |i| format!("$SDDPT,{i},0.3*00\r"), false);
    inputs.push(("1 M CR-only lines", cr, None));

    let junk = at("junk.log");
    write_lines(&junk, 64, |_| "\u{1}".repeat(1 << 20), false);
    inputs.push(("64 MiB without a line feed", junk, None));

    inputs.push((
        "/dev/zero, SIGTERM after 3 s",
        PathBuf::from("/dev/zero"),
        Some(Duration::from_secs(3)),
    ));

    let mut worst = 0;
    let mut baseline = 0;
    println!(
        "replay --dry-run --stats: peak RSS (ru_maxrss), limit {} KiB",
        LIMIT_KIB
    );
    for (name, path, stop) in &inputs {
        let size = std::fs::metadata(path).map(|m| m.len()).unwrap_or(0);
        let (kib, how, secs) = run(path, *stop);
        if baseline == 0 {
            baseline = kib;
        }
        worst = worst.max(kib);
        println!(
            "{name:<40} {size:>11} B on disk  peak {kib:>7} KiB ({:.2}x baseline)  {how}  {secs:.1} s",
            kib as f64 / baseline as f64
        );
    }
    println!("worst peak {worst} KiB of {LIMIT_KIB} KiB allowed");
    if worst > LIMIT_KIB {
        std::process::exit(1);
    }
}

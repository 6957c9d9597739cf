//! Replay throughput and memory on generated logs, against a same-run baseline.
//!
//! `cargo bench -p pty-tests --bench replay` generates timestamped NMEA logs of 10 MB and 100 MB in a
//! temporary directory (deleted afterwards), and for each:
//! - baseline: reads the file line by line (`BufRead::read_until`) into a sink;
//! - replay: `eyebot-hil replay --pacing fast` of the same file into a sink writer, with
//!   every line checked (policy `fix`).
//!
//! It prints MB/s and sentences/s for both, the ratio, and the peak RSS of each replay
//! (`VmHWM` from `/proc/self/status`, reset between runs through `/proc/self/clear_refs`).
//! Replay streams, so its peak RSS must not grow with the log's size.

use std::fs::File;
use std::io::{self, BufRead, BufReader, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::time::Instant;

use eyebot_hil::replay::{ByteSink, Options, Pacing, Policy, Port, Quiet, Replay, Shutdown};
use eyebot_hil::transport::LineSettings;
use firmware_protocol::nmea::checksum;

/// Writes a log of about `target_bytes`: seconds timestamps, DBT/DPT/echo sentences at 10 Hz,
/// one bad checksum every 1000 lines. Returns the number of lines.
fn generate(path: &Path, target_bytes: u64) -> io::Result<u64> {
    let mut out = BufWriter::with_capacity(1 << 20, File::create(path)?);
    let mut written = 0u64;
    let mut lines = 0u64;
    let mut body = String::new();
    let mut line = String::new();
    while written < target_bytes {
        let depth_m = 1.0 + (lines % 300) as f64 * 0.1;
        body.clear();
        match lines % 3 {
            0 => {
                use std::fmt::Write as _;
                let _ = write!(
                    body,
                    "SDDBT,{:.1},f,{depth_m:.1},M,{:.1},F",
                    depth_m / 0.3048,
                    depth_m / 1.8288
                );
            }
            1 => {
                use std::fmt::Write as _;
                let _ = write!(body, "SDDPT,{depth_m:.1},0.3");
            }
            _ => {
                use std::fmt::Write as _;
                let _ = write!(body, "PEBHS,{},{depth_m:.1},{}", 1 + lines % 4, lines % 100);
            }
        }
        let mut sum = checksum(body.as_bytes());
        if lines % 1000 == 999 {
            sum ^= 0x5A;
        }
        line.clear();
        {
            use std::fmt::Write as _;
            let _ = write!(line, "{:.3} ${body}*{sum:02X}\r\n", lines as f64 * 0.1);
        }
        out.write_all(line.as_bytes())?;
        written += line.len() as u64;
        lines += 1;
    }
    out.flush()?;
    Ok(lines)
}

fn vm_hwm_kib() -> u64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1))
                .and_then(|v| v.parse().ok())
        })
        .unwrap_or(0)
}

/// Resets the peak-RSS counter (Linux: writing 5 to clear_refs). Returns whether it worked.
fn reset_hwm() -> bool {
    std::fs::write("/proc/self/clear_refs", "5").is_ok()
}

fn baseline(path: &Path) -> io::Result<(f64, u64)> {
    let start = Instant::now();
    let mut reader = BufReader::with_capacity(64 * 1024, File::open(path)?);
    let mut buf = Vec::new();
    let mut sink = io::sink();
    let mut lines = 0u64;
    loop {
        buf.clear();
        if reader.read_until(b'\n', &mut buf)? == 0 {
            break;
        }
        sink.write_all(&buf)?;
        lines += 1;
    }
    Ok((start.elapsed().as_secs_f64(), lines))
}

fn run_case(dir: &Path, mb: u64) -> Result<(), Box<dyn std::error::Error>> {
    let path: PathBuf = dir.join(format!("log-{mb}mb.nmea"));
    let lines = generate(&path, mb * 1_000_000)?;
    let size = std::fs::metadata(&path)?.len();
    let mb_size = size as f64 / 1e6;

    let (base_s, base_lines) = baseline(&path)?;
    assert_eq!(base_lines, lines);

    let hwm_reset = reset_hwm();
    let hwm_before = vm_hwm_kib();
    let mut opts = Options::new(vec![path.clone()]);
    opts.pacing = Some(Pacing::Fast);
    opts.policy = Policy::Fix;
    let replay = Replay::open(opts)?;
    let mut sink = ByteSink::new(Port::Writer(Box::new(io::sink())), &LineSettings::n81(4800));
    let start = Instant::now();
    let summary = replay.run(&mut sink, &mut Quiet, &Shutdown::new())?;
    let replay_s = start.elapsed().as_secs_f64();
    let hwm = vm_hwm_kib();
    assert_eq!(summary.sentences_sent, lines);
    assert_eq!(summary.lines_fixed, lines / 1000);

    println!(
        "{mb:>4} MB log ({mb_size:.1} MB, {lines} lines): baseline read {:.1} MB/s {:.0} lines/s | replay {:.1} MB/s {:.0} sentences/s | replay/baseline {:.3} | peak RSS {} KiB (before run {} KiB{})",
        mb_size / base_s,
        lines as f64 / base_s,
        mb_size / replay_s,
        lines as f64 / replay_s,
        base_s / replay_s,
        hwm,
        hwm_before,
        if hwm_reset {
            ", reset"
        } else {
            ", could not reset"
        }
    );
    std::fs::remove_file(&path)?;
    Ok(())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    // `cargo bench` passes `--bench`; `cargo test --benches` runs this as a smoke test with
    // only the 1 MB case.
    let smoke = !std::env::args().any(|a| a == "--bench");
    let dir = eyebot_test_support::TempDir::new("replay-bench");
    let sizes: &[u64] = if smoke { &[1] } else { &[10, 100] };
    sizes.iter().try_for_each(|&mb| run_case(dir.path(), mb))
}

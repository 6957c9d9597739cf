//! The daemon's sonar `replay = "FILE"` streams its log: a log of a million sentences costs
//! no more memory than one of ten.

use std::io::Write;

use eyebot_test_support::Daemon;

const BIN: &str = env!("CARGO_BIN_EXE_eyebot-hil");

/// `sentences` timestamped DBT sentences, each with a different depth (no two lines alike).
fn write_log(path: &std::path::Path, sentences: u64) {
    let mut out = std::io::BufWriter::new(std::fs::File::create(path).expect("create the log"));
    for i in 0..sentences {
        let tenths = i % 400 + 3;
        let body = format!("SDDBT,,f,{}.{},M,,F", tenths / 10, tenths % 10);
        let sum = body.bytes().fold(0u8, |a, b| a ^ b);
        writeln!(
            out,
            "{}.{:03} ${body}*{sum:02X}",
            1000 + i / 10,
            (i % 10) * 100
        )
        .expect("write the log");
    }
    out.flush().expect("flush the log");
}

/// Resident memory of a daemon started with a sonar replay log of `sentences` sentences.
fn rss_with_log(tag: &str, sentences: u64) -> u64 {
    let options = Daemon::options(BIN, tag);
    let log = options.dir().join("sonar.nmea");
    write_log(&log, sentences);
    let replay = format!(
        "replay = \"{}\"\n\n[devices.compass]",
        log.display().to_string().replace('\\', "\\\\")
    );
    let daemon = options
        .config(&[("[devices.compass]", replay.as_str())])
        .lockstep()
        .start();
    // Ready means the log is open and its first sentence read.
    daemon.rss_kb()
}

#[test]
fn a_long_sonar_replay_log_is_streamed_not_loaded() {
    let small = rss_with_log("feed-small", 10);
    let large = rss_with_log("feed-large", 1_000_000);
    eprintln!("daemon RSS: 10 sentences {small} KiB, 1 M sentences {large} KiB");
    // Loaded whole, a million sentences (about 30 MB of text) cost well over 60 MB; streamed,
    // the two runs differ by noise.
    assert!(
        large < small + 16 * 1024,
        "RSS with a 1 M-sentence log {large} KiB against {small} KiB with 10 sentences"
    );
}

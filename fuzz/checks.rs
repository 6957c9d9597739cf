//! The properties the fuzz targets check, as plain functions: `fuzz_targets/*.rs` call them
//! under libFuzzer, and `tests/fuzz_corpora.rs` calls them on every committed corpus file,
//! so CI replays the corpora as ordinary tests.

use std::path::Path;

use eyebot_hil::config::Document;
use eyebot_hil::daemon::config::DaemonConfig;
use eyebot_hil::physics::{VehicleConfig, WorldConfig};
use eyebot_hil::replay::input::{CommentMode, Event, Format, LineKind, MAX_PHYSICAL_LINE, Source};
use eyebot_hil::replay::sentence_check::{Policy, check_line};
use eyebot_hil::sensors::SensorsConfig;

/// The replay input reader on `data` (plain or gzip): no panic, no error after the input
/// opened, every line within the input cap and checkable, and for text logs every physical
/// line in exactly one counter or event.
pub fn replay_input(data: &[u8]) {
    let comments = match data.first().map(|b| b % 3) {
        Some(0) => CommentMode::Report,
        Some(1) => CommentMode::Send,
        _ => CommentMode::Ignore,
    };
    let name = Path::new("fuzz.log");
    // A tie in timestamp forms is an error at open, naming the file.
    let mut source = match Source::from_reader(
        name,
        Box::new(std::io::Cursor::new(data.to_vec())),
        "sonar",
        comments,
    ) {
        Ok(s) => s,
        Err(e) => {
            assert!(e.to_string().contains("fuzz.log"), "{e}");
            return;
        }
    };
    let mut data_lines = 0u64;
    let mut problems_dropped = 0u64;
    while let Some(event) = source.next_event().expect("no error once open") {
        match event {
            Event::Line(line) => {
                assert!(line.bytes.len() <= MAX_PHYSICAL_LINE);
                if line.kind == LineKind::Data {
                    data_lines += 1;
                    for policy in [Policy::Pass, Policy::Drop, Policy::Fix] {
                        let checked =
                            check_line(&line.bytes, line.terminator, line.overflow, policy);
                        if let Some(out) = checked.out {
                            assert!(out.ends_with(b"\r\n"));
                        }
                    }
                }
            }
            Event::Problem(p) => {
                assert!(p.to_string().starts_with("fuzz.log:"), "{p}");
                if p.action == eyebot_hil::replay::Action::Dropped {
                    problems_dropped += 1;
                }
            }
            Event::Comment { .. } | Event::Serial { .. } => {}
        }
    }
    assert_eq!(problems_dropped, source.unplaceable_lines);
    if matches!(source.format(), Format::Nmea { .. }) && !source.cut_short {
        assert_eq!(
            source.physical_lines(),
            data_lines
                + source.unplaceable_lines
                + source.comment_lines
                + source.serial_lines
                + source.blank_lines,
            "every line in exactly one counter"
        );
    }
}

/// The configuration loaders on `data` as TOML: no panic; an error names the document.
pub fn config_load(data: &[u8]) {
    let text = String::from_utf8_lossy(data);
    let doc = Document::new("fuzz.toml", &text);
    let named = |e: &dyn std::fmt::Display| {
        let msg = e.to_string();
        assert!(msg.contains("fuzz.toml"), "{msg}");
    };
    if let Err(e) = DaemonConfig::resolve(&doc) {
        named(&e);
    }
    if let Err(e) = VehicleConfig::from_document(&doc) {
        named(&e);
    }
    if let Err(e) = WorldConfig::from_document(&doc) {
        named(&e);
    }
    if let Err(e) = SensorsConfig::from_text("fuzz.toml", &text) {
        named(&e);
    }
}

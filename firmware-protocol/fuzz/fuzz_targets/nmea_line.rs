//! NMEA line parser: no panic; a decoded sentence re-encodes and parses to the same value.
//! The property is `checks::nmea_line` (shared with the corpus replay in `../tests/fuzz_corpora.rs`).
#![no_main]
use libfuzzer_sys::fuzz_target;

#[path = "../checks.rs"]
#[allow(dead_code)]
mod checks;

fuzz_target!(|data: &[u8]| checks::nmea_line(data));

//! NMEA field decoder behind the checksum: mutated lines almost never keep a valid checksum in
//! The property is `checks::nmea_fields` (shared with the corpus replay in `../tests/fuzz_corpora.rs`).
#![no_main]
use libfuzzer_sys::fuzz_target;

#[path = "../checks.rs"]
#[allow(dead_code)]
mod checks;

fuzz_target!(|data: &[u8]| checks::nmea_fields(data));

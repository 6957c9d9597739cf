//! Sensor-link message decoder behind the CRC: mutated payloads almost never pass the CRC in
//! The property is `checks::sensor_message` (shared with the corpus replay in `../tests/fuzz_corpora.rs`).
#![no_main]
use libfuzzer_sys::fuzz_target;

#[path = "../checks.rs"]
#[allow(dead_code)]
mod checks;

fuzz_target!(|data: &[u8]| checks::sensor_message(data));

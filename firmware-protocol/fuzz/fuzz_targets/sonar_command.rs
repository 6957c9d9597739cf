//! Sonar select/ack parser: no panic; a decoded command re-encodes byte for byte.
//! The property is `checks::sonar_command` (shared with the corpus replay in `../tests/fuzz_corpora.rs`).
#![no_main]
use libfuzzer_sys::fuzz_target;

#[path = "../checks.rs"]
#[allow(dead_code)]
mod checks;

fuzz_target!(|data: &[u8]| checks::sonar_command(data));

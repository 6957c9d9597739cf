//! Binary frame parser + message decoder: no panic; a decoded frame re-encodes byte for byte.
//! The property is `checks::sensor_frame` (shared with the corpus replay in `../tests/fuzz_corpora.rs`).
#![no_main]
use libfuzzer_sys::fuzz_target;

#[path = "../checks.rs"]
#[allow(dead_code)]
mod checks;

fuzz_target!(|data: &[u8]| checks::sensor_frame(data));

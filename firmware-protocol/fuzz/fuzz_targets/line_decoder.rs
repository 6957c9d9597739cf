//! Shared-line stream decoder: no panic on any input, the same items whatever the chunking,
//! The property is `checks::line_decoder` (shared with the corpus replay in `../tests/fuzz_corpora.rs`).
#![no_main]
use libfuzzer_sys::fuzz_target;

#[path = "../checks.rs"]
#[allow(dead_code)]
mod checks;

fuzz_target!(|data: &[u8]| checks::line_decoder(data));

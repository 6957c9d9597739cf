//! Vector 2X heading word decoder: no panic; an accepted word re-encodes to itself.
//! The property is `checks::compass_word` (shared with the corpus replay in `../tests/fuzz_corpora.rs`).
#![no_main]
use libfuzzer_sys::fuzz_target;

#[path = "../checks.rs"]
#[allow(dead_code)]
mod checks;

fuzz_target!(|data: &[u8]| checks::compass_word(data));

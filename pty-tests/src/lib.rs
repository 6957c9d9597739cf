//! Fixtures for end-to-end tests: pseudo-terminals, a daemon under test, and clean-up in `Drop`.

pub mod eyebot_c;

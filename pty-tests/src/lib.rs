//! Fixtures for end-to-end tests: pseudo-terminals, a daemon under test, and clean-up in `Drop`.
//!
//! - [`daemon`]: the bridge as the built binary or in-process, with a private run directory,
//!   readiness by its `ready` line, recordings and status helpers.

pub mod daemon;

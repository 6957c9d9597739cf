//! Fixtures for end-to-end tests: pseudo-terminals, a daemon under test, and clean-up in `Drop`.
//!
//! - [`process`]: unique names, temporary directories, child processes killed in `Drop`,
//!   readiness by polling with a timeout, and a loud failure when a system tool is missing.
//! - [`pty`]: ptys made with the bridge's own `PtyMaster`, and a consumer that timestamps
//!   every read on the slave side.
//! - [`replay`]: what the replay pty tests share.
//! - [`daemon`]: the bridge as the built binary or in-process, with a private run directory,
//!   readiness by its `ready` line, recordings and status helpers.
//! - [`eyebot_c`]: builds the EyeBot C library and examples (host and 68k) and runs them
//!   against the daemon.

pub mod daemon;
pub mod eyebot_c;
pub mod process;
pub mod pty;
pub mod replay;

/// The directory of fixture files, e.g. `fixtures/replay`.
pub fn fixture_dir(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures")
        .join(name)
}

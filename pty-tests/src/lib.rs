//! The end-to-end tests over pseudo-terminals. The harness itself (temporary directories,
//! the daemon under test, ptys, recordings, system tools) is the workspace's test-support
//! crate, `eyebot-test-support` (`tests/support/`); this crate adds what its replay tests
//! share ([`replay`]), a bare byte-level link client over the protocol crate's client core
//! ([`wire`]) and the path of its fixture files.

pub mod replay;
pub mod wire;

/// The directory of fixture files, e.g. `fixtures/replay`.
pub fn fixture_dir(name: &str) -> std::path::PathBuf {
    std::path::Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fixtures")
        .join(name)
}

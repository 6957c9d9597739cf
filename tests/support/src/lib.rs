//! The test harness of the workspace, shared by the root package's integration tests and the
//! end-to-end tests of `pty-tests`.
//!
//! - [`dir`]: [`TempDir`], the one temporary directory every test uses, removed on drop.
//! - [`tools`]: [`require_tool`], the one policy for a missing system tool: a loud failure
//!   naming the tool and its Debian package, never a quiet pass.
//! - [`wait`]: readiness by polling with a timeout, never a fixed sleep.
//! - [`process`]: child processes killed and reaped in `Drop`, free ports, `/proc` figures.
//! - [`config`]: daemon configurations written for a test.
//! - [`daemon`]: the daemon under test, as the built binary ([`Daemon`], given the path from
//!   `CARGO_BIN_EXE_eyebot-hil`) or in-process ([`InProcessDaemon`]).
//! - [`clients`]: EyeBot-side clients of a running daemon's links.
//! - [`browser`]: headless chromium over the DevTools protocol, and a plain HTTP client,
//!   for the live view.
//! - [`foxglove`]: a Foxglove WebSocket client for `run --foxglove`.
//! - [`recording`]: a `--record` directory read back.
//! - [`pty`]: ptys made with the bridge's own `PtyMaster`, and a timestamping reader.
//! - [`eyebot_c`]: the EyeBot C library and programs built with make and run against a daemon.

pub mod browser;
pub mod clients;
pub mod config;
pub mod daemon;
pub mod dir;
pub mod eyebot_c;
pub mod foxglove;
pub mod process;
pub mod pty;
pub mod recording;
pub mod tools;
pub mod wait;

pub use daemon::{Daemon, InProcessDaemon, RunningDaemon};
pub use dir::TempDir;
pub use recording::Recording;
pub use tools::require_tool;
pub use wait::wait_for;

use std::path::{Path, PathBuf};

/// The workspace root.
pub fn workspace_root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .canonicalize()
        .expect("the workspace root exists")
}

//! `--pid-file`: the daemon's process id in a file for the life of the run.

use std::path::{Path, PathBuf};

use super::DaemonError;

/// `--pid-file`: written at start, removed at exit.
#[derive(Debug)]
pub struct PidFile(PathBuf);

impl PidFile {
    /// Writes the process id to `path`: never through a symlink, never into a FIFO or
    /// anything but a regular file.
    pub fn create(path: &Path) -> Result<Self, DaemonError> {
        super::run_dir::write_file(path, &format!("{}\n", std::process::id()), 0o644).map_err(
            |source| DaemonError::PidFile {
                path: path.to_path_buf(),
                source,
            },
        )?;
        Ok(Self(path.to_path_buf()))
    }
}

impl Drop for PidFile {
    /// Removes the file if it still holds our process id (another daemon may have written
    /// its own since).
    fn drop(&mut self) {
        if super::run_dir::read_pid(&self.0) == Some(std::process::id()) {
            let _ = std::fs::remove_file(&self.0);
        }
    }
}

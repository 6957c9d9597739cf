//! `--pid-file`: the daemon's process id in a file for the life of the run.

use std::path::{Path, PathBuf};

use super::DaemonError;

/// `--pid-file`: written at start, removed at exit.
#[derive(Debug)]
pub struct PidFile(PathBuf);

impl PidFile {
    /// Writes the process id to `path`.
    pub fn create(path: &Path) -> Result<Self, DaemonError> {
        std::fs::write(path, format!("{}\n", std::process::id())).map_err(|source| {
            DaemonError::PidFile {
                path: path.to_path_buf(),
                source,
            }
        })?;
        Ok(Self(path.to_path_buf()))
    }
}

impl Drop for PidFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

//! The one temporary directory of the harness.

use std::path::{Path, PathBuf};

/// Every directory the harness creates in the system's temporary directory starts with this,
/// followed by the test process's id: `eyebot-hil-test-PID-TAG-RANDOM`.
pub const PREFIX: &str = "eyebot-hil-test-";

/// The name prefix of this process's temporary directories.
pub fn process_prefix() -> String {
    format!("{PREFIX}{}-", std::process::id())
}

/// A private directory in the system's temporary directory, removed with its contents on
/// drop. With `EYEBOT_HIL_KEEP` set it is kept (and its path printed), to look at a failed
/// run.
#[derive(Debug)]
pub struct TempDir {
    dir: Option<tempfile::TempDir>,
    path: PathBuf,
}

impl TempDir {
    /// A fresh directory whose name includes `tag` (which test made it).
    pub fn new(tag: &str) -> Self {
        let dir = tempfile::Builder::new()
            .prefix(&format!("{}{tag}-", process_prefix()))
            .tempdir()
            .unwrap_or_else(|e| panic!("cannot create a temporary directory for {tag}: {e}"));
        let path = dir.path().to_path_buf();
        Self {
            dir: Some(dir),
            path,
        }
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn join(&self, name: impl AsRef<Path>) -> PathBuf {
        self.path.join(name)
    }

    /// Writes `text` to the file `name` in this directory and returns its path.
    pub fn write(&self, name: &str, text: impl AsRef<[u8]>) -> PathBuf {
        let path = self.join(name);
        std::fs::write(&path, text).unwrap_or_else(|e| panic!("write {}: {e}", path.display()));
        path
    }

    /// Writes a daemon configuration (see [`crate::config::config_text`]) and returns its
    /// path.
    pub fn write_config(&self, name: &str, edits: &[(&str, &str)]) -> PathBuf {
        self.write(name, crate::config::config_text(edits))
    }
}

impl Drop for TempDir {
    fn drop(&mut self) {
        if let Some(dir) = self.dir.take()
            && std::env::var_os("EYEBOT_HIL_KEEP").is_some()
        {
            eprintln!("kept {}", dir.keep().display());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_temp_dir_is_named_for_this_process_and_removed_on_drop() {
        let dir = TempDir::new("unit");
        let name = dir
            .path()
            .file_name()
            .expect("a name")
            .to_string_lossy()
            .into_owned();
        assert!(
            name.starts_with(&format!("{}unit-", process_prefix())),
            "{name}"
        );
        dir.write("file", "text");
        let path = dir.path().to_path_buf();
        drop(dir);
        assert!(!path.exists(), "{} left behind", path.display());
    }
}

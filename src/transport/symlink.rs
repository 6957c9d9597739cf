//! Stable names for pseudo-terminals: `run/sonar -> /dev/pts/7`.
//!
//! A pty's device number changes every run, so each link gets a symlink at a fixed path. The
//! bridge never replaces anything it did not create: beside each link it writes an owner
//! file (`.sonar.owner`, holding the daemon's PID), and an existing symlink is replaced only
//! when its owner file names a process that no longer runs. Anything else at that path (a
//! regular file, a directory, someone else's symlink, a live daemon's link) is an error that
//! names the path and what holds it.

use std::fs::{self, File};
use std::io::{self, Read};
use std::os::unix::fs::OpenOptionsExt;
use std::path::{Path, PathBuf};

/// Why a link could not be created.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    #[error("link path {path}: {what} is there and is not ours; remove it or choose another path")]
    Occupied { path: PathBuf, what: &'static str },
    #[error("link path {path}: in use by running eyebot-hil process {pid}")]
    InUse { path: PathBuf, pid: u32 },
    #[error("link path {path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: io::Error,
    },
}

/// A symlink this process created; removed on drop if it still points where we set it.
#[derive(Debug)]
pub struct OwnedLink {
    path: PathBuf,
    target: PathBuf,
}

fn owner_file_for(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.owner"))
}

fn process_alive(pid: u32) -> bool {
    let Ok(pid) = i32::try_from(pid) else {
        return false;
    };
    // Signal 0 checks existence; EPERM means it exists but belongs to someone else.
    match nix::sys::signal::kill(nix::unistd::Pid::from_raw(pid), None) {
        Ok(()) => true,
        Err(e) => e == nix::errno::Errno::EPERM,
    }
}

impl OwnedLink {
    /// Points `path` at `target`, creating parent directories, replacing only our own stale
    /// link.
    pub fn create(path: &Path, target: &Path) -> Result<Self, LinkError> {
        let io_err = |source| LinkError::Io {
            path: path.to_path_buf(),
            source,
        };
        if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
            fs::create_dir_all(parent).map_err(io_err)?;
        }
        let owner_file = owner_file_for(path);
        match fs::symlink_metadata(path) {
            Err(e) if e.kind() == io::ErrorKind::NotFound => {}
            Err(e) => return Err(io_err(e)),
            Ok(meta) if !meta.file_type().is_symlink() => {
                return Err(LinkError::Occupied {
                    path: path.to_path_buf(),
                    what: if meta.is_dir() {
                        "a directory"
                    } else {
                        "a file"
                    },
                });
            }
            Ok(_) => {
                let owner = read_pid(&owner_file);
                match owner {
                    None => {
                        return Err(LinkError::Occupied {
                            path: path.to_path_buf(),
                            what: "a symlink without an eyebot-hil owner file",
                        });
                    }
                    Some(pid) if pid != std::process::id() && process_alive(pid) => {
                        return Err(LinkError::InUse {
                            path: path.to_path_buf(),
                            pid,
                        });
                    }
                    Some(pid) => {
                        tracing::info!(path = %path.display(), stale_owner = pid, "replacing stale link");
                    }
                }
            }
        }
        // Write the owner file first, then swap the link in atomically with a rename.
        write_file(&owner_file, &format!("{}\n", std::process::id()), 0o600).map_err(|source| {
            LinkError::Io {
                path: owner_file.clone(),
                source,
            }
        })?;
        let tmp = path.with_file_name(format!(
            ".{}.tmp{}",
            path.file_name()
                .map(|n| n.to_string_lossy())
                .unwrap_or_default(),
            std::process::id()
        ));
        let _ = fs::remove_file(&tmp);
        std::os::unix::fs::symlink(target, &tmp).map_err(io_err)?;
        fs::rename(&tmp, path).map_err(io_err)?;
        Ok(Self {
            path: path.to_path_buf(),
            target: target.to_path_buf(),
        })
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    pub fn target(&self) -> &Path {
        &self.target
    }
}

impl Drop for OwnedLink {
    fn drop(&mut self) {
        remove_if_ours(&self.path, &self.target);
    }
}

/// Removes the symlink at `path` if it still points at `target`, and its owner file if it
/// still names this process: another daemon may have taken the path over.
pub fn remove_if_ours(path: &Path, target: &Path) {
    if fs::read_link(path).is_ok_and(|t| t == target) {
        let _ = fs::remove_file(path);
    }
    let owner_file = owner_file_for(path);
    let ours = read_pid(&owner_file) == Some(std::process::id());
    if ours {
        let _ = fs::remove_file(&owner_file);
    }
}

/// An error for something the daemon refuses to touch.
pub fn refuse(message: String) -> io::Error {
    io::Error::new(io::ErrorKind::PermissionDenied, message)
}

/// The options for opening a daemon file (owner, pid) for writing: created with `mode`,
/// truncated, never through a symlink, never blocking on a FIFO.
fn write_options(mode: u32) -> std::fs::OpenOptions {
    let mut o = std::fs::OpenOptions::new();
    o.write(true)
        .create(true)
        .truncate(true)
        .mode(mode)
        .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK | libc::O_NOCTTY);
    o
}

/// Opens `path` with `options`, refusing anything but a regular file.
pub fn open_nofollow(path: &Path, options: &std::fs::OpenOptions) -> io::Result<File> {
    let file = options.open(path).map_err(|e| match e.raw_os_error() {
        Some(libc::ELOOP) => refuse("is a symlink; the daemon does not follow it".into()),
        Some(libc::ENXIO) => refuse("is a FIFO; expected a regular file".into()),
        _ => e,
    })?;
    if !file.metadata()?.is_file() {
        return Err(refuse("is not a regular file".into()));
    }
    Ok(file)
}

/// Writes `text` to `path` (mode `mode`) through [`open_nofollow`].
pub fn write_file(path: &Path, text: &str, mode: u32) -> io::Result<()> {
    use std::io::Write;
    let mut file = open_nofollow(path, &write_options(mode))?;
    file.write_all(text.as_bytes())
}

/// Reads at most `limit` bytes of `path`, if it is a regular file reached without a
/// symlink; `None` for anything else.
pub fn read_small(path: &Path, limit: u64) -> Option<String> {
    let mut options = std::fs::OpenOptions::new();
    options
        .read(true)
        .custom_flags(libc::O_NOFOLLOW | libc::O_NONBLOCK | libc::O_NOCTTY);
    let file = open_nofollow(path, &options).ok()?;
    let mut text = String::new();
    file.take(limit).read_to_string(&mut text).ok()?;
    Some(text)
}

/// The process id a daemon file (owner, pid) holds, read as [`read_small`] does.
pub fn read_pid(path: &Path) -> Option<u32> {
    read_small(path, 32)?.trim().parse().ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn creates_and_removes_its_link() {
        let tmp = crate::scratch::dir("create");
        let dir = tmp.path();
        let link = dir.join("run/sonar");
        {
            let owned = OwnedLink::create(&link, Path::new("/dev/null")).unwrap();
            assert_eq!(fs::read_link(owned.path()).unwrap(), Path::new("/dev/null"));
        }
        assert!(fs::symlink_metadata(&link).is_err(), "link removed on drop");
        assert!(!owner_file_for(&link).exists());
    }

    #[test]
    fn never_replaces_a_file_or_a_foreign_symlink() {
        let tmp = crate::scratch::dir("foreign");
        let dir = tmp.path();
        let file = dir.join("sonar");
        fs::write(&file, "user data").unwrap();
        assert!(matches!(
            OwnedLink::create(&file, Path::new("/dev/null")),
            Err(LinkError::Occupied { .. })
        ));
        assert_eq!(fs::read_to_string(&file).unwrap(), "user data");

        let foreign = dir.join("sensor");
        std::os::unix::fs::symlink("/etc/hostname", &foreign).unwrap();
        assert!(matches!(
            OwnedLink::create(&foreign, Path::new("/dev/null")),
            Err(LinkError::Occupied { .. })
        ));
        assert_eq!(fs::read_link(&foreign).unwrap(), Path::new("/etc/hostname"));
    }

    #[test]
    fn replaces_a_stale_link_of_a_dead_daemon_but_not_a_live_one() {
        let tmp = crate::scratch::dir("stale");
        let dir = tmp.path();
        let link = dir.join("sonar");
        std::os::unix::fs::symlink("/dev/pts/999", &link).unwrap();
        // PID 1 is alive (init); a link it owns is in use.
        fs::write(owner_file_for(&link), "1\n").unwrap();
        assert!(matches!(
            OwnedLink::create(&link, Path::new("/dev/null")),
            Err(LinkError::InUse { pid: 1, .. })
        ));
        // A PID above pid_max never runs: that owner is dead, so the link is stale.
        fs::write(owner_file_for(&link), "4194305\n").unwrap();
        let owned = OwnedLink::create(&link, Path::new("/dev/null")).unwrap();
        assert_eq!(fs::read_link(&link).unwrap(), Path::new("/dev/null"));
        drop(owned);
    }
}

//! The run directory is ours or refused.
//!
//! The daemon writes owner files, a pid file, sockets and symlinks into its run directory and
//! removes them at exit, often as root. So before it touches anything there:
//!
//! - a missing run directory is created with mode 0700 (its parents as the umask gives);
//! - an existing one must be a real directory (not a symlink: it is opened with
//!   `O_NOFOLLOW`), owned by this user, and neither group- nor world-writable;
//! - the daemon takes an exclusive `flock` on it and holds it until it has removed what it
//!   made, so of two daemons started together on one directory exactly one runs; the other
//!   stops before its first clean-up, changing nothing.
//!
//! Files inside are opened with [`open_nofollow`]: never through a symlink, never blocking on
//! a FIFO, and only when they are regular files (the helpers live beside the owner files they
//! were made for, in [`crate::transport::symlink`]).

use std::fs::File;
use std::io;
use std::os::unix::fs::{DirBuilderExt, MetadataExt, OpenOptionsExt};
use std::path::{Path, PathBuf};

use nix::fcntl::{Flock, FlockArg};

pub use crate::transport::symlink::{open_nofollow, read_pid, read_small, write_file};

/// The exclusive lock on a run directory, held for the life of the daemon.
#[derive(Debug)]
pub struct RunDirLock {
    path: PathBuf,
    _lock: Flock<File>,
}

impl RunDirLock {
    pub fn path(&self) -> &Path {
        &self.path
    }
}

use crate::transport::symlink::refuse;

/// Creates `dir` (0700) if needed, checks it is ours and private, and locks it.
pub fn acquire(dir: &Path) -> io::Result<RunDirLock> {
    if let Some(parent) = dir.parent().filter(|p| !p.as_os_str().is_empty()) {
        std::fs::create_dir_all(parent)?;
    }
    match std::fs::DirBuilder::new().mode(0o700).create(dir) {
        Ok(()) => {}
        Err(e) if e.kind() == io::ErrorKind::AlreadyExists => {}
        Err(e) => return Err(e),
    }
    if std::fs::symlink_metadata(dir)?.file_type().is_symlink() {
        return Err(refuse(
            "is a symlink; the run directory must be a real directory (remove the link or choose another)".into(),
        ));
    }
    // O_NOFOLLOW also covers a symlink swapped in since the check (it then fails ENOTDIR).
    let file = std::fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_DIRECTORY | libc::O_NOFOLLOW)
        .open(dir)
        .map_err(|e| match e.raw_os_error() {
            Some(libc::ELOOP) => refuse(
                "is a symlink; the run directory must be a real directory (remove the link or choose another)".into(),
            ),
            Some(libc::ENOTDIR) => refuse("is not a directory (or became a symlink)".into()),
            _ => e,
        })?;
    let meta = file.metadata()?;
    let me = nix::unistd::geteuid().as_raw();
    if meta.uid() != me {
        return Err(refuse(format!(
            "is owned by uid {}, not by this user (uid {me}); the daemon only uses a run directory of its own",
            meta.uid()
        )));
    }
    let mode = meta.mode() & 0o7777;
    if mode & 0o022 != 0 {
        return Err(refuse(format!(
            "is group- or world-writable (mode {mode:04o}): another account could replace what the daemon makes there; `chmod go-w` it or choose another"
        )));
    }
    let lock = Flock::lock(file, FlockArg::LockExclusiveNonblock).map_err(|(_, errno)| {
        if errno == nix::errno::Errno::EWOULDBLOCK {
            io::Error::new(
                io::ErrorKind::AddrInUse,
                "another eyebot-hil daemon is using it (it holds the run directory's lock)",
            )
        } else {
            io::Error::from(errno)
        }
    })?;
    Ok(RunDirLock {
        path: dir.to_path_buf(),
        _lock: lock,
    })
}

#[cfg(test)]
mod tests {
    use std::os::unix::fs::PermissionsExt;

    use super::*;

    #[test]
    fn a_new_run_directory_is_private_and_locked_once() {
        let tmp = crate::scratch::dir("rundir");
        let dir = tmp.path().join("a/run");
        let lock = acquire(&dir).unwrap();
        let mode = std::fs::metadata(&dir).unwrap().mode() & 0o777;
        assert_eq!(mode & 0o077, 0, "mode {mode:o}");
        let err = acquire(&dir).unwrap_err();
        assert_eq!(err.kind(), io::ErrorKind::AddrInUse, "{err}");
        drop(lock);
        acquire(&dir).unwrap();
    }

    #[test]
    fn symlinked_or_shared_run_directories_are_refused() {
        let tmp = crate::scratch::dir("rundir-bad");
        let real = tmp.path().join("real");
        std::fs::create_dir(&real).unwrap();
        let link = tmp.path().join("run");
        std::os::unix::fs::symlink(&real, &link).unwrap();
        let err = acquire(&link).unwrap_err().to_string();
        assert!(err.contains("symlink"), "{err}");
        std::fs::set_permissions(&real, std::fs::Permissions::from_mode(0o777)).unwrap();
        let err = acquire(&real).unwrap_err().to_string();
        assert!(
            err.contains("world-writable") && err.contains("0777"),
            "{err}"
        );
        std::fs::set_permissions(&real, std::fs::Permissions::from_mode(0o770)).unwrap();
        assert!(acquire(&real).is_err(), "group-writable");
        std::fs::set_permissions(&real, std::fs::Permissions::from_mode(0o755)).unwrap();
        acquire(&real).unwrap();
        let file = tmp.path().join("file");
        std::fs::write(&file, "").unwrap();
        assert!(
            acquire(&file)
                .unwrap_err()
                .to_string()
                .contains("not a directory")
        );
    }

    #[test]
    fn daemon_files_are_never_written_through_a_symlink_or_into_a_fifo() {
        let tmp = crate::scratch::dir("rundir-files");
        let victim = tmp.path().join("victim");
        std::fs::write(&victim, "precious").unwrap();
        let planted = tmp.path().join(".sonar.owner");
        std::os::unix::fs::symlink(&victim, &planted).unwrap();
        let err = write_file(&planted, "123\n", 0o600)
            .unwrap_err()
            .to_string();
        assert!(err.contains("symlink"), "{err}");
        assert_eq!(std::fs::read_to_string(&victim).unwrap(), "precious");
        assert_eq!(
            read_pid(&planted),
            None,
            "not read through a symlink either"
        );
        let fifo = tmp.path().join("pid");
        nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).unwrap();
        assert!(write_file(&fifo, "1\n", 0o644).is_err());
        assert_eq!(read_pid(&fifo), None, "a FIFO is not waited on");
        let ok = tmp.path().join("ok");
        write_file(&ok, "42\n", 0o600).unwrap();
        assert_eq!(read_pid(&ok), Some(42));
    }
}

//! The CI scripts as a newcomer's machine runs them: `.ci/install-deps` against a stand-in
//! `apt-get`, so no package is installed and no lock of the real system is touched.

use std::os::unix::fs::PermissionsExt;
use std::path::Path;
use std::process::Command;

use eyebot_test_support::{TempDir, require_tool, workspace_root};

/// The tools `.ci/install-deps` calls besides `apt-get` and `sudo`, taken from this machine,
/// with their Debian packages.
const REAL_TOOLS: [(&str, &str); 6] = [
    ("id", "coreutils"),
    ("mktemp", "coreutils"),
    ("grep", "grep"),
    ("cat", "coreutils"),
    ("rm", "coreutils"),
    ("sleep", "coreutils"),
];

fn executable(path: &Path, text: &str) {
    std::fs::write(path, text).unwrap();
    std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o755)).unwrap();
}

/// Runs `.ci/install-deps` with a `PATH` holding only the real tools it needs, a `sudo` that
/// runs its command, and an `apt-get` that fails its first `locked` calls the way apt does when
/// another package manager holds the lock, then fails with `then_status` (0: succeeds).
/// Returns the script's output and the `apt-get` calls made, one a line.
fn install_deps_with(locked: u32, then_status: u32, wait_s: u32) -> (std::process::Output, String) {
    let bash = require_tool("bash", "bash");
    let dir = TempDir::new("install-deps");
    let bin = dir.join("bin");
    std::fs::create_dir(&bin).unwrap();
    for (tool, package) in REAL_TOOLS {
        let real = require_tool(tool, package);
        std::os::unix::fs::symlink(&real, bin.join(tool)).unwrap();
    }
    executable(&bin.join("sudo"), "#!/bin/sh\nexec \"$@\"\n");
    let calls = dir.join("calls");
    let apt_get = format!(
        "#!{bash}\n\
         echo \"$*\" >> {calls}\n\
         n=$(grep -c . {calls})\n\
         if [ \"$n\" -le {locked} ]; then\n\
           echo 'E: Could not get lock /var/lib/apt/lists/lock. It is held by process 1 (apt-get)' >&2\n\
           echo 'E: Unable to lock directory /var/lib/apt/lists/' >&2\n\
           exit 100\n\
         fi\n\
         [ {then_status} -eq 0 ] || echo 'E: Unable to locate package nothing-here' >&2\n\
         exit {then_status}\n",
        bash = bash.display(),
        calls = calls.display(),
    );
    executable(&bin.join("apt-get"), &apt_get);
    let out = Command::new(&bash)
        .arg(workspace_root().join(".ci/install-deps"))
        .env_clear()
        .env("PATH", &bin)
        .env("EYEBOT_APT_LOCK_WAIT_S", wait_s.to_string())
        .output()
        .unwrap();
    let calls = std::fs::read_to_string(&calls).unwrap_or_default();
    (out, calls)
}

/// `.ci/install-deps` failed at once (status 100) when another package manager held apt's
/// lock; it waits for the lock, within a bound, and then installs.
#[test]
fn install_deps_waits_for_a_held_apt_lock() {
    let (out, calls) = install_deps_with(2, 0, 60);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(out.status.success(), "{out:?}");
    let calls: Vec<&str> = calls.lines().collect();
    assert_eq!(
        calls.len(),
        4,
        "two locked updates, one update, one install: {calls:?}"
    );
    assert!(calls[..3].iter().all(|c| c.contains("update")), "{calls:?}");
    assert!(calls[3].contains("install"), "{calls:?}");
    assert!(
        calls.iter().all(|c| c.contains("DPkg::Lock::Timeout=")),
        "apt-get itself waits for the dpkg lock: {calls:?}"
    );
    assert!(stderr.contains("waiting up to 60 s"), "{stderr}");
}

/// The wait is bounded: a lock never released ends the script with apt's message, and a
/// failure that is not about a lock is not retried.
#[test]
fn install_deps_gives_up_on_a_lock_after_its_bound_and_at_once_on_other_errors() {
    let (out, calls) = install_deps_with(u32::MAX, 0, 2);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{out:?}");
    assert!(stderr.contains("Could not get lock"), "{stderr}");
    assert!(stderr.contains("apt-get update failed"), "{stderr}");
    assert!(
        calls.lines().count() >= 2,
        "retried within the bound: {calls}"
    );

    let (out, calls) = install_deps_with(0, 100, 60);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{out:?}");
    assert_eq!(calls.lines().count(), 1, "not retried: {calls}");
    assert!(stderr.contains("Unable to locate package"), "{stderr}");
}

//! The one policy for a system tool a test needs: find it, or fail loudly naming the tool and
//! the Debian package that provides it. A test never passes quietly without its tool; the
//! README's test command (`.ci/test`) installs every one of them.

use std::path::{Path, PathBuf};

/// The path of `tool` on `PATH` (or in `/usr/sbin`, `/sbin`), or a panic naming it and
/// `package`.
pub fn require_tool(tool: &str, package: &str) -> PathBuf {
    let paths = std::env::var_os("PATH").unwrap_or_default();
    std::env::split_paths(&paths)
        .chain([PathBuf::from("/usr/sbin"), PathBuf::from("/sbin")])
        .map(|dir| dir.join(tool))
        .find(|p| p.is_file())
        .unwrap_or_else(|| missing(&format!("`{tool}`"), package))
}

/// `path` (a file a tool chain needs, such as a cross C library's header), or a panic naming
/// it and `package`.
pub fn require_file(path: &Path, package: &str) -> PathBuf {
    if path.is_file() {
        return path.to_path_buf();
    }
    missing(&path.display().to_string(), package)
}

fn missing(what: &str, package: &str) -> ! {
    let banner = "!".repeat(72);
    eprintln!(
        "\n{banner}\n!! MISSING: {what} is not installed (Debian package `{package}`).\n\
         !! This test needs it; `bash .ci/install-deps` installs it.\n{banner}\n"
    );
    panic!("{what} is missing: install the Debian package `{package}` (bash .ci/install-deps)");
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_present_tool_is_found_on_the_path() {
        assert!(require_tool("sh", "dash").is_file());
    }

    /// A missing tool is a failure that names the tool and its package, never a skip.
    #[test]
    #[should_panic(
        expected = "`eyebot-no-such-tool` is missing: install the Debian package `no-such-package`"
    )]
    fn a_missing_tool_fails_naming_its_package() {
        require_tool("eyebot-no-such-tool", "no-such-package");
    }
}

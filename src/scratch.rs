//! Scratch directories for this crate's unit tests: each a [`tempfile::TempDir`] in the
//! system's temporary directory, removed with its contents when it drops, also when the test
//! panics. Named `eyebot-hil-unit-PID-TAG-RANDOM`, so parallel tests never share one and a
//! look at the temporary directory tells which process made it.

use std::path::Path;

/// The name prefix of every scratch directory.
pub(crate) const PREFIX: &str = "eyebot-hil-unit-";

/// A fresh, empty directory for the test `tag`.
pub(crate) fn dir(tag: &str) -> tempfile::TempDir {
    tempfile::Builder::new()
        .prefix(&format!("{PREFIX}{}-{tag}-", std::process::id()))
        .tempdir()
        .unwrap_or_else(|e| panic!("cannot create a scratch directory for {tag}: {e}"))
}

/// The files under `src` (relative paths) whose text contains `needle`, outside `skip`.
fn sources_containing(needle: &str, skip: &[&str]) -> Vec<String> {
    fn walk(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
        for entry in std::fs::read_dir(dir).expect("list src") {
            let path = entry.expect("a directory entry").path();
            if path.is_dir() {
                walk(&path, out);
            } else if path.extension().is_some_and(|e| e == "rs") {
                out.push(path);
            }
        }
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut files = Vec::new();
    walk(&root.join("src"), &mut files);
    let mut hits: Vec<String> = files
        .iter()
        .map(|p| {
            p.strip_prefix(root)
                .expect("under the manifest directory")
                .to_string_lossy()
                .into_owned()
        })
        .filter(|rel| !skip.iter().any(|s| rel.starts_with(s)))
        .filter(|rel| {
            std::fs::read_to_string(root.join(rel))
                .expect("read a source file")
                .contains(needle)
        })
        .collect();
    hits.sort();
    hits
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A scratch directory and its files are gone once the test that made it panics.
    #[test]
    fn a_scratch_dir_is_removed_when_its_test_panics() {
        let made = std::sync::Mutex::new(None);
        let result = std::panic::catch_unwind(|| {
            let tmp = dir("panic");
            std::fs::write(tmp.path().join("file"), "text").unwrap();
            std::fs::create_dir(tmp.path().join("sub")).unwrap();
            *made.lock().unwrap() = Some(tmp.path().to_path_buf());
            panic!("a failing test");
        });
        assert!(result.is_err());
        let path = made.into_inner().unwrap().expect("the directory was made");
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        assert!(name.starts_with(&format!("{PREFIX}{}-panic-", std::process::id())));
        assert!(!path.exists(), "{} left behind", path.display());
    }

    /// Every unit test that needs a directory takes a scratch one: no other file in `src`
    /// makes its own under the system's temporary directory, where a failing test would leave
    /// it behind. The exceptions are not tests: `gap-bench` (the independent and bridge
    /// sources) writes its generated runs, and the independent model's program built into
    /// the binary, under the temporary directory and removes them when it ends.
    #[test]
    fn no_unit_test_makes_its_own_temporary_directory() {
        assert_eq!(
            sources_containing(
                "temp_dir()",
                &[
                    "src/scratch.rs",
                    "src/gap/bench/calibrated.rs",
                    "src/gap/bench/independent.rs"
                ]
            ),
            Vec::<String>::new()
        );
    }
}

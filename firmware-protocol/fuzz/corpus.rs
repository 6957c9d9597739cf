//! Replaying a committed fuzz corpus through a target's property function: shared by the
//! corpus tests of `firmware-protocol` and of the root package (each includes this file with
//! `#[path]`, as it does its `checks.rs`).

use std::path::Path;

/// Runs `check` on every file of `corpora/<target>/` under `root`, in name order; fails
/// naming the first file whose property does not hold, or an empty or missing corpus.
pub fn replay(root: &Path, target: &str, check: fn(&[u8])) {
    let dir = root.join("corpora").join(target);
    let mut files: Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("corpus {}: {e}", dir.display()))
        .map(|e| e.expect("a corpus entry").path())
        .collect();
    files.sort();
    assert!(!files.is_empty(), "corpus {} is empty", dir.display());
    for file in &files {
        let data = std::fs::read(file).expect("a corpus file");
        let outcome = std::panic::catch_unwind(|| check(&data));
        assert!(
            outcome.is_ok(),
            "{target}: {} fails its property",
            file.display()
        );
    }
}

//! Replays the committed fuzz corpora of the replay input reader and the configuration
//! loaders (`fuzz/corpora/<target>/`, minimised with libFuzzer's `-merge=1`) through the
//! same property functions the fuzz targets run (`fuzz/checks.rs`), so CI checks every
//! input the fuzzer kept on the stable toolchain.

#[path = "../fuzz/checks.rs"]
mod checks;

use std::path::Path;

fn replay(target: &str, check: fn(&[u8])) {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("fuzz/corpora")
        .join(target);
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

#[test]
fn replay_input_corpus() {
    replay("replay_input", checks::replay_input);
}

#[test]
fn config_load_corpus() {
    replay("config_load", checks::config_load);
}

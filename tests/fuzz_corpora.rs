//! Replays the committed fuzz corpora of the replay input reader and the configuration
//! loaders (`fuzz/corpora/<target>/`, minimised with libFuzzer's `-merge=1`) through the
//! same property functions the fuzz targets run (`fuzz/checks.rs`), so CI checks every
//! input the fuzzer kept on the stable toolchain.

#[path = "../fuzz/checks.rs"]
mod checks;

#[path = "../firmware-protocol/fuzz/corpus.rs"]
mod corpus;

fn replay(target: &str, check: fn(&[u8])) {
    corpus::replay(
        std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/fuzz")),
        target,
        check,
    );
}

#[test]
fn replay_input_corpus() {
    replay("replay_input", checks::replay_input);
}

#[test]
fn config_load_corpus() {
    replay("config_load", checks::config_load);
}

//! Replays the committed fuzz corpora (`fuzz/corpora/<target>/`, minimised with libFuzzer's
//! `-merge=1`) through the same property functions the fuzz targets run (`fuzz/checks.rs`),
//! so every input the fuzzer kept, and every finding turned into a corpus file, is checked by
//! `cargo test` on the stable toolchain.

#[path = "../fuzz/checks.rs"]
mod checks;

#[path = "../fuzz/corpus.rs"]
mod corpus;

fn replay(target: &str, check: fn(&[u8])) {
    corpus::replay(
        std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/fuzz")),
        target,
        check,
    );
}

#[test]
fn line_decoder_corpus() {
    replay("line_decoder", checks::line_decoder);
}

#[test]
fn nmea_line_corpus() {
    replay("nmea_line", checks::nmea_line);
}

#[test]
fn nmea_fields_corpus() {
    replay("nmea_fields", checks::nmea_fields);
}

#[test]
fn sensor_frame_corpus() {
    replay("sensor_frame", checks::sensor_frame);
}

#[test]
fn sensor_message_corpus() {
    replay("sensor_message", checks::sensor_message);
}

#[test]
fn sonar_command_corpus() {
    replay("sonar_command", checks::sonar_command);
}

#[test]
fn compass_word_corpus() {
    replay("compass_word", checks::compass_word);
}

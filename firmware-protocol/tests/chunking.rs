//! Every fixture fed at every chunk size from 1 byte to its full length gives the same items
//! as feeding it whole (mavlink's `decodes_fragmented_and_adjacent_frames`).

mod common;

use bytes::BytesMut;
use common::{examples, expected_for};
use firmware_protocol::{LineDecoder, LineItem};

fn decode_in_chunks(bytes: &[u8], chunk: usize) -> Vec<LineItem> {
    let mut decoder = LineDecoder::new();
    let mut buf = BytesMut::new();
    let mut items = Vec::new();
    for piece in bytes.chunks(chunk) {
        buf.extend_from_slice(piece);
        while let Some(item) = decoder.decode(&mut buf) {
            items.push(item);
        }
    }
    while let Some(item) = decoder.decode_eof(&mut buf) {
        items.push(item);
    }
    assert!(buf.is_empty(), "decode_eof must consume everything");
    items
}

fn assert_chunk_invariant(bytes: &[u8], expected: &[LineItem]) {
    for chunk in 1..=bytes.len() {
        assert_eq!(
            decode_in_chunks(bytes, chunk),
            expected,
            "chunk size {chunk}"
        );
    }
}

#[test]
fn each_protocol_example_at_every_chunk_size() {
    for ex in examples() {
        assert_chunk_invariant(&ex.bytes, &[expected_for(&ex)]);
    }
}

#[test]
fn all_examples_back_to_back_at_every_chunk_size() {
    let exs = examples();
    let bytes: Vec<u8> = exs.iter().flat_map(|e| e.bytes.clone()).collect();
    let expected: Vec<LineItem> = exs.iter().map(expected_for).collect();
    assert_chunk_invariant(&bytes, &expected);
}

#[test]
fn examples_separated_by_garbage_at_every_chunk_size() {
    use firmware_protocol::LinkError;
    let mut bytes = Vec::new();
    let mut expected = Vec::new();
    for ex in examples() {
        bytes.extend_from_slice(b"xyz\x00\xEB");
        expected.push(LineItem::Error(LinkError::Skipped { count: 5 }));
        bytes.extend_from_slice(&ex.bytes);
        expected.push(expected_for(&ex));
    }
    assert_chunk_invariant(&bytes, &expected);
}

//! Shared-line stream decoder: no panic on any input, the same items whatever the chunking,
//! everything consumed at EOF, and every decoded message re-encodes to bytes that decode to it.
#![no_main]
use bytes::BytesMut;
use firmware_protocol::{LineDecoder, LineItem};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let Some((&chunk, bytes)) = data.split_first() else {
        return;
    };
    let whole = LineDecoder::decode_all(bytes);

    let chunk = usize::from(chunk).max(1);
    let mut decoder = LineDecoder::new();
    let mut buf = BytesMut::new();
    let mut chunked = Vec::new();
    for piece in bytes.chunks(chunk) {
        buf.extend_from_slice(piece);
        while let Some(item) = decoder.decode(&mut buf) {
            chunked.push(item);
        }
    }
    while let Some(item) = decoder.decode_eof(&mut buf) {
        chunked.push(item);
    }
    assert!(buf.is_empty(), "decode_eof left bytes behind");
    assert_eq!(whole, chunked, "items depend on chunking");

    for item in whole {
        if matches!(item, LineItem::Error(_)) {
            continue;
        }
        let mut out = BytesMut::new();
        item.encode(&mut out).expect("a decoded message re-encodes");
        let again = LineDecoder::decode_all(&out);
        assert_eq!(again, vec![item], "re-encoded message decodes differently");
    }
});

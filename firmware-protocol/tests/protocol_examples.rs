//! Golden tests: every hex/NMEA example in PROTOCOL.md decodes to what its prose says and
//! re-encodes to the same bytes.

mod common;

use bytes::BytesMut;
use common::{examples, expected_for};
use firmware_protocol::LineDecoder;

#[test]
fn every_protocol_example_decodes_to_its_meaning_and_reencodes_identically() {
    let examples = examples();
    // Guards the extractor: if it silently found nothing, the loop below would prove nothing.
    assert!(
        examples.len() >= 38,
        "only {} examples extracted from PROTOCOL.md",
        examples.len()
    );
    for ex in &examples {
        let expected = expected_for(ex);
        let decoded = LineDecoder::decode_all(&ex.bytes);
        assert_eq!(
            decoded,
            vec![expected.clone()],
            "example {:?} decodes wrongly",
            ex.name
        );
        let mut out = BytesMut::new();
        assert!(expected.encode(&mut out).unwrap());
        assert_eq!(
            &out[..],
            &ex.bytes[..],
            "example {:?} re-encodes differently",
            ex.name
        );
    }
}

/// Each example block has a name of its own, so a name says which example it is.
#[test]
fn example_names_are_unique() {
    let mut names: Vec<String> = examples().into_iter().map(|ex| ex.name).collect();
    let count = names.len();
    names.sort_unstable();
    names.dedup();
    assert_eq!(
        names.len(),
        count,
        "an example name is used twice: {names:?}"
    );
}

#[test]
fn every_message_type_has_an_example() {
    use firmware_protocol::LineItem;
    let mut types: Vec<u8> = examples()
        .iter()
        .filter_map(|ex| match expected_for(ex) {
            LineItem::Frame(f) => Some(f.message.msg_type()),
            _ => None,
        })
        .collect();
    types.sort_unstable();
    types.dedup();
    assert_eq!(types.len(), 25, "types with an example: {types:02x?}");
}

#[test]
fn crc_parameters_in_protocol_md_match_the_code() {
    let a = firmware_protocol::crc::ALGORITHM;
    let row = format!(
        "| 16 | `{:#06x}` | `{:#06x}` | {} | {} | `{:#06x}` | `{:#06x}` |",
        a.poly, a.init, a.refin, a.refout, a.xorout, a.check
    )
    .replace("0x", "0x")
    .to_uppercase()
    .replace("0X", "0x")
    .replace("FALSE", "false")
    .replace("TRUE", "true");
    assert!(
        common::PROTOCOL_MD.contains(&row),
        "PROTOCOL.md lacks the CRC row {row}"
    );
}

//! Vector 2X heading word decoder: no panic; an accepted word re-encodes to itself.
#![no_main]
use firmware_protocol::{HeadingFormat, HeadingWord};
use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: [u8; 2]| {
    let word = HeadingWord(u16::from_be_bytes(data));
    for format in [HeadingFormat::Binary, HeadingFormat::Bcd] {
        if let Ok(heading) = word.decode(format) {
            assert_eq!(HeadingWord::encode(heading, format), Ok(word));
        }
    }
});

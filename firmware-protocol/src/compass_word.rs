//! The Vector 2X heading word: one 16-bit word, MSB first on the wire.
//!
//! The compass reports 0..=359 degrees either as plain binary in the low 9 bits or as packed
//! BCD in the low 10 bits (hundreds in bits 9..8, tens in bits 7..4, units in bits 3..0). All
//! other bits are zero. The BCD word printed in hex reads as the decimal heading: 359 deg is
//! 0x0359 in BCD and 0x0167 in binary.

use crate::error::{CompassWordError, EncodeError};

/// How the compass encodes a heading in its 16-bit word.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum HeadingFormat {
    /// Heading in the low 9 bits.
    Binary,
    /// Packed BCD in the low 10 bits: hundreds (2 bits), tens (4), units (4).
    Bcd,
}

/// One heading word exactly as the Vector 2X clocks it out.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub struct HeadingWord(pub u16);

impl HeadingWord {
    /// Encode a heading of 0..=359 whole degrees.
    pub fn encode(heading_deg: u16, format: HeadingFormat) -> Result<Self, EncodeError> {
        if heading_deg > 359 {
            return Err(EncodeError::HeadingOutOfRange { heading_deg });
        }
        Ok(match format {
            HeadingFormat::Binary => Self(heading_deg),
            HeadingFormat::Bcd => {
                let hundreds = heading_deg / 100;
                let tens = (heading_deg / 10) % 10;
                let units = heading_deg % 10;
                Self((hundreds << 8) | (tens << 4) | units)
            }
        })
    }

    /// Decode the word back to whole degrees, rejecting words the compass cannot produce.
    pub fn decode(self, format: HeadingFormat) -> Result<u16, CompassWordError> {
        let word = self.0;
        match format {
            HeadingFormat::Binary => {
                if word & !0x01FF != 0 {
                    return Err(CompassWordError::StrayBits { word, mask: 0x01FF });
                }
                if word > 359 {
                    return Err(CompassWordError::OutOfRange { word });
                }
                Ok(word)
            }
            HeadingFormat::Bcd => {
                if word & !0x03FF != 0 {
                    return Err(CompassWordError::StrayBits { word, mask: 0x03FF });
                }
                let hundreds = (word >> 8) & 0x3;
                let tens = (word >> 4) & 0xF;
                let units = word & 0xF;
                if tens > 9 || units > 9 {
                    return Err(CompassWordError::BadBcdDigit { word });
                }
                let heading = hundreds * 100 + tens * 10 + units;
                if heading > 359 {
                    return Err(CompassWordError::OutOfRange { word });
                }
                Ok(heading)
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn datasheet_layout_examples() {
        assert_eq!(
            HeadingWord::encode(359, HeadingFormat::Bcd).unwrap(),
            HeadingWord(0x0359)
        );
        assert_eq!(
            HeadingWord::encode(359, HeadingFormat::Binary).unwrap(),
            HeadingWord(0x0167)
        );
        assert_eq!(
            HeadingWord::encode(270, HeadingFormat::Bcd).unwrap(),
            HeadingWord(0x0270)
        );
        assert_eq!(
            HeadingWord::encode(0, HeadingFormat::Bcd).unwrap(),
            HeadingWord(0x0000)
        );
    }

    #[test]
    fn every_heading_round_trips_in_both_formats() {
        for heading in 0..360 {
            for format in [HeadingFormat::Binary, HeadingFormat::Bcd] {
                let word = HeadingWord::encode(heading, format).unwrap();
                assert_eq!(word.decode(format), Ok(heading));
            }
        }
    }

    #[test]
    fn out_of_range_heading_is_misuse_not_wire_error() {
        assert_eq!(
            HeadingWord::encode(360, HeadingFormat::Binary),
            Err(EncodeError::HeadingOutOfRange { heading_deg: 360 })
        );
    }

    #[test]
    fn impossible_words_are_rejected() {
        assert!(matches!(
            HeadingWord(0x0400).decode(HeadingFormat::Bcd),
            Err(CompassWordError::StrayBits { .. })
        ));
        assert!(matches!(
            HeadingWord(0x003A).decode(HeadingFormat::Bcd),
            Err(CompassWordError::BadBcdDigit { .. })
        ));
        assert!(matches!(
            HeadingWord(0x0360).decode(HeadingFormat::Bcd),
            Err(CompassWordError::OutOfRange { .. })
        ));
        assert!(matches!(
            HeadingWord(360).decode(HeadingFormat::Binary),
            Err(CompassWordError::OutOfRange { .. })
        ));
        assert!(matches!(
            HeadingWord(0x0200).decode(HeadingFormat::Binary),
            Err(CompassWordError::StrayBits { .. })
        ));
    }
}

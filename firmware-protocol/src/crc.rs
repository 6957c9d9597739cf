//! The sensor-link frame check: CRC-16/IBM-3740 (often called CRC-16/CCITT-FALSE).
//!
//! Parameters (also in `PROTOCOL.md`): width 16, poly 0x1021, init 0xFFFF, refin false,
//! refout false, xorout 0x0000, check value ("123456789") 0x29B1. The arithmetic comes from
//! the `crc` crate's catalogue; this module only names the choice.

/// The algorithm used for every sensor-link frame.
pub const ALGORITHM: &crc::Algorithm<u16> = &crc::CRC_16_IBM_3740;

// Slice-by-16 tables (8 KiB, built at compile time): about 4x the byte-table speed on long
// buffers, which matters when replaying large captures (benches/decode.rs).
const CRC16: crc::Crc<u16, crc::Table<16>> = crc::Crc::<u16, crc::Table<16>>::new(ALGORITHM);

/// CRC of `bytes` with the sensor-link parameters.
pub fn crc16(bytes: &[u8]) -> u16 {
    CRC16.checksum(bytes)
}

/// CRC over several slices, as if they were concatenated (header then payload).
pub fn crc16_parts(parts: &[&[u8]]) -> u16 {
    let mut digest = CRC16.digest();
    for part in parts {
        digest.update(part);
    }
    digest.finalize()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The catalogue check value: a wrong algorithm constant would change it.
    #[test]
    fn check_value_matches_catalogue_parameters() {
        assert_eq!(crc16(b"123456789"), 0x29B1);
        assert_eq!(ALGORITHM.poly, 0x1021);
        assert_eq!(ALGORITHM.init, 0xFFFF);
        assert!(!ALGORITHM.refin && !ALGORITHM.refout);
        assert_eq!(ALGORITHM.xorout, 0x0000);
    }

    #[test]
    fn parts_equal_whole() {
        assert_eq!(crc16_parts(&[b"1234", b"", b"56789"]), crc16(b"123456789"));
    }
}

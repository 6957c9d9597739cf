//! Serial line settings and the wire time they imply.
//!
//! A pseudo-terminal has no baud rate, but control code that depends on timing must see the
//! real timing, so every byte the bridge sends is paced at the configured line rate: one
//! start bit, the data bits, an optional parity bit and the stop bits per character.

use std::fmt;
use std::str::FromStr;

use serde::Deserialize;

/// Parity of a serial character.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Parity {
    None,
    Odd,
    Even,
}

/// Hardware or software flow control.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Deserialize, Default)]
#[serde(rename_all = "lowercase")]
pub enum FlowControl {
    #[default]
    None,
    /// RTS/CTS handshake (RoBIOS `RTSCTS`).
    Hardware,
    /// XON/XOFF.
    Software,
}

/// The settings of one serial line, e.g. `4800 8N1`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct LineSettings {
    pub baud: u32,
    pub data_bits: u8,
    pub parity: Parity,
    pub stop_bits: u8,
    pub flow_control: FlowControl,
}

impl LineSettings {
    /// 8N1 at `baud`, no flow control.
    pub const fn n81(baud: u32) -> Self {
        Self {
            baud,
            data_bits: 8,
            parity: Parity::None,
            stop_bits: 1,
            flow_control: FlowControl::None,
        }
    }

    /// Bits on the wire per character: start + data + parity + stop.
    pub fn bits_per_char(&self) -> u32 {
        1 + u32::from(self.data_bits)
            + u32::from(self.parity != Parity::None)
            + u32::from(self.stop_bits)
    }

    /// Seconds one character occupies the wire (8N1 at 4800 baud: 10 / 4800 s).
    pub fn char_time_s(&self) -> f64 {
        f64::from(self.bits_per_char()) / f64::from(self.baud)
    }

    /// Nanoseconds one character occupies the wire, rounded up so a pacer never runs fast.
    pub fn char_time_ns(&self) -> u64 {
        (u64::from(self.bits_per_char()) * 1_000_000_000).div_ceil(u64::from(self.baud))
    }
}

/// Why a line-settings string such as `4800 8N1` was rejected.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("line settings `{input}`: {reason} (expected e.g. `4800 8N1` or `115200,8,N,1`)")]
pub struct LineSettingsError {
    pub input: String,
    pub reason: String,
}

/// Baud rates a 68332 SCI and common USB adapters accept; others are rejected as typos.
pub const STANDARD_BAUDS: &[u32] = &[
    300, 600, 1200, 2400, 4800, 9600, 19200, 38400, 57600, 115200, 230400, 460800, 921600,
];

impl LineSettings {
    /// Checks ranges: a standard baud, 5-8 data bits, 1-2 stop bits.
    pub fn validate(self, input: &str) -> Result<Self, LineSettingsError> {
        let fail = |reason: String| LineSettingsError {
            input: input.to_string(),
            reason,
        };
        if !STANDARD_BAUDS.contains(&self.baud) {
            return Err(fail(format!(
                "{} is not a standard baud rate {STANDARD_BAUDS:?}",
                self.baud
            )));
        }
        if !(5..=8).contains(&self.data_bits) {
            return Err(fail(format!(
                "{} data bits; 5 to 8 allowed",
                self.data_bits
            )));
        }
        if !(1..=2).contains(&self.stop_bits) {
            return Err(fail(format!(
                "{} stop bits; 1 or 2 allowed",
                self.stop_bits
            )));
        }
        Ok(self)
    }
}

impl FromStr for LineSettings {
    type Err = LineSettingsError;

    /// Accepts `4800 8N1`, `4800,8N1`, `115200,8,N,1` and gpsfake's `#Serial: 4800 8N1`
    /// payload. Case-insensitive parity letter.
    fn from_str(input: &str) -> Result<Self, Self::Err> {
        let fail = |reason: &str| LineSettingsError {
            input: input.to_string(),
            reason: reason.to_string(),
        };
        let fields: Vec<&str> = input
            .split(|c: char| c == ',' || c.is_whitespace())
            .filter(|f| !f.is_empty())
            .collect();
        let (baud, frame): (&str, String) = match fields.as_slice() {
            [baud, frame] => (baud, frame.to_string()),
            [baud, d, p, s] => (baud, format!("{d}{p}{s}")),
            [baud] => (baud, "8N1".to_string()),
            _ => return Err(fail("wrong number of fields")),
        };
        let baud: u32 = baud.parse().map_err(|_| fail("baud is not a number"))?;
        let bytes = frame.as_bytes();
        let [d, p, s] = bytes else {
            return Err(fail(
                "frame must be data bits, parity letter, stop bits, like 8N1",
            ));
        };
        let data_bits = (*d as char)
            .to_digit(10)
            .ok_or_else(|| fail("data bits must be a digit"))? as u8;
        let parity = match p.to_ascii_uppercase() {
            b'N' => Parity::None,
            b'O' => Parity::Odd,
            b'E' => Parity::Even,
            _ => return Err(fail("parity must be N, O or E")),
        };
        let stop_bits = (*s as char)
            .to_digit(10)
            .ok_or_else(|| fail("stop bits must be a digit"))? as u8;
        LineSettings {
            baud,
            data_bits,
            parity,
            stop_bits,
            flow_control: FlowControl::None,
        }
        .validate(input)
    }
}

impl fmt::Display for LineSettings {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        let p = match self.parity {
            Parity::None => 'N',
            Parity::Odd => 'O',
            Parity::Even => 'E',
        };
        write!(f, "{} {}{}{}", self.baud, self.data_bits, p, self.stop_bits)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nmea_line_carries_480_characters_per_second() {
        let line: LineSettings = "4800 8N1".parse().unwrap();
        assert_eq!(line, LineSettings::n81(4800));
        assert_eq!(line.bits_per_char(), 10);
        assert!((line.char_time_s() - 1.0 / 480.0).abs() < 1e-15);
        assert_eq!(line.char_time_ns(), 2_083_334);
    }

    #[test]
    fn parity_and_two_stop_bits_lengthen_a_character() {
        let line: LineSettings = "9600,7,e,2".parse().unwrap();
        assert_eq!(line.bits_per_char(), 11);
        assert_eq!(line.to_string(), "9600 7E2");
    }

    #[test]
    fn typos_are_rejected_with_the_input_named() {
        for bad in [
            "4801 8N1",
            "4800 9N1",
            "4800 8X1",
            "4800 8N3",
            "fast",
            "",
            "4800 8N1 extra",
        ] {
            let err = bad.parse::<LineSettings>().unwrap_err();
            assert_eq!(err.input, bad);
        }
    }
}

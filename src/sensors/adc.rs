//! The EyeBot's analog inputs: 8 channels, 10 bits, 0-5 V (thesis 2.2.2, 4.6), as a small
//! state machine that remembers the channel it converted last.
//!
//! A conversion of input `v` on channel `c`:
//! 1. **first read after a switch** (optional): with a high source impedance the sample
//!    capacitor still holds part of the previous channel's voltage, so the first read after
//!    switching sees `r * v_prev + (1 - r) * v` (`first_read_retention` = r; the RoBIOS FAQ
//!    advises reading twice). A repeated read of the same channel is unaffected;
//! 2. **over-voltage coupling** (optional fault): input current through the clamp diodes of
//!    any channel driven above the reference (the paddle wheel on 12 V, thesis 3.3.3) lifts
//!    every channel by `coupling * excess`;
//! 3. **board noise**: Gaussian, `noise_v_rms`;
//! 4. **quantisation**: `code = floor(v / LSB + 0.5 + offset_lsb)`, clamped to 0..=1023. With
//!    `offset_lsb = 0` this is the ideal converter (transitions at half an LSB).

use rand::RngExt;
use rand_distr::StandardNormal;

use super::config::{AdcSettings, AdcSource};
use super::rng::{self, SensorRng};

/// Misuse of the ADC API (a channel number from a client that does not exist).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum AdcError {
    #[error("ADC channel {channel} does not exist (the board has channels 0..=7)")]
    NoSuchChannel { channel: u8 },
}

/// The ADC board.
#[derive(Debug, Clone)]
pub struct AdcBoard {
    s: AdcSettings,
    lsb_v: f64,
    max_code: u16,
    last: Option<(u8, f64)>,
    rng: SensorRng,
}

impl AdcBoard {
    pub fn new(settings: &AdcSettings, master_seed: u64) -> Self {
        let max_code = u16::try_from((1u32 << settings.bits) - 1).unwrap_or(u16::MAX);
        Self {
            lsb_v: settings.reference_v / f64::from(1u32 << settings.bits),
            s: settings.clone(),
            max_code,
            last: None,
            rng: rng::stream(master_seed, "adc"),
        }
    }

    /// Volts per code (4.883 mV for 10 bits at 5 V).
    pub fn lsb_v(&self) -> f64 {
        self.lsb_v
    }

    pub fn reference_v(&self) -> f64 {
        self.s.reference_v
    }

    pub fn max_code(&self) -> u16 {
        self.max_code
    }

    /// What is wired to `channel` (`None` = nothing; it reads 0 V).
    pub fn source(&self, channel: u8) -> Result<Option<AdcSource>, AdcError> {
        self.s
            .channels
            .get(usize::from(channel))
            .copied()
            .ok_or(AdcError::NoSuchChannel { channel })
    }

    /// The channel wired to `source`, if any.
    pub fn channel_of(&self, source: AdcSource) -> Option<u8> {
        self.s
            .channels
            .iter()
            .position(|c| *c == Some(source))
            .and_then(|i| u8::try_from(i).ok())
    }

    /// The ideal converter's code for `v` (no offset, no noise).
    pub fn ideal_code(&self, v: f64) -> u16 {
        self.quantise(v, 0.0)
    }

    fn quantise(&self, v: f64, offset_lsb: f64) -> u16 {
        let code = (v / self.lsb_v + 0.5 + offset_lsb).floor();
        if code <= 0.0 {
            0
        } else if code >= f64::from(self.max_code) {
            self.max_code
        } else {
            code as u16
        }
    }

    /// Converts `input_v` on `channel`; `overvoltage_v` is the sum, over all channels, of
    /// how far their inputs exceed the reference.
    pub fn convert(
        &mut self,
        channel: u8,
        input_v: f64,
        overvoltage_v: f64,
    ) -> Result<u16, AdcError> {
        self.source(channel)?;
        let mut v = input_v;
        if let Some((last_channel, last_v)) = self.last
            && last_channel != channel
            && self.s.first_read_retention > 0.0
        {
            let r = self.s.first_read_retention;
            v = r * last_v + (1.0 - r) * v;
        }
        self.last = Some((channel, v.clamp(0.0, self.s.reference_v)));
        v += self.s.overvoltage_coupling * overvoltage_v.max(0.0);
        if self.s.noise_v_rms > 0.0 {
            let n: f64 = self.rng.sample(StandardNormal);
            v += self.s.noise_v_rms * n;
        }
        Ok(self.quantise(v, self.s.offset_lsb))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn settings() -> AdcSettings {
        AdcSettings {
            reference_v: 5.0,
            bits: 10,
            offset_lsb: 0.0,
            noise_v_rms: 0.0,
            first_read_retention: 0.0,
            overvoltage_coupling: 0.0,
            channels: [
                Some(AdcSource::Depth),
                Some(AdcSource::Velocity),
                None,
                None,
                None,
                None,
                None,
                None,
            ],
        }
    }

    #[test]
    fn ideal_converter_rounds_to_the_nearest_code_and_clamps() {
        let mut adc = AdcBoard::new(&settings(), 0);
        let lsb = 5.0 / 1024.0;
        assert!((adc.lsb_v() - 0.004_882_812_5).abs() < 1e-15);
        assert_eq!(adc.convert(0, 0.0, 0.0), Ok(0));
        assert_eq!(adc.convert(0, 100.0 * lsb + 0.49 * lsb, 0.0), Ok(100));
        assert_eq!(adc.convert(0, 100.0 * lsb + 0.51 * lsb, 0.0), Ok(101));
        assert_eq!(adc.convert(0, 7.0, 0.0), Ok(1023));
        assert_eq!(adc.convert(0, -1.0, 0.0), Ok(0));
        assert_eq!(
            adc.convert(8, 1.0, 0.0),
            Err(AdcError::NoSuchChannel { channel: 8 })
        );
    }

    #[test]
    fn offset_shifts_the_transitions() {
        let mut s = settings();
        s.offset_lsb = 0.5;
        let mut adc = AdcBoard::new(&s, 0);
        let lsb = adc.lsb_v();
        // With +0.5 LSB the transition to 101 moves from 100.5 LSB down to 100.0 LSB.
        assert_eq!(adc.convert(0, 100.2 * lsb, 0.0), Ok(101));
        assert_eq!(adc.convert(0, 99.9 * lsb, 0.0), Ok(100));
    }

    /// The RoBIOS FAQ's effect: only the first read after switching channel is off.
    #[test]
    fn first_read_after_switching_is_pulled_towards_the_previous_channel() {
        let mut s = settings();
        s.first_read_retention = 0.1;
        let mut adc = AdcBoard::new(&s, 0);
        let a = adc.convert(0, 4.0, 0.0).unwrap();
        let first = adc.convert(1, 1.0, 0.0).unwrap();
        let second = adc.convert(1, 1.0, 0.0).unwrap();
        assert_eq!(a, adc.ideal_code(4.0));
        assert_eq!(second, adc.ideal_code(1.0));
        assert_eq!(first, adc.ideal_code(0.1 * 4.0 + 0.9 * 1.0));
        assert!(first > second);
    }

    #[test]
    fn overvoltage_lifts_every_channel() {
        let mut s = settings();
        s.overvoltage_coupling = 0.05;
        let mut adc = AdcBoard::new(&s, 0);
        let clean = adc.ideal_code(2.0);
        let faulty = adc.convert(0, 2.0, 7.0).unwrap();
        assert_eq!(faulty, adc.ideal_code(2.35));
        assert!(faulty > clean + 60);
    }
}

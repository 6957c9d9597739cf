//! tokio-util `Decoder`/`Encoder` adapters (feature `tokio-codec`).
//!
//! Wire errors stay items (`Ok(Some(LineItem::Error(..)))`), so a `FramedRead` keeps reading
//! after a bad frame; the codec's `Error` is only `std::io::Error` from the transport or an
//! [`EncodeError`] from misuse when encoding.

use bytes::BytesMut;
use tokio_util::codec::{Decoder, Encoder};

use crate::error::EncodeError;
use crate::line::{LineDecoder, LineItem};
use crate::nmea::Sentence;
use crate::sensor_link::Frame;
use crate::sonar_link::SonarCommand;

/// Codec for a line carrying any mix of NMEA, sonar commands and binary frames.
#[derive(Debug, Clone, Default)]
pub struct LineCodec {
    decoder: LineDecoder,
}

impl LineCodec {
    pub fn new() -> Self {
        Self::default()
    }
}

/// Errors surfaced through the codec: transport I/O or our own API misuse.
#[derive(Debug, thiserror::Error)]
pub enum CodecError {
    #[error(transparent)]
    Io(#[from] std::io::Error),
    #[error(transparent)]
    Encode(#[from] EncodeError),
}

impl Decoder for LineCodec {
    type Item = LineItem;
    type Error = CodecError;

    fn decode(&mut self, src: &mut BytesMut) -> Result<Option<LineItem>, CodecError> {
        Ok(self.decoder.decode(src))
    }

    fn decode_eof(&mut self, src: &mut BytesMut) -> Result<Option<LineItem>, CodecError> {
        Ok(self.decoder.decode_eof(src))
    }
}

impl Encoder<Frame> for LineCodec {
    type Error = CodecError;
    fn encode(&mut self, item: Frame, dst: &mut BytesMut) -> Result<(), CodecError> {
        item.encode(dst);
        Ok(())
    }
}

impl Encoder<Sentence> for LineCodec {
    type Error = CodecError;
    fn encode(&mut self, item: Sentence, dst: &mut BytesMut) -> Result<(), CodecError> {
        Ok(item.encode(dst)?)
    }
}

impl Encoder<SonarCommand> for LineCodec {
    type Error = CodecError;
    fn encode(&mut self, item: SonarCommand, dst: &mut BytesMut) -> Result<(), CodecError> {
        item.encode(dst);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::sensor_link::Message;

    #[test]
    fn codec_yields_error_items_and_continues() {
        let mut codec = LineCodec::new();
        let mut buf = BytesMut::new();
        buf.extend_from_slice(b"$SDDBT,1.0,f,0.3,M,0.2,F*00\r\n");
        Encoder::<Frame>::encode(&mut codec, Frame::new(1, Message::TimeGet), &mut buf).unwrap();
        let first = codec.decode(&mut buf).unwrap();
        assert!(matches!(first, Some(LineItem::Error(_))));
        let second = codec.decode(&mut buf).unwrap();
        assert_eq!(
            second,
            Some(LineItem::Frame(Frame::new(1, Message::TimeGet)))
        );
        assert!(buf.is_empty());
    }
}

//! The EyeBot side of a line, sans-IO: requests out, classified items in.
//!
//! [`EyeBotClient`] holds what every EyeBot-side client of the bridge keeps, whatever moves its
//! bytes (an async serial port, a blocking file, a test's buffer): the sequence counter of the
//! sensor link, a [`LineDecoder`] with its input buffer, the pushes that arrived while a reply
//! was awaited, and counts of wire errors and stale replies. It never reads, writes, sleeps or
//! reads a clock; timeouts and retries (PROTOCOL.md 2.2) belong to the caller.
//!
//! ```text
//! Message ──► encode_request ──► (seq, bytes) ──► caller writes them
//! bytes read ──► receive ──► next_incoming: Reply | Push | Nmea | Sonar | Error, in order
//!                         └► take_reply(seq): the reply to seq; pushes queued, stale
//!                            replies, NMEA and sonar items skipped, errors counted
//!                         └► take_push: queued pushes first, then the line's
//! ```
//!
//! A retry resends the identical bytes (same seq), so the bridge may answer one request twice;
//! the second answer reaches the next [`take_reply`](EyeBotClient::take_reply), which skips it
//! because its seq is not the one awaited.

use std::collections::VecDeque;

use bytes::BytesMut;

use crate::error::LinkError;
use crate::line::{LineDecoder, LineItem};
use crate::nmea::Sentence;
use crate::sensor_link::{Frame, Message};
use crate::sonar_link::SonarCommand;

/// The first message type of an unsolicited push (PROTOCOL.md 2.2, 2.3); below it, a reply.
pub const FIRST_PUSH_TYPE: u8 = 0xC0;

/// Whether a frame of `msg_type` is a push (from the bridge on its own) rather than a reply.
pub fn is_push(msg_type: u8) -> bool {
    msg_type >= FIRST_PUSH_TYPE
}

/// One item the EyeBot side received, classified.
#[derive(Debug, Clone, PartialEq)]
pub enum Incoming {
    /// A frame of a type below [`FIRST_PUSH_TYPE`]: the answer to the request with its seq.
    Reply(Frame),
    /// A frame of a type from [`FIRST_PUSH_TYPE`] on; its seq is the bridge's push counter.
    Push(Frame),
    /// An NMEA sentence (the sonar link, or a shared line).
    Nmea(Sentence),
    /// A sonar command or acknowledgement (the sonar link, or a shared line).
    Sonar(SonarCommand),
    /// Bad bytes, already counted in [`EyeBotClient::errors`].
    Error(LinkError),
}

impl From<LineItem> for Incoming {
    fn from(item: LineItem) -> Self {
        match item {
            LineItem::Frame(frame) if is_push(frame.message.msg_type()) => Self::Push(frame),
            LineItem::Frame(frame) => Self::Reply(frame),
            LineItem::Nmea(sentence) => Self::Nmea(sentence),
            LineItem::Sonar(command) => Self::Sonar(command),
            LineItem::Error(error) => Self::Error(error),
        }
    }
}

impl From<Incoming> for LineItem {
    fn from(item: Incoming) -> Self {
        match item {
            Incoming::Reply(frame) | Incoming::Push(frame) => Self::Frame(frame),
            Incoming::Nmea(sentence) => Self::Nmea(sentence),
            Incoming::Sonar(command) => Self::Sonar(command),
            Incoming::Error(error) => Self::Error(error),
        }
    }
}

/// The EyeBot side of a sensor, sonar or shared line, without I/O.
#[derive(Debug, Clone, Default)]
pub struct EyeBotClient {
    decoder: LineDecoder,
    buf: BytesMut,
    next_seq: u8,
    pushes: VecDeque<Frame>,
    errors: u64,
    stale_replies: u64,
    /// Whether a whole item has been decoded yet.
    started: bool,
    joined_tail: usize,
}

impl EyeBotClient {
    /// A client whose first request is seq 0.
    pub fn new() -> Self {
        Self::default()
    }

    /// A client whose first request is seq `first_seq`. A new process that must not repeat
    /// its predecessor's last (seq, request) starts elsewhere than 0: the bridge answers a
    /// request identical to the last one from its stored reply without executing it.
    pub fn with_first_seq(first_seq: u8) -> Self {
        Self {
            next_seq: first_seq,
            ..Self::default()
        }
    }

    /// The seq the next [`encode_request`](Self::encode_request) uses.
    pub fn next_seq(&self) -> u8 {
        self.next_seq
    }

    /// Appends `message` as a new request to `dst` and returns its seq; the counter moves on
    /// (wrapping). To retry, send the same bytes again.
    pub fn encode_request(&mut self, message: Message, dst: &mut BytesMut) -> u8 {
        let seq = self.next_seq;
        self.encode_request_as(seq, message, dst);
        seq
    }

    /// Appends `message` as a request with the caller's `seq` to `dst` (a test that sends
    /// given seqs); the next [`encode_request`](Self::encode_request) uses `seq + 1`.
    pub fn encode_request_as(&mut self, seq: u8, message: Message, dst: &mut BytesMut) {
        Frame::new(seq, message).encode(dst);
        self.next_seq = seq.wrapping_add(1);
    }

    /// Hands over bytes received from the line, in order.
    pub fn receive(&mut self, bytes: &[u8]) {
        self.buf.extend_from_slice(bytes);
    }

    /// The next item on the line in arrival order, or `None` until more bytes are received.
    /// Pushes queued by [`take_reply`](Self::take_reply) are not among them: they wait for
    /// [`take_push`](Self::take_push).
    ///
    /// Bytes skipped before the first whole item are the tail of a message the line was
    /// already sending when the client joined it (a sonar line carries sentences all the
    /// time): they are counted in [`joined_tail`](Self::joined_tail), not as a wire error.
    pub fn next_incoming(&mut self) -> Option<Incoming> {
        loop {
            let item = Incoming::from(self.decoder.decode(&mut self.buf)?);
            if let Some(item) = self.classify(item) {
                return Some(item);
            }
        }
    }

    /// Counts `item`; `None` for the tail of a message joined in the middle.
    fn classify(&mut self, item: Incoming) -> Option<Incoming> {
        match item {
            Incoming::Error(LinkError::Skipped { count }) if !self.started => {
                self.joined_tail += count;
                None
            }
            Incoming::Error(_) => {
                self.errors += 1;
                Some(item)
            }
            _ => {
                self.started = true;
                Some(item)
            }
        }
    }

    /// Like [`next_incoming`](Self::next_incoming), with the bytes the item was decoded from
    /// (the text of a sentence, for a person to read).
    pub fn next_incoming_with_bytes(&mut self) -> Option<(Incoming, BytesMut)> {
        loop {
            let d = self.decoder.decode_slice(&self.buf);
            let bytes = self.buf.split_to(d.consumed);
            if let Some(item) = self.classify(Incoming::from(d.item?)) {
                return Some((item, bytes));
            }
        }
    }

    /// The reply to the request `seq`, once it has been received: `Some(Ok(message))`, a NAK
    /// included. Pushes before it are queued for [`take_push`](Self::take_push); replies to
    /// other seqs (a late answer to a retried request) are skipped and counted in
    /// [`stale_replies`](Self::stale_replies); NMEA and sonar items are skipped. A wire error
    /// is counted and returned as `Some(Err(_))`; call again to go on waiting. `None`: not yet.
    pub fn take_reply(&mut self, seq: u8) -> Option<Result<Message, LinkError>> {
        loop {
            match self.next_incoming()? {
                Incoming::Reply(frame) if frame.seq == seq => return Some(Ok(frame.message)),
                Incoming::Reply(_) => self.stale_replies += 1,
                Incoming::Push(frame) => self.pushes.push_back(frame),
                Incoming::Nmea(_) | Incoming::Sonar(_) => {}
                Incoming::Error(error) => return Some(Err(error)),
            }
        }
    }

    /// The next push: those queued while a reply was awaited first, then the line's. Replies
    /// (no request is awaited) are skipped and counted in
    /// [`stale_replies`](Self::stale_replies); NMEA and sonar items are skipped. A wire error
    /// is counted and returned as `Some(Err(_))`. `None`: not yet.
    pub fn take_push(&mut self) -> Option<Result<Frame, LinkError>> {
        if let Some(frame) = self.pushes.pop_front() {
            return Some(Ok(frame));
        }
        loop {
            match self.next_incoming()? {
                Incoming::Push(frame) => return Some(Ok(frame)),
                Incoming::Reply(_) => self.stale_replies += 1,
                Incoming::Nmea(_) | Incoming::Sonar(_) => {}
                Incoming::Error(error) => return Some(Err(error)),
            }
        }
    }

    /// Wire errors seen in what was received (bad bytes from the bridge).
    pub fn errors(&self) -> u64 {
        self.errors
    }

    /// Replies skipped because no request with their seq was awaited.
    pub fn stale_replies(&self) -> u64 {
        self.stale_replies
    }

    /// Bytes skipped before the first whole item: the tail of a message joined mid-way.
    pub fn joined_tail(&self) -> usize {
        self.joined_tail
    }
}

#[cfg(test)]
mod tests;

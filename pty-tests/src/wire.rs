//! A bare EyeBot-side client for tests that speak the wire protocols byte by byte: writes
//! exactly the bytes given, and decodes and classifies what comes back with the protocol's own
//! client core, [`EyeBotClient`] (a blocking I/O shell over it, as `probe` is an async one).
//!
//! Unlike `probe`'s clients it never retries, never reframes and never hides an unexpected
//! item, so a test sees every byte the bridge sent, in order.

use std::fs::File;
use std::io::{Read, Write};
use std::os::fd::AsFd;
use std::path::Path;
use std::time::{Duration, Instant};

use bytes::BytesMut;
use firmware_protocol::sensor_link::{Counters, Message};
use firmware_protocol::{EyeBotClient, Frame, Incoming, LineItem};

/// One end of a link, opened as a plain C program would (raw file, blocking writes).
pub struct Wire {
    file: File,
    client: EyeBotClient,
    /// Every byte read so far, in order.
    pub received: Vec<u8>,
}

/// How long [`Wire::reply`] waits for a reply.
pub const REPLY_WAIT: Duration = Duration::from_secs(10);

impl Wire {
    pub fn open(path: &Path) -> Self {
        Self {
            file: eyebot_test_support::clients::open_raw(path),
            client: EyeBotClient::new(),
            received: Vec::new(),
        }
    }

    /// Writes `bytes` whole.
    pub fn send(&mut self, bytes: &[u8]) {
        self.file.write_all(bytes).expect("write to the link");
    }

    /// Encodes and writes a request frame.
    pub fn request(&mut self, seq: u8, message: Message) {
        let mut b = BytesMut::new();
        self.client.encode_request_as(seq, message, &mut b);
        self.send(&b);
    }

    /// Reads what arrives within `wait` (polling); `false` if nothing did.
    fn fill(&mut self, wait: Duration) -> bool {
        let timeout = nix::poll::PollTimeout::from(wait.as_millis().min(60_000) as u16);
        let mut fds = [nix::poll::PollFd::new(
            self.file.as_fd(),
            nix::poll::PollFlags::POLLIN,
        )];
        match nix::poll::poll(&mut fds, timeout) {
            Ok(n) if n > 0 => {
                let mut chunk = [0u8; 4096];
                match (&self.file).read(&mut chunk) {
                    Ok(n) if n > 0 => {
                        self.client.receive(&chunk[..n]);
                        self.received.extend_from_slice(&chunk[..n]);
                        true
                    }
                    _ => false,
                }
            }
            _ => false,
        }
    }

    /// The next decoded item, waiting at most `timeout` for it.
    pub fn next_item(&mut self, timeout: Duration) -> Option<LineItem> {
        self.next_incoming(timeout).map(LineItem::from)
    }

    /// The next decoded item, classified (reply, push, ...), waiting at most `timeout`.
    pub fn next_incoming(&mut self, timeout: Duration) -> Option<Incoming> {
        let deadline = Instant::now() + timeout;
        loop {
            if let Some(item) = self.client.next_incoming() {
                return Some(item);
            }
            let left = deadline.saturating_duration_since(Instant::now());
            if left.is_zero() {
                return None;
            }
            self.fill(left);
        }
    }

    /// The next frame, skipping NMEA sentences (a sonar line's depth readings); panics with
    /// `what` if none arrives within `timeout` or something else does.
    pub fn next_frame(&mut self, what: &str, timeout: Duration) -> Frame {
        loop {
            match self.next_item(timeout) {
                Some(LineItem::Frame(frame)) => return frame,
                Some(LineItem::Nmea(_)) => continue,
                other => panic!("{what}: expected a frame, got {other:?}"),
            }
        }
    }

    /// The next frame that is not a push (types `0xC0` and up), within [`REPLY_WAIT`]; it must
    /// carry `seq`. `what` names the request in a failure.
    pub fn reply(&mut self, seq: u8, what: &str) -> Message {
        self.reply_and_pushes(seq, what).0
    }

    /// Like [`reply`](Self::reply), with the pushes that came before the reply, in order.
    pub fn reply_and_pushes(&mut self, seq: u8, what: &str) -> (Message, Vec<Frame>) {
        let mut pushes = Vec::new();
        loop {
            match self.next_incoming(REPLY_WAIT) {
                Some(Incoming::Push(frame)) => pushes.push(frame),
                Some(Incoming::Nmea(_)) => {}
                Some(Incoming::Reply(frame)) => {
                    assert_eq!(frame.seq, seq, "{what}: reply seq");
                    return (frame.message, pushes);
                }
                other => panic!("{what}: expected a frame, got {other:?}"),
            }
        }
    }

    /// Sends `message` as frame `seq` and returns its reply (pushes and NMEA skipped).
    pub fn ask(&mut self, seq: u8, message: Message) -> Message {
        self.request(seq, message);
        self.reply(seq, &format!("{message:?}"))
    }

    /// The bridge's counters (COUNTERS_GET as frame `seq`).
    pub fn counters(&mut self, seq: u8) -> Counters {
        match self.ask(seq, Message::CountersGet) {
            Message::Counters(c) => c,
            other => panic!("COUNTERS_GET answered {other:?}"),
        }
    }

    /// The next item that is not an NMEA sentence, within `timeout`.
    pub fn next_non_nmea(&mut self, timeout: Duration) -> Option<LineItem> {
        loop {
            match self.next_item(timeout) {
                Some(LineItem::Nmea(_)) => continue,
                other => return other,
            }
        }
    }

    /// Waits `quiet` and returns every item that arrived meanwhile (NMEA included).
    pub fn drain(&mut self, quiet: Duration) -> Vec<LineItem> {
        let mut items = Vec::new();
        while let Some(item) = self.next_item(quiet) {
            items.push(item);
        }
        items
    }
}

/// The bytes of a frame.
pub fn frame_bytes(seq: u8, message: Message) -> Vec<u8> {
    let mut b = BytesMut::new();
    Frame::new(seq, message).encode(&mut b);
    b.to_vec()
}

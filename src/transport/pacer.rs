//! The wire as a clock: outgoing bytes take their real time on the line.
//!
//! Sans-IO. A reply queued at simulated time `t` on a 4800 baud line starts when the line is
//! free and each byte is complete one character time after the previous one. The daemon
//! releases a byte to the port only when simulated time has reached its completion, so a
//! control program sees the timing of the real line whether the port is a UART or a pty, and
//! in lockstep mode the bytes it sees after each time step are fixed by simulated time alone.

use std::collections::VecDeque;

use bytes::{Buf, Bytes};

use super::LineSettings;

use crate::SimNanos;

#[derive(Debug)]
struct Chunk {
    /// When the first byte's start bit begins.
    start_ns: SimNanos,
    data: Bytes,
}

/// The queue of one direction of one line: bytes scheduled, not yet complete.
#[derive(Debug)]
pub struct WirePacer {
    char_ns: u64,
    /// When the line finishes the last scheduled byte.
    free_at_ns: SimNanos,
    queue: VecDeque<Chunk>,
    queued_bytes: usize,
    max_queued_bytes: usize,
    dropped_bytes: u64,
}

/// A chunk did not fit: the line is that far behind.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("transmit queue full ({queued} bytes waiting, limit {limit}); {dropped} bytes dropped")]
pub struct QueueFull {
    pub queued: usize,
    pub limit: usize,
    pub dropped: usize,
}

impl WirePacer {
    /// A pacer for `line`, holding at most `max_queued_bytes` not yet on the wire.
    pub fn new(line: &LineSettings, max_queued_bytes: usize) -> Self {
        Self {
            char_ns: line.char_time_ns(),
            free_at_ns: 0,
            queue: VecDeque::new(),
            queued_bytes: 0,
            max_queued_bytes,
            dropped_bytes: 0,
        }
    }

    /// Nanoseconds per character on this line.
    pub fn char_ns(&self) -> u64 {
        self.char_ns
    }

    /// Schedules `data`, handed to the UART at `now_ns`. Returns the completion time of its
    /// last byte. A chunk that would overflow the queue is dropped whole and counted: a
    /// sender outrunning its line loses data on a real UART too, and a partial frame would be
    /// worse than none.
    pub fn push(&mut self, now_ns: SimNanos, data: Bytes) -> Result<SimNanos, QueueFull> {
        if data.is_empty() {
            return Ok(self.free_at_ns.max(now_ns));
        }
        if self.queued_bytes + data.len() > self.max_queued_bytes {
            self.dropped_bytes += data.len() as u64;
            return Err(QueueFull {
                queued: self.queued_bytes,
                limit: self.max_queued_bytes,
                dropped: data.len(),
            });
        }
        let start_ns = self.free_at_ns.max(now_ns);
        self.free_at_ns = start_ns + self.char_ns * data.len() as u64;
        self.queued_bytes += data.len();
        self.queue.push_back(Chunk { start_ns, data });
        Ok(self.free_at_ns)
    }

    /// Moves every byte complete by `now_ns` into `out`, in order.
    pub fn release(&mut self, now_ns: SimNanos, out: &mut Vec<u8>) {
        while let Some(chunk) = self.queue.front_mut() {
            if now_ns < chunk.start_ns + self.char_ns {
                break;
            }
            let complete = ((now_ns - chunk.start_ns) / self.char_ns) as usize;
            let n = complete.min(chunk.data.len());
            out.extend_from_slice(&chunk.data[..n]);
            self.queued_bytes -= n;
            if n == chunk.data.len() {
                self.queue.pop_front();
            } else {
                chunk.data.advance(n);
                chunk.start_ns += self.char_ns * n as u64;
                break;
            }
        }
    }

    /// When the next byte completes, if any is queued.
    pub fn next_release_ns(&self) -> Option<SimNanos> {
        self.queue.front().map(|c| c.start_ns + self.char_ns)
    }

    /// Bytes scheduled but not yet complete.
    pub fn queued_bytes(&self) -> usize {
        self.queued_bytes
    }

    /// Bytes dropped because the queue was full.
    pub fn dropped_bytes(&self) -> u64 {
        self.dropped_bytes
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    fn nmea_line() -> WirePacer {
        WirePacer::new(&LineSettings::n81(4800), 4096)
    }

    #[test]
    fn a_sentence_takes_its_wire_time() {
        let mut p = nmea_line();
        let sentence = Bytes::from_static(b"$SDDBT,6.6,f,2.0,M,1.1,F*3A\r\n");
        let end = p.push(1_000_000_000, sentence.clone()).unwrap();
        // 29 characters at 480 characters per second.
        assert_eq!(end, 1_000_000_000 + 29 * p.char_ns());
        let mut out = Vec::new();
        p.release(1_000_000_000 + p.char_ns() - 1, &mut out);
        assert!(
            out.is_empty(),
            "no byte is complete before one character time"
        );
        p.release(1_000_000_000 + 10 * p.char_ns(), &mut out);
        assert_eq!(out, &sentence[..10]);
        p.release(end, &mut out);
        assert_eq!(out, sentence);
        assert_eq!(p.next_release_ns(), None);
    }

    #[test]
    fn back_to_back_chunks_queue_behind_each_other() {
        let mut p = nmea_line();
        let first_end = p.push(0, Bytes::from_static(b"abc")).unwrap();
        let second_end = p.push(0, Bytes::from_static(b"de")).unwrap();
        assert_eq!(second_end, first_end + 2 * p.char_ns());
        // A chunk pushed after the line went idle starts at its push time.
        let mut out = Vec::new();
        p.release(second_end, &mut out);
        let third_end = p
            .push(second_end + 1_000, Bytes::from_static(b"f"))
            .unwrap();
        assert_eq!(third_end, second_end + 1_000 + p.char_ns());
    }

    #[test]
    fn overflow_drops_whole_chunks_and_counts_them() {
        let mut p = WirePacer::new(&LineSettings::n81(4800), 8);
        p.push(0, Bytes::from_static(b"12345")).unwrap();
        let err = p.push(0, Bytes::from_static(b"6789")).unwrap_err();
        assert_eq!(err.dropped, 4);
        assert_eq!(p.dropped_bytes(), 4);
        assert_eq!(p.queued_bytes(), 5);
    }

    proptest! {
        /// However releases are interleaved, the bytes come out complete, in order, and never
        /// before their completion time.
        #[test]
        fn releases_preserve_order_and_timing(
            chunks in proptest::collection::vec((0u64..50_000_000, proptest::collection::vec(any::<u8>(), 1..40)), 1..20),
            polls in proptest::collection::vec(0u64..20_000_000, 1..60),
        ) {
            let mut p = WirePacer::new(&LineSettings::n81(115_200), 1 << 20);
            let mut now = 0u64;
            let mut sent = Vec::new();
            let mut got = Vec::new();
            for (gap, data) in &chunks {
                now += gap;
                let mut out = Vec::new();
                p.release(now, &mut out);
                got.extend(out);
                p.push(now, Bytes::from(data.clone())).unwrap();
                sent.extend_from_slice(data);
            }
            for step in &polls {
                now += step;
                let before = got.len();
                let mut out = Vec::new();
                p.release(now, &mut out);
                got.extend(out);
                // Bytes on the wire never outrun the line rate.
                prop_assert!(((got.len() - before) as u64) <= now / p.char_ns() + 1);
            }
            p.release(u64::MAX / 2, &mut got);
            prop_assert_eq!(got, sent);
        }
    }
}

//! The wire as a clock: outgoing bytes take their real time on the line.
//!
//! Sans-IO. A reply queued at simulated time `t` on a 4800 baud line starts when the line is
//! free and each byte is complete one character time after the previous one. The daemon
//! releases a byte to the port only when simulated time has reached its completion, so a
//! control program sees the timing of the real line whether the port is a UART or a pty, and
//! in lockstep mode the bytes it sees after each time step are fixed by simulated time alone.
//!
//! **Release quantum.** Which bytes are complete at a given time is fixed by the line rate
//! alone; the quantum only says how often the daemon needs to wake to hand them over. A
//! byte-by-byte wake-up costs one timer, one wake and one `write` per character (2,800 a
//! second for a 100 Hz stream of 28-byte frames at 115200 baud). Instead,
//! [`WirePacer::next_release_ns`] names the completion time of the *last* queued byte that
//! completes within one quantum of the *first* not-yet-released byte, so bytes leave in
//! bursts, like a UART receive FIFO read out by an interrupt, with these guarantees:
//!
//! - no byte is handed over before its own completion time (the wire schedule at
//!   10 bits per byte for 8N1 is never beaten);
//! - no byte waits more than one quantum after its completion time;
//! - the last byte of a burst, and so the last byte of every reply the client waits for, is
//!   handed over exactly at its completion time (a whole reply shorter than a quantum arrives
//!   at once, at the moment its last bit would have left the real line);
//! - on a line slower than the quantum (4800 baud: 2.08 ms per character against 1 ms)
//!   every byte is still handed over on its own, at its own time.
//!
//! Releases at any other moment (the daemon woke for another reason) still hand over exactly
//! the bytes complete by then, so the simulated-time side, and every lockstep transcript, is
//! unaffected by the quantum.

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
    /// Longest a complete byte may wait for its hand-over (see the module doc).
    quantum_ns: u64,
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
    /// A pacer for `line`, holding at most `max_queued_bytes` not yet on the wire, that
    /// releases byte by byte (quantum 0; see [`Self::with_quantum`]).
    pub fn new(line: &LineSettings, max_queued_bytes: usize) -> Self {
        Self {
            char_ns: line.char_time_ns(),
            quantum_ns: 0,
            free_at_ns: 0,
            queue: VecDeque::new(),
            queued_bytes: 0,
            max_queued_bytes,
            dropped_bytes: 0,
        }
    }

    /// Releases in bursts of at most `quantum_ns` (module doc); 0 releases byte by byte.
    pub fn with_quantum(mut self, quantum_ns: u64) -> Self {
        self.quantum_ns = quantum_ns;
        self
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
    pub fn next_completion_ns(&self) -> Option<SimNanos> {
        self.queue.front().map(|c| c.start_ns + self.char_ns)
    }

    /// When the daemon should next hand bytes over: the completion time of the last queued
    /// byte that completes within one quantum of the next byte's completion (module doc).
    pub fn next_release_ns(&self) -> Option<SimNanos> {
        let first = self.next_completion_ns()?;
        let horizon = first.saturating_add(self.quantum_ns);
        let mut last = first;
        for chunk in &self.queue {
            let first_of_chunk = chunk.start_ns + self.char_ns;
            if first_of_chunk > horizon {
                break;
            }
            let whole = ((horizon - chunk.start_ns) / self.char_ns).min(chunk.data.len() as u64);
            last = last.max(chunk.start_ns + whole * self.char_ns);
        }
        Some(last)
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

    const MS: u64 = 1_000_000;

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

    /// At 115200 baud (86.8 us per character) a 1 ms quantum releases 12 characters per
    /// wake: the first 955 us after its completion, the last exactly on time.
    #[test]
    fn a_quantum_groups_bytes_without_releasing_any_early() {
        let line = LineSettings::n81(115_200);
        let mut p = WirePacer::new(&line, 4096).with_quantum(MS);
        let c = p.char_ns();
        let frame = Bytes::from(vec![0xA5; 28]);
        let end = p.push(0, frame.clone()).unwrap();
        let mut released = Vec::new();
        let mut wakes = Vec::new();
        while let Some(at) = p.next_release_ns() {
            let mut out = Vec::new();
            p.release(at, &mut out);
            assert!(!out.is_empty(), "every wake hands over bytes");
            wakes.push((at, out.len()));
            released.extend(out);
        }
        assert_eq!(released, frame);
        assert_eq!(
            wakes.len(),
            3,
            "28 characters of 86.8 us in 1 ms groups: {wakes:?}"
        );
        assert_eq!(wakes[0], (12 * c, 12));
        assert_eq!(
            wakes.last().unwrap().0,
            end,
            "the frame's last byte on time"
        );
        // Every byte: handed over at or after its completion, at most one quantum later.
        let mut k = 0u64;
        for (at, n) in wakes {
            for _ in 0..n {
                k += 1;
                assert!(at >= k * c && at - k * c <= MS, "byte {k} at {at}");
            }
        }
    }

    /// A reply shorter than a quantum goes in one piece when its last byte completes.
    #[test]
    fn a_short_reply_is_handed_over_whole_at_its_completion() {
        let mut p = WirePacer::new(&LineSettings::n81(115_200), 4096).with_quantum(MS);
        let end = p.push(5 * MS, Bytes::from(vec![0; 10])).unwrap();
        assert_eq!(p.next_release_ns(), Some(end));
        // A second chunk queued behind it within the quantum joins the burst.
        let end2 = p.push(5 * MS, Bytes::from(vec![1; 2])).unwrap();
        assert_eq!(p.next_release_ns(), Some(end2));
    }

    /// A line slower than the quantum still releases byte by byte, each on time.
    #[test]
    fn a_slow_line_releases_each_byte_at_its_own_time() {
        let mut p = WirePacer::new(&LineSettings::n81(4800), 4096).with_quantum(MS);
        let c = p.char_ns();
        p.push(0, Bytes::from_static(b"$SDDBT")).unwrap();
        assert_eq!(p.next_release_ns(), Some(c));
        let mut out = Vec::new();
        p.release(c, &mut out);
        assert_eq!(out, b"$");
        assert_eq!(p.next_release_ns(), Some(2 * c));
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
            let mut p = WirePacer::new(&LineSettings::n81(115_200), 1 << 20).with_quantum(MS);
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
                // A wake at the announced release time hands over at least one byte, and
                // it is never earlier than the next byte's completion.
                if let (Some(next), Some(first)) = (p.next_release_ns(), p.next_completion_ns()) {
                    prop_assert!(next >= first && next <= first + MS);
                }
            }
            p.release(u64::MAX / 2, &mut got);
            prop_assert_eq!(got, sent);
        }
    }
}

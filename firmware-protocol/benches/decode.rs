//! Decode throughput for NMEA framing + checksum and for binary frames, each next to a
//! baseline measured in the same run over the same buffer.
//!
//! Run: `cargo bench -p firmware-protocol --bench decode`
//!
//! Baseline: a plain byte-at-a-time pass over the same buffer that XORs bytes and splits at
//! LF (no memchr, no validation): the least any NMEA framing + checksum can do. Each figure is the best of several passes over an 8 MiB buffer,
//! single-threaded. Results go into docs/performance.md ("Wire protocols").

use std::hint::black_box;
use std::time::{Duration, Instant};

use bytes::BytesMut;
use firmware_protocol::nmea::{self, LineScan};
use firmware_protocol::sensor_link::{AdcChannel, AdcSamples, AdcValue, Message};
use firmware_protocol::{Dbt, Frame, LineDecoder, LineItem, Sentence, Talker};

const TARGET_BYTES: usize = 8 << 20;
const PASSES: usize = 7;

/// Best (shortest) time of `PASSES` runs of `f`, and the value of the last run.
fn best_of<T>(mut f: impl FnMut() -> T) -> (Duration, T) {
    let mut best = Duration::MAX;
    let mut last = None;
    for _ in 0..PASSES {
        let start = Instant::now();
        let v = black_box(f());
        best = best.min(start.elapsed());
        last = Some(v);
    }
    (best, last.expect("PASSES > 0"))
}

fn mb_s(bytes: usize, t: Duration) -> f64 {
    bytes as f64 / 1e6 / t.as_secs_f64()
}

fn byte_scan_baseline(buf: &[u8]) -> (usize, u8) {
    let (mut lines, mut line_xor, mut acc) = (0usize, 0u8, 0u8);
    for &b in buf {
        if b == b'\n' {
            lines += 1;
            acc ^= line_xor;
            line_xor = 0;
        } else {
            line_xor ^= b;
        }
    }
    (lines, acc)
}

fn nmea_buffer() -> Vec<u8> {
    let mut b = BytesMut::new();
    let mut i = 0u32;
    while b.len() < TARGET_BYTES {
        let depth_m = f64::from(i % 4400) / 100.0;
        Sentence::Dbt(Dbt::from_depth_m(Talker::SOUNDER, depth_m).expect("depth in range"))
            .encode(&mut b)
            .expect("encodes");
        i += 1;
    }
    b.to_vec()
}

fn frame_buffer() -> Vec<u8> {
    let mut b = BytesMut::new();
    let mut i = 0u32;
    let ch = |c| AdcChannel::new(c).expect("channel");
    let v = |x: u32| AdcValue::new((x % 1024) as u16).expect("value");
    while b.len() < TARGET_BYTES {
        let message = match i % 4 {
            0 => Message::AdcValue {
                channel: ch((i % 8) as u8),
                value: v(i),
            },
            1 => Message::AdcSamples {
                ticks: i,
                samples: AdcSamples::new([(ch(0), v(i)), (ch(2), v(i * 7)), (ch(5), v(i * 13))]),
            },
            2 => Message::TimeAdvance { ticks: i },
            _ => Message::CompassRaw {
                x: i as i16,
                y: -(i as i16),
            },
        };
        Frame::new(i as u8, message).encode(&mut b);
        i += 1;
    }
    b.to_vec()
}

/// NMEA framing (scan_line) + checksum verification, no field parsing.
fn nmea_frame_and_checksum(buf: &[u8]) -> usize {
    let mut pos = 0;
    let mut ok = 0;
    while pos < buf.len() {
        match nmea::scan_line(&buf[pos..], 0) {
            LineScan::Complete { len } => {
                if nmea::checked_body(&buf[pos..pos + len]).is_ok() {
                    ok += 1;
                }
                pos += len;
            }
            LineScan::Reject { consume, .. } => pos += consume,
            LineScan::NeedMore { .. } => break,
        }
    }
    ok
}

/// The full shared-line decoder: framing, checksum and typed decoding of every item.
fn line_decode(buf: &[u8]) -> usize {
    let mut decoder = LineDecoder::new();
    let mut pos = 0;
    let mut good = 0;
    loop {
        let d = decoder.decode_slice(&buf[pos..]);
        pos += d.consumed;
        match d.item {
            Some(LineItem::Error(_)) => {}
            Some(_) => good += 1,
            None => break,
        }
    }
    good
}

fn report(name: &str, bytes: usize, t: Duration, baseline: Duration) {
    println!(
        "{name:<44} {:>9.1} MB/s   ratio to baseline {:>6.3}",
        mb_s(bytes, t),
        baseline.as_secs_f64() / t.as_secs_f64()
    );
}

fn main() {
    let nmea_buf = nmea_buffer();
    let frames_buf = frame_buffer();
    let n_sentences = nmea_frame_and_checksum(&nmea_buf);
    let n_frames = line_decode(&frames_buf);
    assert!(n_sentences > 0 && n_frames > 0);
    assert_eq!(
        line_decode(&nmea_buf),
        n_sentences,
        "every sentence decodes"
    );

    println!(
        "NMEA buffer: {} bytes, {} DBT sentences",
        nmea_buf.len(),
        n_sentences
    );
    let (base, _) = best_of(|| byte_scan_baseline(black_box(&nmea_buf)));
    report(
        "baseline: plain byte scan (XOR, split at LF)",
        nmea_buf.len(),
        base,
        base,
    );
    let (t, n) = best_of(|| nmea_frame_and_checksum(black_box(&nmea_buf)));
    assert_eq!(n, n_sentences);
    report("NMEA framing + checksum", nmea_buf.len(), t, base);
    let (t, n) = best_of(|| line_decode(black_box(&nmea_buf)));
    assert_eq!(n, n_sentences);
    report(
        "NMEA LineDecoder (framing+checksum+fields)",
        nmea_buf.len(),
        t,
        base,
    );

    println!(
        "binary buffer: {} bytes, {} frames",
        frames_buf.len(),
        n_frames
    );
    let (base, _) = best_of(|| byte_scan_baseline(black_box(&frames_buf)));
    report(
        "baseline: plain byte scan (XOR, split at LF)",
        frames_buf.len(),
        base,
        base,
    );
    let (crc_t, _) = best_of(|| firmware_protocol::crc::crc16(black_box(&frames_buf)));
    report(
        "CRC-16 over the buffer (crc crate)",
        frames_buf.len(),
        crc_t,
        base,
    );
    let (t, n) = best_of(|| line_decode(black_box(&frames_buf)));
    assert_eq!(n, n_frames);
    report(
        "binary LineDecoder (framing+CRC+message)",
        frames_buf.len(),
        t,
        base,
    );
}

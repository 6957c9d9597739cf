//! Replay pacing at speed 1, in a test binary of its own: cargo runs test binaries one after
//! another, so no other test of ours competes for the CPU while bytes are timed.
//!
//! The default run checks behaviour: the consumer reads exactly the expected bytes, in order,
//! and no byte is written or arrives before its completion time on a 4800 baud line. How
//! close to that time the bytes come is a timing figure, and depends on the host: it is
//! checked on demand by the ignored tests, which ask for `SCHED_FIFO` and a CPU latency
//! request (run as root):
//!
//! ```sh
//! cargo test -p pty-tests --test replay_timing -- --ignored --nocapture
//! ```

use std::time::Duration;

use eyebot_hil::replay::{Options, Policy};
use eyebot_test_support::pty::concat;
use pty_tests::replay::{fixture, read_fixture, replay_to_pty};

/// What a run checks beyond the behaviour.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Bound {
    /// Order, content, and no byte before its time.
    None,
    /// Also: 99 % of the bytes handed to the kernel within 2 ms of their completion time.
    WriteP99,
    /// Also: every byte written, and every byte read by the consumer, within 2 ms.
    EveryByte,
}

/// The 10 s log at speed 1: the consumer reads exactly the expected bytes in order, and
/// none is written or read before its completion time on the 4800 baud line.
#[test]
fn replayed_bytes_keep_their_order_and_never_come_early() {
    timed_replay(Bound::None);
}

/// The replay hands 99 % of its bytes to the kernel within 2 ms of their completion time.
/// A pacing defect (drift, a timer's tick, bursts) moves the p99; a rare stall of the host
/// does not.
#[test]
#[ignore = "timing on the host: cargo test -p pty-tests --test replay_timing -- --ignored"]
fn bytes_are_written_on_schedule_at_speed_1() {
    timed_replay(Bound::WriteP99);
}

/// Every byte written, and every byte read by the consumer, within 2 ms of its completion
/// time. A host that holds the pty's delivery or the replay's wake-up for a few
/// milliseconds fails it now and then (`docs/performance.md`, "Replay").
#[test]
#[ignore = "timing on the host: cargo test -p pty-tests --test replay_timing -- --ignored"]
fn bytes_arrive_within_2_ms_of_schedule_at_speed_1() {
    timed_replay(Bound::EveryByte);
}

fn timed_replay(bound: Bound) {
    const BOUND_NS: i64 = 2_000_000;
    let expected = read_fixture("expected-fix.bin");
    let schedule: Vec<(f64, usize)> = String::from_utf8(read_fixture("expected-fix.schedule"))
        .unwrap()
        .lines()
        .map(|l| {
            let (t, n) = l.split_once('\t').unwrap();
            (t.parse().unwrap(), n.parse().unwrap())
        })
        .collect();
    assert!(
        schedule.last().unwrap().0 - schedule[0].0 >= 10.0,
        "a 10 s log"
    );
    // The oracle's wire model: 10 bits per character at 4800 baud, a sentence starts when it
    // is due or when the line is free, whichever is later.
    let char_ns = (10 * 1_000_000_000u64).div_ceil(4800) as i64;
    let mut due_per_byte = Vec::new();
    let mut free_ns = 0i64;
    let t0 = schedule[0].0;
    for (t, len) in &schedule {
        let start = free_ns.max(((t - t0) * 1e9).round() as i64);
        for k in 1..=*len as i64 {
            due_per_byte.push(start + k * char_ns);
        }
        free_ns = start + *len as i64 * char_ns;
    }
    assert_eq!(due_per_byte.len(), expected.len());

    // For the timing bounds both the replay and this consumer ask for SCHED_FIFO, and, as
    // cyclictest does, for a CPU latency of 0 us: under the default scheduler either side
    // wakes a 4 ms tick late under load, and an idle vCPU can take milliseconds to wake for
    // the kernel's pty delivery, which says nothing about the replay. `REPLAY_NO_FIFO=1` and
    // `REPLAY_NO_QOS=1` leave either request out, to measure what it is worth.
    let timed = bound != Bound::None;
    let fifo = timed && std::env::var_os("REPLAY_NO_FIFO").is_none();
    let qos = timed && std::env::var_os("REPLAY_NO_QOS").is_none();
    let mut opts = Options::new(vec![fixture("timed.log")]);
    opts.policy = Policy::Fix;
    opts.realtime_priority = fifo.then_some(10);
    opts.cpu_latency_us = qos.then_some(0);
    let out = replay_to_pty(
        opts,
        expected.len(),
        Duration::from_millis(300),
        fifo.then_some(20),
    );
    eprintln!(
        "SCHED_FIFO: consumer {}, replay {}; CPU latency request: {:?} us",
        out.realtime, out.summary.realtime, out.summary.cpu_latency_us
    );
    if qos {
        assert_eq!(
            out.summary.cpu_latency_us,
            Some(0),
            "the CPU latency request was refused (needs write access to /dev/cpu_dma_latency, \
             normally root)"
        );
    }
    if fifo {
        assert!(
            out.realtime && out.summary.realtime,
            "SCHED_FIFO was refused (needs root, CAP_SYS_NICE or an rtprio limit); the 2 ms \
             bound is only meaningful without CPU queueing"
        );
    }
    let origin = out.observed.origin.expect("the replay reports its origin");
    assert_eq!(concat(&out.reads), expected, "order and content preserved");

    // When each byte was written (from the sink's trace) and read (by the consumer).
    let mut written_per_byte = Vec::new();
    for (total, at) in &out.write_trace {
        let at = at.duration_since(origin).as_nanos() as i64;
        written_per_byte.resize(*total as usize, at);
    }
    assert_eq!(written_per_byte.len(), expected.len());
    let mut lateness = Vec::new();
    let mut delivery = Vec::new();
    let mut byte = 0usize;
    for read in &out.reads {
        let at = read.at.duration_since(origin).as_nanos() as i64;
        for _ in &read.bytes {
            lateness.push((at - due_per_byte[byte], byte));
            delivery.push(at - written_per_byte[byte]);
            byte += 1;
        }
    }
    let write_side: Vec<i64> = written_per_byte
        .iter()
        .zip(&due_per_byte)
        .map(|(w, d)| w - d)
        .collect();
    // The replay side: when the last byte of each sentence was handed to the kernel.
    let write_late: Vec<i64> = out
        .observed
        .sent
        .iter()
        .map(|(_, _, s)| {
            s.written_at.duration_since(origin).as_nanos() as i64 - s.end_ns.unwrap() as i64
        })
        .collect();
    let stats = |v: &mut Vec<i64>| {
        v.sort();
        let q = |p: f64| v[((v.len() - 1) as f64 * p) as usize];
        (q(0.0), q(0.5), q(0.99), q(1.0))
    };
    let mut l: Vec<i64> = lateness.iter().map(|(l, _)| *l).collect();
    let arrival_stats = stats(&mut l);
    let (min, _, _, max) = arrival_stats;
    print_stats(
        &format!("arrival minus schedule over {} bytes", l.len()),
        arrival_stats,
    );
    let mut w = write_late.clone();
    print_stats(
        &format!(
            "write (last byte of each sentence) minus schedule over {} sentences",
            w.len()
        ),
        stats(&mut w),
    );
    // Which sentences were late at the consumer, and how late this process wrote them.
    let mut sentence_of_byte = Vec::new();
    for (i, (_, len)) in schedule.iter().enumerate() {
        sentence_of_byte.extend(std::iter::repeat_n(i, *len));
    }
    let mut worst_per_sentence = vec![0i64; schedule.len()];
    for (late, byte) in &lateness {
        let i = sentence_of_byte[*byte];
        worst_per_sentence[i] = worst_per_sentence[i].max(*late);
    }
    for (i, worst) in worst_per_sentence.iter().enumerate() {
        if *worst > BOUND_NS {
            eprintln!(
                "sentence {i} (log t = {:.3} s): consumer saw a byte {:.3} ms late; this process wrote its bytes at most {:.3} ms late, longest write() call {:.3} ms",
                schedule[i].0,
                *worst as f64 * 1e-6,
                out.observed.sent[i].2.write_late_max_ns as f64 * 1e-6,
                out.observed.sent[i].2.write_call_max_ns as f64 * 1e-6
            );
        }
    }
    let write_worst = write_side.iter().copied().max().unwrap_or(0).max(0) as u64;
    let write_min = write_side.iter().copied().min().unwrap_or(0);
    let mut d = delivery.clone();
    let delivery_stats = stats(&mut d);
    eprintln!(
        "write minus schedule, every byte: min {:.3} ms, max {:.3} ms",
        write_min as f64 * 1e-6,
        write_worst as f64 * 1e-6
    );
    print_stats(
        "kernel pty delivery (read minus write), every byte",
        delivery_stats,
    );
    for (late, byte) in lateness.iter().filter(|(l, _)| *l > BOUND_NS) {
        eprintln!(
            "byte {byte}: {:.3} ms late at the consumer = written {:.3} ms late + {:.3} ms in the kernel",
            *late as f64 * 1e-6,
            write_side[*byte] as f64 * 1e-6,
            delivery[*byte] as f64 * 1e-6
        );
    }
    assert!(
        write_min >= 0,
        "the replay wrote a byte {:.3} ms before its completion time",
        -write_min as f64 * 1e-6
    );
    // This process's part: bytes handed to the kernel within 2 ms of their completion time.
    let mut w = write_side.clone();
    let (_, _, write_p99, _) = stats(&mut w);
    assert!(
        bound == Bound::None || write_p99 <= BOUND_NS,
        "the replay itself wrote 1 % of its bytes more than {:.3} ms after their completion time",
        write_p99 as f64 * 1e-6
    );
    assert!(
        bound != Bound::EveryByte || write_worst <= BOUND_NS as u64,
        "the replay itself wrote a byte {:.3} ms after its completion time",
        write_worst as f64 * 1e-6
    );
    assert!(
        min >= 0,
        "a byte arrived {:.3} ms before its wire completion time",
        -min as f64 * 1e-6
    );
    // The consumer's view. If this fails while the write side above passed, the delay was in
    // the kernel's pty delivery (flush_to_ldisc runs in an ordinary-priority kworker, which
    // waits behind other processes when the CPUs are saturated): see docs/performance.md.
    let late: Vec<&(i64, usize)> = lateness.iter().filter(|(l, _)| *l > BOUND_NS).collect();
    if bound != Bound::EveryByte {
        return;
    }
    assert!(
        late.is_empty(),
        "{} of {} bytes arrived more than 2 ms late, worst {:.3} ms, although this process wrote every byte within {:.3} ms of its time: kernel pty delivery was delayed (CPU saturated?)",
        late.len(),
        lateness.len(),
        max as f64 * 1e-6,
        write_worst as f64 * 1e-6
    );
}

/// Prints `what`: the minimum, median, 99th percentile and maximum, given in ns, in ms.
fn print_stats(what: &str, (min, p50, p99, max): (i64, i64, i64, i64)) {
    let ms = |ns: i64| ns as f64 * 1e-6;
    eprintln!(
        "{what}: min {:.3} ms, p50 {:.3} ms, p99 {:.3} ms, max {:.3} ms",
        ms(min),
        ms(p50),
        ms(p99),
        ms(max)
    );
}

#!/usr/bin/env python3
"""Where a slow ADC read's time went: an ftrace of the daemon bench's `adc` section.

Runs `cargo bench -p pty-tests --bench daemon -- adc` with EYEBOT_BENCH_OUTLIERS_US set to
THRESHOLD_US (default 200) and the scheduler and workqueue trace events on (the events and
tracing set-up of `trace_pty_delivery.py`), then prints a timeline for every read the bench
reports as slower than that, from the client's `write` of the request (time 0):

    request delivered    the kernel's flush_to_ldisc work for the request starts
    reply written        eyebot-hil queues flush_to_ldisc for its write of the reply's last
                         byte; the gap before it, less the reply's 868.1 us of wire time, is
                         the daemon's part (its wake-up for the request, its work, and its
                         timer wake-up for the hand-over)
    reply delivered      that work starts
    client ran           the bench's client thread is switched in after that

For the longest gap of each read it names the tasks on the CPUs meanwhile.

The binary measured and the scheduler settings of the run come from the environment, as for
the bench (EYEBOT_HIL_BIN, EYEBOT_BENCH_CPU_LATENCY_US, EYEBOT_BENCH_RT_PRIORITY). Needs root
and tracefs at /sys/kernel/tracing; leaves tracing off and the event list empty.

    cargo build --release --bin eyebot-hil
    sudo EYEBOT_HIL_BIN=target/release/eyebot-hil EYEBOT_BENCH_CPU_LATENCY_US=0 \\
        EYEBOT_BENCH_RT_PRIORITY=10 python3 pty-tests/diagnostics/trace_daemon_adc.py [THRESHOLD_US]
"""
import os
import re
import subprocess
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from trace_pty_delivery import TRACING, nice_of, start_tracing, take_events, write  # noqa: E402

DAEMON = "eyebot-hil"
# The daemon's threads (its main thread and the recording writer).
OURS = {DAEMON, "recorder"}
WIRE_S = 10 * 10 / 115200


def first(events, after, pred):
    return next((e for e in events if e["ts"] >= after and pred(e)), None)


def switched_in(comm):
    return lambda e: e["event"] == "sched_switch" and ("next_comm=%s " % comm) in e["rest"]


def flush_by(comm):
    return lambda e: (e["event"] == "workqueue_queue_work" and "flush_to_ldisc" in e["rest"]
                      and e["task"].strip() == comm)


def started(queued):
    work = re.search(r"work struct=?(\S+)", queued["rest"]).group(1)
    return lambda e: e["event"] == "workqueue_execute_start" and work in e["rest"]


def holders(events, start, end):
    """Per CPU: the task running at `start`, then every task switched in up to `end`."""
    held = {}
    for e in events:
        if e["event"] != "sched_switch" or e["ts"] > end:
            continue
        nxt = re.search(r"next_comm=(.+?) next_pid=(\d+)", e["rest"])
        task = (nxt.group(1), nxt.group(2))
        if e["ts"] <= start:
            held[e["cpu"]] = [task]
        else:
            held.setdefault(e["cpu"], []).append(task)
    return held


def main():
    threshold_us = float(sys.argv[1]) if len(sys.argv) > 1 else 200.0
    if not os.path.isdir(os.path.join(TRACING, "events")):
        sys.exit("tracefs is not mounted at %s (mount -t tracefs nodev %s)" % (TRACING, TRACING))
    env = dict(os.environ, EYEBOT_BENCH_OUTLIERS_US=str(threshold_us))
    start_tracing(60000)
    try:
        out = subprocess.run(
            ["cargo", "bench", "-p", "pty-tests", "--bench", "daemon", "--", "adc"],
            check=True, capture_output=True, text=True, env=env,
        ).stdout
    finally:
        write("tracing_on", "0")
    events = take_events()
    print(out, end="")
    client = next((e["task"].strip() for e in events
                   if e["event"] == "workqueue_queue_work" and "flush_to_ldisc" in e["rest"]
                   and e["task"].strip().startswith("daemon-")), None)
    outliers = [(float(m.group(1)), float(m.group(2))) for m in
                re.finditer(r"outlier: request sent at (\d+\.\d+) s \(monotonic\), (\d+\.\d+) us", out)]
    print("\n%d slow reads traced (client thread `%s`)" % (len(outliers), client))
    # (longest step, foreign tasks that held a CPU during it) per fully traced read.
    tally = {}
    for sent, over_us in outliers:
        end = sent + WIRE_S + over_us * 1e-6 + 2e-4
        window = [e for e in events if sent - 1e-5 <= e["ts"] <= end]
        steps = [("request written", {"ts": sent})]
        req = first(window, sent - 1e-5, flush_by(client))
        if req is None:
            print("\nread sent at %.6f: no request flush in the trace (buffer overrun?)" % sent)
            continue
        got = first(window, req["ts"], started(req))
        # The write of the reply's last byte: less than one character (86.8 us) before its end.
        rep = got and first(window, got["ts"] + WIRE_S - 40e-6, flush_by(DAEMON))
        dlv = rep and first(window, rep["ts"], started(rep))
        back = dlv and first(window, dlv["ts"], switched_in(client))
        for name, e in [("request delivered", got), ("reply written", rep),
                        ("reply delivered", dlv), ("client ran", back)]:
            if e is None:
                break
            steps.append((name, e))
        print("\nread sent at %.6f, %.1f us over the wire time:" % (sent, over_us))
        for (name, e), (_, prev) in zip(steps[1:], steps):
            note = "  (after the 868.1 us wire time)" if name == "reply written" else ""
            gap = e["ts"] - prev["ts"] - (WIRE_S if name == "reply written" else 0)
            print("  %-18s +%8.1f us  (%+7.1f us)%s" % (name, (e["ts"] - sent) * 1e6, gap * 1e6, note))
        if len(steps) < 5:
            print("  (the rest is not in the trace window)")
            continue
        gaps = [(steps[i + 1][1]["ts"] - steps[i][1]["ts"] - (WIRE_S if steps[i + 1][0] == "reply written" else 0),
                 steps[i][1]["ts"], steps[i + 1][1]["ts"], steps[i + 1][0]) for i in range(len(steps) - 1)]
        gap, a, b, name = max(gaps)
        print("  longest: before %s, %.1f us; tasks on the CPUs meanwhile:" % (name, gap * 1e6))
        foreign = set()
        for cpu, tasks in sorted(holders(events, b - gap, b).items()):
            names = ", ".join("%s (pid %s, %s)" % (c, p, "idle" if p == "0" else nice_of(p))
                              for c, p in dict.fromkeys(tasks))
            print("    CPU %s: %s" % (cpu, names))
            foreign |= {c for c, p in tasks if p != "0" and c not in OURS and c != client}
        key = (name, ", ".join(sorted(foreign)) or "only idle and this test's own threads")
        tally[key] = tally.get(key, 0) + 1
    print("\nlongest step of each fully traced slow read, and the other tasks on the CPUs meanwhile:")
    for (name, who), n in sorted(tally.items(), key=lambda kv: -kv[1]):
        print("  %3d  before %-16s %s" % (n, name, who))


if __name__ == "__main__":
    main()

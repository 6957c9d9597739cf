#!/usr/bin/env python3
"""Why a byte written to a pty arrived late: an ftrace of the kernel's pty delivery.

Runs `pty_delivery_latency.py fifo` (a byte every 2 ms through a raw pty pair, writer and
reader under SCHED_FIFO, no eyebot-hil code) with the scheduler and workqueue trace events on,
then explains every byte that took longer than THRESHOLD_MS (default 1.5) from write() to
read(): where the kernel queued `flush_to_ldisc` (the work item that moves pty bytes to the
reader), which CPU its worker thread was woken on, how long it waited to run, and which tasks
held that CPU meanwhile.

Needs root and tracefs at /sys/kernel/tracing. Leaves tracing off and the event list empty.

    sudo python3 pty-tests/diagnostics/trace_pty_delivery.py [THRESHOLD_MS]
"""
import os
import re
import subprocess
import sys

TRACING = "/sys/kernel/tracing"
EVENTS = [
    "sched:sched_wakeup",
    "sched:sched_switch",
    "workqueue:workqueue_queue_work",
    "workqueue:workqueue_execute_start",
    "irq_vectors:reschedule_entry",
    "irq_vectors:call_function_single_entry",
    "power:cpu_idle",
]
LINE = re.compile(r"^\s*(?P<task>.+?)-(?P<pid>\d+)\s+\[(?P<cpu>\d+)\]\s+\S+\s+(?P<ts>\d+\.\d+): (?P<event>\w+): (?P<rest>.*)$")


def write(name, value):
    with open(os.path.join(TRACING, name), "w") as f:
        f.write(value)


def nice_of(pid):
    try:
        with open("/proc/%s/stat" % pid) as f:
            fields = f.read().rsplit(")", 1)[1].split()
        return "nice %s" % fields[16]
    except OSError:
        return "gone"


def start_tracing(buffer_kb):
    """Turns on EVENTS with the monotonic clock (Python's time.monotonic_ns(), and the
    clock the benches print outliers on), into an empty buffer of `buffer_kb` per CPU."""
    write("tracing_on", "0")
    write("trace_clock", "mono")
    write("buffer_size_kb", str(buffer_kb))
    write("trace", "")
    write("set_event", "")
    for e in EVENTS:
        # O_APPEND without the seek Python's "a" mode does (tracefs refuses it).
        fd = os.open(os.path.join(TRACING, "set_event"), os.O_WRONLY | os.O_APPEND)
        try:
            os.write(fd, (e + "\n").encode())
        finally:
            os.close(fd)
    write("tracing_on", "1")


def take_events():
    """The parsed events of the (stopped) trace, times as floats; leaves the event list and
    the buffer empty."""
    with open(os.path.join(TRACING, "trace")) as f:
        events = [m.groupdict() for m in map(LINE.match, f) if m]
    write("set_event", "")
    write("trace", "")
    for e in events:
        e["ts"] = float(e["ts"])
    return events


def main():
    threshold_ms = float(sys.argv[1]) if len(sys.argv) > 1 else 1.5
    if not os.path.isdir(os.path.join(TRACING, "events")):
        sys.exit("tracefs is not mounted at %s (mount -t tracefs nodev %s)" % (TRACING, TRACING))
    here = os.path.dirname(os.path.abspath(__file__))
    start_tracing(20000)
    try:
        out = subprocess.run(
            [sys.executable, os.path.join(here, "pty_delivery_latency.py"), "fifo", "--outliers",
             str(threshold_ms)],
            check=True, capture_output=True, text=True,
        ).stdout
    finally:
        write("tracing_on", "0")
    events = take_events()
    print(out, end="")
    outliers = [
        (float(m.group(1)), float(m.group(2)))
        for m in re.finditer(r"OUTLIER sent_mono (\d+\.\d+) delay (\d+\.\d+) ms", out)
    ]
    for sent, delay in outliers:
        print("\nbyte written at %.6f, read %.3f ms later:" % (sent, delay))
        window = [e for e in events if sent - 1e-4 <= e["ts"] <= sent + delay / 1e3 + 1e-4]
        queued = next((e for e in window if e["event"] == "workqueue_queue_work"
                       and "flush_to_ldisc" in e["rest"]), None)
        if queued is None:
            print("  no flush_to_ldisc queued in the window (trace buffer overrun?)")
            continue
        woken = next((e for e in window if e["event"] == "sched_wakeup" and e["ts"] >= queued["ts"]
                      and "kworker" in e["rest"]), None)
        started = next((e for e in window if e["event"] == "workqueue_execute_start"
                        and e["ts"] >= queued["ts"] and "flush_to_ldisc" in e["rest"]), None)
        print("  flush_to_ldisc queued on CPU %s at +%.3f ms" % (queued["cpu"], (queued["ts"] - sent) * 1e3))
        if woken is None or started is None:
            print("  worker wake-up or start not in the window")
            continue
        target = re.search(r"target_cpu=(\d+)", woken["rest"]).group(1)
        print("  worker woken for CPU %d at +%.3f ms, ran on CPU %d at +%.3f ms (waited %.3f ms)"
              % (int(target), (woken["ts"] - sent) * 1e3, int(started["cpu"]),
                 (started["ts"] - sent) * 1e3, (started["ts"] - woken["ts"]) * 1e3))
        held = {}
        for e in window:
            if (e["event"] == "sched_switch" and int(e["cpu"]) == int(target)
                    and woken["ts"] <= e["ts"] <= started["ts"]):
                nxt = re.search(r"next_comm=(.+?) next_pid=(\d+)", e["rest"])
                held[(nxt.group(1), nxt.group(2))] = True
        # The task running on the target CPU when the worker was woken.
        before = [e for e in events if int(e["cpu"]) == int(target) and e["ts"] <= woken["ts"]
                  and e["event"] == "sched_switch"]
        if before:
            nxt = re.search(r"next_comm=(.+?) next_pid=(\d+)", before[-1]["rest"])
            held[(nxt.group(1), nxt.group(2))] = True
        worker = re.search(r"pid=(\d+)", woken["rest"]).group(1)
        for comm, pid in held:
            if pid == worker:
                continue
            print("  CPU %s ran %s (pid %s, %s) while the worker waited"
                  % (target, comm, pid, "idle" if pid == "0" else nice_of(pid)))


if __name__ == "__main__":
    main()

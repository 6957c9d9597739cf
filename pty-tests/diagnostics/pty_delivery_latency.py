#!/usr/bin/env python3
"""How long the kernel takes to deliver bytes through a pty, without any eyebot-hil code.

A writer thread writes one byte every 2 ms to a pty master; a reader thread on the slave
timestamps each byte. With `fifo`, both threads run under SCHED_FIFO (needs root or
CAP_SYS_NICE), so what remains is the kernel's own path (pty_write queues flush_to_ldisc on
an ordinary-priority kworker, which waits behind other processes when the CPUs are busy).

    python3 pty-tests/diagnostics/pty_delivery_latency.py fifo
    python3 pty-tests/diagnostics/pty_delivery_latency.py cfs

`--outliers MS` also prints each byte slower than MS with its write time on the monotonic
clock (what `trace_pty_delivery.py` matches against the kernel trace).
"""
import os
import pty
import sys
import threading
import time
import tty

N = 2000
fifo = len(sys.argv) > 1 and sys.argv[1] == "fifo"
outlier_ms = float(sys.argv[sys.argv.index("--outliers") + 1]) if "--outliers" in sys.argv else None
master, slave = pty.openpty()
tty.setraw(slave)
sent, delivery, write_call = [], [], []


def reader():
    if fifo:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(20))
    got = 0
    while got < N:
        data = os.read(slave, 64)
        now = time.monotonic_ns()
        for _ in data:
            delivery.append(now - sent[got])
            got += 1


thread = threading.Thread(target=reader)
thread.start()
if fifo:
    os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(10))
for _ in range(N):
    time.sleep(0.002)
    t0 = time.monotonic_ns()
    sent.append(t0)
    os.write(master, b"x")
    write_call.append(time.monotonic_ns() - t0)
thread.join()
if outlier_ms is not None:
    for i, d in enumerate(delivery):
        if d > outlier_ms * 1e6:
            print("OUTLIER sent_mono %.6f delay %.3f ms" % (sent[i] / 1e9, d / 1e6))
for name, v in (("write->read", delivery), ("write() call", write_call)):
    v.sort()
    n = len(v)
    print(
        "%s %s: p50 %.3f p99 %.3f max %.3f ms; over 2 ms: %d of %d"
        % ("fifo" if fifo else "cfs", name, v[n // 2] / 1e6, v[int(n * 0.99)] / 1e6,
           v[-1] / 1e6, sum(1 for x in v if x > 2e6), n)
    )

"""The bench's CPU time of a process (``ecatsim.bench.master.cpu_seconds``): to the
nanosecond from the scheduler's statistics, so a daemon of a few drives that runs less
than one clock tick (10 ms) in a short run is measured, not read as 0 %."""

from __future__ import annotations

import os
import threading
import time

from ecatsim.bench.master import cpu_seconds


def spin(seconds: float) -> None:
    end = time.thread_time() + seconds
    while time.thread_time() < end:
        pass


def test_a_few_milliseconds_of_cpu_are_measured_finer_than_a_clock_tick() -> None:
    for _ in range(5):
        before = cpu_seconds(os.getpid())
        spin(0.003)
        # clock ticks would read 0 or 10 ms here
        assert 0.0025 <= cpu_seconds(os.getpid()) - before <= 0.008


def test_every_thread_of_the_process_counts() -> None:
    spun, done = threading.Event(), threading.Event()

    def worker() -> None:
        spin(0.02)
        spun.set()
        done.wait()

    before = cpu_seconds(os.getpid())
    t = threading.Thread(target=worker)
    t.start()
    spun.wait()
    try:
        assert cpu_seconds(os.getpid()) - before >= 0.019  # the other thread's 20 ms
    finally:
        done.set()
        t.join()

"""The one clock of compiled kernels: CLOCK_MONOTONIC read from compiled code."""

import time

import numpy as np

from qpbench.native import clock


def test_clock_is_the_monotonic_clock_and_never_goes_back():
    monotonic = clock()
    ts = np.zeros(2, dtype=np.int64)
    before = time.monotonic()
    readings = [monotonic(ts) for _ in range(1000)]
    after = time.monotonic()
    assert all(b >= a for a, b in zip(readings, readings[1:]))
    # the same clock as Python's time.monotonic (CLOCK_MONOTONIC on Linux)
    assert before <= readings[0] <= readings[-1] <= after

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


def test_a_compiled_caller_is_renamed_when_a_callee_in_another_file_changes(tmp_path):
    """numba's cache checks the caller's own file only; the caller's name carries a digest of
    every file its compiled callees come from, so an edited callee gives a new cache entry."""
    import importlib.util

    from qpbench.native import compile_with

    def load(name, text):
        path = tmp_path / f"{name}.py"
        path.write_text(text)
        spec = importlib.util.spec_from_file_location(name, path)
        module = importlib.util.module_from_spec(spec)
        spec.loader.exec_module(module)
        return module

    caller = load("caller_mod", "def twice(x):\n    return 2 * callee(x)\n")
    callee_v1 = load("callee_mod", "def callee(x):\n    return x + 1\n")
    first = compile_with(caller.twice, {"callee": compile_with(callee_v1.callee)})
    again = compile_with(caller.twice, {"callee": compile_with(callee_v1.callee)})
    callee_v2 = load("callee_mod", "def callee(x):\n    return x + 2\n")
    edited = compile_with(caller.twice, {"callee": compile_with(callee_v2.callee)})
    assert first.py_func.__name__ == again.py_func.__name__
    assert edited.py_func.__name__ != first.py_func.__name__
    assert (first(1.0), edited(1.0)) == (4.0, 6.0)

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
    from qpbench.native import compile_with

    caller = _load(tmp_path, "caller_mod", "def twice(x):\n    return 2 * callee(x)\n")
    callee_v1 = _load(tmp_path, "callee_mod", "def callee(x):\n    return x + 1\n")
    first = compile_with(caller.twice, {"callee": compile_with(callee_v1.callee)})
    again = compile_with(caller.twice, {"callee": compile_with(callee_v1.callee)})
    callee_v2 = _load(tmp_path, "callee_mod", "def callee(x):\n    return x + 2\n")
    edited = compile_with(caller.twice, {"callee": compile_with(callee_v2.callee)})
    assert first.py_func.__name__ == again.py_func.__name__
    assert edited.py_func.__name__ != first.py_func.__name__
    assert (first(1.0), edited(1.0)) == (4.0, 6.0)


def test_a_callee_that_allocates_compiles_when_first_called_without_the_runtime(tmp_path):
    """numba compiles a callee that does not say otherwise with its first caller's setting of
    the runtime; the engine runs without it, the backends' solves it calls may allocate, and a
    fresh cache compiles them first as its callees: compile_with says the runtime is on."""
    from qpbench.native import compile_with

    alloc = _load(
        tmp_path, "alloc_mod", "import numpy as np\ndef total(n):\n    return np.ones(n).sum()\n"
    )
    caller = _load(tmp_path, "bare_mod", "def run(n):\n    return total(n)\n")
    run = compile_with(caller.run, {"total": compile_with(alloc.total)}, _nrt=False)
    assert run(3) == 3.0


def _load(folder, name, text):
    """The module ``name`` of source ``text``, written to ``folder`` (fresh: nothing cached)."""
    import importlib.util

    path = folder / f"{name}.py"
    path.write_text(text)
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module

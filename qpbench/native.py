"""Compiled kernels and the native code they call: copies of one body compiled with other
functions bound (:func:`compile_with`), shared libraries loaded into the process's symbol table,
their functions declared for numba, and the one monotonic clock every tick is timed by.

A function declared here (:func:`external`) is resolved by name when a kernel is compiled or
loaded from numba's cache, so kernels that call it cache like any other (a ctypes function
pointer would be baked into the code and make numba refuse to cache it). Pointers cross as
``intp`` addresses (``arr.ctypes.data`` in compiled code): on the 64-bit targets numba supports,
a pointer and a 64-bit integer are passed the same way.
"""

from __future__ import annotations

import ctypes.util
from functools import cache

#: ``CLOCK_MONOTONIC`` of Linux' ``<time.h>``.
CLOCK_MONOTONIC = 1


@cache
def load_permanently(path: str) -> None:
    """Add the shared library at ``path`` to the symbols compiled kernels resolve (once)."""
    import llvmlite.binding

    llvmlite.binding.load_library_permanently(path)


def external(name: str, signature):
    """The C function ``name`` of a library loaded by :func:`load_permanently`, callable from
    compiled code with numba ``signature``."""
    from numba import types

    return types.ExternalFunction(name, signature)


@cache
def clock():
    """The compiled clock ``monotonic(ts) -> seconds``: ``clock_gettime(CLOCK_MONOTONIC)`` into
    the caller's ``ts`` (int64[2], no allocation per call)."""
    import numba
    from numba import types

    load_permanently(ctypes.util.find_library("c"))
    _clock_gettime = external("clock_gettime", types.intc(types.intc, types.intp))
    globals()["_clock_gettime"] = _clock_gettime
    return numba.njit(cache=True, nogil=True)(_monotonic_py)


def _monotonic_py(ts):  # pragma: no cover - compiled
    """Seconds of ``CLOCK_MONOTONIC`` (the clock's origin is arbitrary: take differences)."""
    _clock_gettime(CLOCK_MONOTONIC, ts.ctypes.data)  # noqa: F821 - bound by clock()
    return ts[0] + 1e-9 * ts[1]


def compile_with(fn, bindings: dict | None = None, name: str | None = None, **options):
    """``numba.njit(cache=True, nogil=True)`` of a copy of ``fn`` whose globals also hold
    ``bindings`` (compiled functions it calls by name), named ``name`` (default: ``fn``'s).

    One body compiled with other functions bound (an engine per backend's solve), each copy
    cached under its own name; numba's cache stays valid because the bindings are compiled
    functions resolved when the copy is compiled.
    """
    import types

    import numba

    name = name or fn.__name__
    copy = types.FunctionType(fn.__code__, {**fn.__globals__, **(bindings or {})}, name)
    copy.__qualname__ = name
    copy.__module__ = fn.__module__
    copy.__doc__ = fn.__doc__
    return numba.njit(cache=True, nogil=True, **options)(copy)


def entry_point(dispatcher, *args):
    """The compiled function of ``dispatcher`` for the types of ``args`` (compiled, or loaded
    from the cache, now), callable without numba's type dispatch: for a caller that calls it
    per tick with arguments of these same types (a named model costs several microseconds to
    type per call)."""
    sig = tuple(dispatcher.typeof_pyval(a) for a in args)
    dispatcher.compile(sig)
    return dispatcher.overloads[sig].entry_point

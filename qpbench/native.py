"""Compiled kernels and the native code they call: one body compiled with other functions
bound (:func:`compile_with`), shared libraries' functions declared for numba by name (so the
kernels calling them cache; a ctypes pointer would not), pointers as ``intp`` addresses, and
the one monotonic clock every tick is timed by.
"""

from __future__ import annotations

import ctypes.util
from functools import cache
from pathlib import Path

#: ``CLOCK_MONOTONIC`` of Linux' ``<time.h>``.
CLOCK_MONOTONIC = 1


@cache
def load_permanently(path: str) -> None:
    """Add the shared library at ``path`` to the symbols compiled kernels resolve (once)."""
    import llvmlite.binding

    llvmlite.binding.load_library_permanently(path)


@cache
def clock():
    """The compiled clock ``monotonic(ts) -> seconds`` (``ts``: the caller's int64[2])."""
    from numba import types

    load_permanently(ctypes.util.find_library("c"))
    signature = types.intc(types.intc, types.intp)
    globals()["_clock_gettime"] = types.ExternalFunction("clock_gettime", signature)
    return njit(_nrt=False)(_monotonic_py)


def _monotonic_py(ts):  # pragma: no cover - compiled
    """Seconds of ``CLOCK_MONOTONIC`` (the clock's origin is arbitrary: take differences)."""
    _clock_gettime(CLOCK_MONOTONIC, ts.ctypes.data)  # noqa: F821 - bound by clock()
    return ts[0] + 1e-9 * ts[1]


def njit(*signature, **options):
    """``numba.njit`` with the package's options unless ``options`` say otherwise: cached, the GIL
    released, and numba's runtime (reference counts, allocation) on. The runtime is always said:
    numba compiles a function that does not say with its first caller's setting, so one that
    allocates, first called from a function compiled without it (the engine), would fail."""
    import numba

    return numba.njit(*signature, **{"cache": True, "nogil": True, "_nrt": True, **options})


def compile_with(fn, bindings: dict | None = None, name: str | None = None, **options):
    """:func:`njit` (``options`` passed on) of a copy of ``fn`` named ``name``, its globals also
    holding ``bindings`` (compiled functions it calls by name), cached under its name."""
    import types

    scope = {**fn.__globals__, **(bindings or {})}
    name = f"{name or fn.__name__}_{_sources_digest(fn.__code__.co_filename, scope)}"
    copy = types.FunctionType(fn.__code__, scope, name)
    copy.__qualname__ = name
    copy.__module__ = fn.__module__
    copy.__doc__ = fn.__doc__
    return njit(**options)(copy)


def _sources_digest(path: str, scope: dict) -> str:
    """A digest of ``path`` and of the source file of every compiled function reachable from
    ``scope``: numba's cache checks the calling function's own file only, yet a caller's cached
    code holds its callees' code (inlined or linked), so a callee edited in another file would
    leave a stale caller. Naming the copy by this digest gives the edited program a new entry."""
    import hashlib

    files, seen, todo = {path}, set(), list(scope.values())
    while todo:
        value = todo.pop()
        py_func = getattr(value, "py_func", None)
        if py_func is None or id(value) in seen:
            continue
        seen.add(id(value))
        files.add(py_func.__code__.co_filename)
        todo.extend(py_func.__globals__.values())
    text = "".join(hashlib.sha1(Path(f).read_bytes()).hexdigest() for f in sorted(files))
    return hashlib.sha1(text.encode()).hexdigest()[:12]


def entry_point(dispatcher, *args):
    """The compiled function of ``dispatcher`` for the types of ``args``, callable without
    numba's type dispatch (a per-tick caller with arguments of these types)."""
    sig = tuple(dispatcher.typeof_pyval(a) for a in args)
    dispatcher.compile(sig)
    return dispatcher.overloads[sig].entry_point

"""Compiled solves of the backends whose solver is qpbench's own code: ``noop`` (the machine's
own loop), ``pinv`` (the paper's pseudo-inverse baseline) and the paper's network online
(``rnn``, ``rnn-tuned``). The protocol: :class:`qpbench.engine.compiled.CompiledSolver`; each
mirrors its Python backend call for call (same answer, status and state). One compiled solve
serves the four (the state says which), so one engine is compiled for them."""

from __future__ import annotations

from functools import cache
from typing import NamedTuple

import numpy as np

from ..backends.pinv import pinv_kernel
from ..native import compile_with
from ..rnn import kernels as nk

#: Status codes (``TICK_STATUSES``).
_OPTIMAL, _MAX_ITER, _ERROR = 0, 3, 5
#: ``OwnState.kind``: which solve a state is for (one engine for all four backends).
NOOP, PINV, NETWORK = 0, 1, 2

# Compiled functions the solves call, bound by compiled_solve().
_pinv = _packed = _null_solve_in = _pinv_solve_in = _network_solve_in = None


class OwnState(NamedTuple):
    """A solve's state: ``kind`` (:data:`NOOP`, :data:`PINV`, :data:`NETWORK`); the online
    network's state ``xi = [v; l1; l2]``, its parameter block ``prm``
    (:mod:`qpbench.rnn.kernels`), the kernel's output ``out`` and ``cold[0]``: the next call
    starts from ``v = warm`` and zero multipliers (after a reset or a divergence); empty for
    the others."""

    kind: int
    xi: np.ndarray
    prm: np.ndarray
    out: np.ndarray
    cold: np.ndarray


def make_state(backend, model, n_rows: int):
    """The solve's state for ``backend`` on ``model``'s QPs (``n_rows`` obstacle rows)."""
    n = model.theta0.shape[0]
    if backend.name == "noop" or backend.name == "pinv":
        kind, none = (NOOP if backend.name == "noop" else PINV), np.zeros(0)
        return OwnState(kind, none, none, none, np.ones(1))
    me = 0 if model.soft else model.controller.normal.shape[0]
    prm = backend._prm.copy()
    prm[nk.STATE_ME] = me
    size = n + me + n_rows
    out = np.empty(3 * n + 2 * (me + n_rows))
    return OwnState(NETWORK, np.zeros(size), prm, out, np.ones(1))


def close_state(st) -> None:
    """Nothing to free: the state is numpy memory."""


def unavailable_reason(backend) -> str | None:
    """Why ``backend`` cannot run compiled here (``None``: it can)."""
    if backend.name.startswith("rnn") and not backend.use_numba:
        return "the network is set to run without numba (use_numba = false)"
    return None


def error_text(name: str, raw: float) -> str:
    """The message of an ``error`` tick of backend ``name`` (the network's divergence)."""
    return "FloatingPointError: network state diverged"


@cache
def compiled_solve(name: str = ""):
    """The compiled ``solve`` of every backend here (by its state's ``kind``): one engine."""
    inline = {"inline": "always"}
    bound = {
        "_pinv": pinv_kernel(),
        "_packed": nk.packed_kernel_dispatcher(),
        "_null_solve_in": compile_with(_null_solve, name="noop_solve", **inline),
    }
    bound["_pinv_solve_in"] = compile_with(_pinv_solve, bound, name="pinv_solve", **inline)
    bound["_network_solve_in"] = compile_with(_network_solve, bound, name="network_solve", **inline)
    return compile_with(_own_solve, bound, name="own_solve")


@cache
def compiled_reset(name: str = ""):
    """The compiled ``reset`` of every backend here."""
    return compile_with(_network_reset, name="network_reset")


def _own_solve(st, buf, warm, sol, info):  # pragma: no cover - compiled
    """The solve of ``st.kind``."""
    if st.kind == NOOP:
        return _null_solve_in(st, buf, warm, sol, info)
    if st.kind == PINV:
        return _pinv_solve_in(st, buf, warm, sol, info)
    return _network_solve_in(st, buf, warm, sol, info)


def _null_solve(st, buf, warm, sol, info):  # pragma: no cover - compiled
    """``x = 0`` and zero duals, optimal, instantly: the loop without a solver."""
    n, me, mi = int(buf[0]), int(buf[1]), int(buf[2])
    for i in range(n + me + mi):
        sol[i] = 0.0
    info[0] = np.nan
    info[1] = 0.0
    return _OPTIMAL


def _pinv_solve(st, buf, warm, sol, info):  # pragma: no cover - compiled
    """The pseudo-inverse baseline (:func:`qpbench.backends.pinv.pinv_py`, the backend's own
    kernel) on the packed QP; ``z = 0``."""
    n, me, mi = int(buf[0]), int(buf[1]), int(buf[2])
    oP, oq, oA, ob = int(buf[3]), int(buf[4]), int(buf[5]), int(buf[6])
    if me == 0:
        oA = ob = 0
    P = buf[oP : oP + n * n].reshape((n, n)).copy()
    A = buf[oA : oA + me * n].reshape((me, n)).copy()
    _pinv(P, buf[oq : oq + n].copy(), A, buf[ob : ob + me].copy(), sol[:n], sol[n : n + me])
    for i in range(mi):
        sol[n + me + i] = 0.0
    info[0] = np.nan
    info[1] = 0.0
    return _OPTIMAL


def _network_reset(st):  # pragma: no cover - compiled
    """The next network call starts cold (nothing to reset for the others)."""
    st.cold[0] = 1.0


def _network_solve(st, buf, warm, sol, info):  # pragma: no cover - compiled
    """One tick of the network online (:class:`qpbench.backends.rnn.RNNOnline`): the packed
    kernel on ``buf`` from the state, cold from ``warm`` after a reset; a divergence is an
    ``error`` and drops the state."""
    n, me, mi = int(buf[0]), int(buf[1]), int(buf[2])
    xi = st.xi
    if st.cold[0] != 0.0:
        for i in range(xi.shape[0]):
            xi[i] = warm[i] if i < n else 0.0
        st.cold[0] = 0.0
    code = _packed(buf, xi, st.prm, st.out)
    info[0] = np.nan
    if code < 0:
        st.cold[0] = 1.0
        info[1] = st.prm[nk.STEPS]
        info[2] = code
        return _ERROR
    info[1] = code >> 2
    for i in range(n + me + mi):
        sol[i] = st.out[i]
    return _OPTIMAL if code & 1 else _MAX_ITER

"""The network's numba kernels: the integrator as explicit loops, compiled on first use and cached.

Kept together in one module, past the usual 500 lines, by necessity: numba
resolves the functions a kernel calls from the globals of the module that
defines the kernel (``_step_jit``, ``_residuals_jit`` ... are rebound to
their compiled versions by :func:`kernel`, :func:`online_kernel` and
:func:`packed_kernel` before the first compile), so the loops and the
functions that compile them must share one namespace. The numpy twin of the
loop is :mod:`qpbench.rnn.integrate_numpy` (same algorithm, tested equal).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from .integrate_numpy import _integrate_numpy

# Each slot name imported on its own (the list repeats the other rnn modules'): the kernels read
# them as plain module globals, which numba freezes as constants at compile time.
from .layout import (
    _SQUARINGS,
    CLAMP,
    COMPL,
    DIVERGED,
    DUAL,
    L1_CLIP,
    MAX_STEPS,
    NO_STABLE_STEP,
    NOMINAL,
    NOTE,
    NOTE_CAPPED,
    NOTE_CLAMPED,
    NOTE_NONE,
    NOTE_UNPROVEN,
    OBJ,
    OK_DUAL,
    OK_PRIMAL,
    PMAX,
    PMIN,
    PRIMAL,
    R_STEP,
    R_TOTAL,
    RATIO,
    RATIO_MAX,
    SAFETY,
    SEMI,
    SHAPE_MISMATCH,
    SIG2,
    STATE_ME,
    STEPS,
    SUBSTEPS,
    TOL,
)
from .step_bound import _clamped_steps, _frobenius2, _gershgorin, _nominal_steps, _ratio_max

if TYPE_CHECKING:
    from collections.abc import Callable


def _sigma2_bound_loops(A, G):  # pragma: no cover - runs compiled
    n = A.shape[1]
    B = np.zeros((n, n))
    for k in range(A.shape[0]):
        for i in range(n):
            for j in range(n):
                B[i, j] += A[k, i] * A[k, j]
    for k in range(G.shape[0]):
        for i in range(n):
            for j in range(n):
                B[i, j] += G[k, i] * G[k, j]
    t = 0.0
    for i in range(n):
        t += B[i, i]
    if not t > 0.0:
        return 0.0
    logc = math.log(t)
    for i in range(n):
        for j in range(n):
            B[i, j] /= t
    C = np.empty((n, n))
    for _ in range(_SQUARINGS):
        for i in range(n):
            for j in range(n):
                s = 0.0
                for k in range(n):
                    s += B[i, k] * B[k, j]
                C[i, j] = s
        t = 0.0
        for i in range(n):
            t += C[i, i]
        if not t > 0.0:
            return 0.0
        logc = 2.0 * logc + math.log(t)
        for i in range(n):
            for j in range(n):
                B[i, j] = C[i, j] / t
    return math.exp(logc / 2.0**_SQUARINGS)


def _matvec_off(M, xi, off, y):  # pragma: no cover - runs compiled
    """``y = M @ xi[off : off + M.shape[1]]``."""
    for i in range(M.shape[0]):
        s = 0.0
        for j in range(M.shape[1]):
            s += M[i, j] * xi[off + j]
        y[i] = s


def _grad_products(P, q, A, G, xi, g, Av, Gv, products):  # pragma: no cover - runs compiled
    """``g = P v + q - A^T l1 + G^T l2`` and, with ``products``, ``Av = A v``, ``Gv = G v``.

    Row by row: each row of ``A`` and ``G`` is read once for both its
    product with ``v`` and its share of ``g`` (the rows are contiguous).
    """
    n = P.shape[0]
    me = A.shape[0]
    mi = G.shape[0]
    for j in range(n):
        s = q[j]
        for k in range(n):
            s += P[j, k] * xi[k]
        g[j] = s
    for i in range(me):
        c = xi[n + i]
        s = 0.0
        for j in range(n):
            a = A[i, j]
            s += a * xi[j]
            g[j] -= a * c
        if products:
            Av[i] = s
    for i in range(mi):
        c = xi[n + me + i]
        s = 0.0
        for j in range(n):
            a = G[i, j]
            s += a * xi[j]
            g[j] += a * c
        if products:
            Gv[i] = s


def _step(
    P, q, A, b, G, h, lb, ub, xi, g, Av, Gv, r, semi, l1_clip
):  # pragma: no cover - runs compiled
    """One step of ratio ``r`` from the state ``xi`` whose ``g`` (and ``Av``, ``Gv``) are given; refreshes them."""
    n = q.shape[0]
    me = b.shape[0]
    mi = h.shape[0]
    o1 = n
    o2 = n + me
    for j in range(n):
        w = min(max(xi[j] - g[j], lb[j]), ub[j])
        xi[j] += r * (w - xi[j])
    if semi:
        _matvec_jit(A, xi, 0, Av)
        _matvec_jit(G, xi, 0, Gv)
    for i in range(me):
        xi[o1 + i] += r * (b[i] - Av[i])
        if l1_clip < np.inf:
            xi[o1 + i] = min(max(xi[o1 + i], -l1_clip), l1_clip)
    for i in range(mi):
        xi[o2 + i] += r * (max(xi[o2 + i] + Gv[i] - h[i], 0.0) - xi[o2 + i])
    # the next step's g (and, for Euler, Av and Gv): one pass over each row
    _grad_products_jit(P, q, A, G, xi, g, Av, Gv, not semi)


def _residuals(b, h, lb, ub, xi, g, Av, Gv):  # pragma: no cover - runs compiled
    """``(primal, dual, complementarity)`` residuals of the state (see :class:`IntegrationResult`).

    Maxima that propagate NaN: a diverged state must not look converged.
    """
    n = lb.shape[0]
    me = b.shape[0]
    mi = h.shape[0]
    o2 = n + me
    pr = 0.0
    for i in range(me):
        e = abs(Av[i] - b[i])
        if e > pr or e != e:
            pr = e
    for i in range(mi):
        e = Gv[i] - h[i]
        if e > pr or e != e:
            pr = e
    for j in range(n):
        e = max(lb[j] - xi[j], xi[j] - ub[j])
        if e > pr or xi[j] != xi[j]:
            pr = e if xi[j] == xi[j] else xi[j]
    du = 0.0
    for j in range(n):
        e = abs(xi[j] - min(max(xi[j] - g[j], lb[j]), ub[j]))
        if e > du or g[j] != g[j] or xi[j] != xi[j]:
            du = e if (g[j] == g[j] and xi[j] == xi[j]) else np.nan
    co = 0.0
    for i in range(mi):
        e = abs(xi[o2 + i] - max(xi[o2 + i] + Gv[i] - h[i], 0.0))
        if e > co or xi[o2 + i] != xi[o2 + i] or Gv[i] != Gv[i]:
            co = e if (xi[o2 + i] == xi[o2 + i] and Gv[i] == Gv[i]) else np.nan
    return pr, du, co


# Over 80 lines, kept whole on purpose: the integrator's main loop is one compiled loop (the
# per-step functions it calls are already separate kernels, inlined by numba); moving its
# set-up or its stopping tests out would add calls inside the loop or another compiled
# function to rebind before the first compile, and the bit-identical tests against the
# numpy twin (qpbench/rnn/integrate_numpy.py) pin its numbers.
def _integrate_loops(P, q, A, b, G, h, lb, ub, xi, prm, sol):  # pragma: no cover - runs compiled
    n = q.shape[0]
    me = b.shape[0]
    mi = h.shape[0]
    if (
        P.shape[0] != n
        or P.shape[1] != n
        or A.shape[0] != me
        or A.shape[1] != n
        or G.shape[0] != mi
        or G.shape[1] != n
        or lb.shape[0] != n
        or ub.shape[0] != n
        or xi.shape[0] != n + me + mi
        or (
            sol.shape[0] != 0
            and sol.shape[0] != 2 * n + me + mi
            and sol.shape[0] != 3 * n + 2 * (me + mi)
        )
    ):
        return SHAPE_MISMATCH
    o1 = n
    o2 = n + me
    semi = prm[SEMI] != 0.0
    r_total = prm[R_TOTAL]
    l1_clip = prm[L1_CLIP]
    tol = prm[TOL]
    nominal = _nominal_steps_jit(r_total, prm[R_STEP], int(prm[SUBSTEPS]))
    forced = nominal > 0
    prm[NOMINAL] = nominal
    nsteps = nominal
    note = NOTE_NONE
    if forced:
        rmax = np.nan
        sig2 = np.nan
        if prm[CLAMP] != 0.0:
            # the bound only when the step may exceed it: below a cheap lower
            # estimate of it (Gershgorin for P, Frobenius for sigma_max^2) it cannot
            glo, ghi, exact = _gershgorin_jit(P)
            low = _ratio_max_jit(glo, ghi, _frobenius2_jit(A, G), semi)
            if not r_total / nominal <= prm[SAFETY] * low:
                pmin = glo
                pmax = ghi
                if not exact:
                    w = np.linalg.eigvalsh(0.5 * (P + P.T))
                    pmin = w[0]
                    pmax = w[n - 1]
                # same logic as _integrate_numpy's (the numpy twin, kept apart on purpose: numba
                # compiles this one; tests/test_rnn.py checks both give the same steps and notes)
                sig2 = _sigma2_bound_jit(A, G)
                rmax = _ratio_max_jit(pmin, pmax, sig2, semi)
                if rmax <= 0.0:
                    note = NOTE_UNPROVEN
                elif r_total / nominal > prm[SAFETY] * rmax:
                    nsteps = _clamped_steps_jit(
                        r_total, prm[SAFETY] * rmax, nominal, prm[MAX_STEPS]
                    )
                    note = NOTE_CLAMPED
    else:
        sig2 = _sigma2_bound_jit(A, G)
        rmax = _ratio_max_jit(prm[PMIN], prm[PMAX], sig2, semi)
    prm[RATIO_MAX] = rmax
    prm[SIG2] = sig2
    # From here on the same lines as the numpy twin (qpbench/rnn/integrate_numpy.py), kept twice
    # on purpose: numba cannot call the twin's array code, the twin runs without numba, and it is
    # this loop's reference (tests/test_rnn.py::test_numba_and_numpy_agree_online_and_converged).
    if not forced and rmax <= 0.0:
        prm[RATIO] = 0.0
        prm[STEPS] = NO_STABLE_STEP
        return NO_STABLE_STEP
    if r_total > 0.0:
        if not forced:
            nsteps = _clamped_steps_jit(r_total, prm[SAFETY] * rmax, 1, prm[MAX_STEPS])
        if nsteps >= prm[MAX_STEPS] and r_total / nsteps > prm[SAFETY] * rmax:
            note = NOTE_CAPPED
        r = r_total / nsteps
        check = False
    else:
        r = prm[SAFETY] * rmax
        nsteps = int(prm[MAX_STEPS])
        check = tol >= 0.0
    prm[NOTE] = note
    prm[RATIO] = r
    if sol.shape[0] >= 3 * n + 2 * (me + mi):
        # scratch space after the outputs (saves three allocations)
        base = 2 * n + me + mi
        g = sol[base : base + n]
        Av = sol[base + n : base + n + me]
        Gv = sol[base + n + me : base + n + me + mi]
    else:
        Av = np.empty(me)
        Gv = np.empty(mi)
        g = np.empty(n)
    # g = P v + q - A^T l1 + G^T l2, Av = A v, Gv = G v at the current state
    _grad_products_jit(P, q, A, G, xi, g, Av, Gv, True)
    if check:
        steps = 0
        while True:
            pr, du, co = _residuals_jit(b, h, lb, ub, xi, g, Av, Gv)
            if steps == nsteps or (pr <= tol and du <= tol and co <= tol):
                break
            _step_jit(P, q, A, b, G, h, lb, ub, xi, g, Av, Gv, r, semi, l1_clip)
            steps += 1
    else:
        # a fixed duration: a plain loop (the residuals once, at the end)
        for _ in range(nsteps):
            _step_jit(P, q, A, b, G, h, lb, ub, xi, g, Av, Gv, r, semi, l1_clip)
        steps = nsteps
        pr, du, co = _residuals_jit(b, h, lb, ub, xi, g, Av, Gv)
    prm[PRIMAL] = pr
    prm[DUAL] = du
    prm[COMPL] = co
    obj = 0.0
    for j in range(n):
        s = 0.0
        for k in range(n):
            s += P[j, k] * xi[k]
        obj += xi[j] * (0.5 * s + q[j])
    prm[OBJ] = obj
    prm[STEPS] = steps
    if sol.shape[0] != 0:
        for j in range(n):
            sol[j] = xi[j]
            w = xi[j] - g[j]
            sol[n + me + mi + j] = w - min(max(w, lb[j]), ub[j])
        for i in range(me):
            sol[n + i] = -xi[o1 + i]
        for i in range(mi):
            sol[n + me + i] = xi[o2 + i]
    return steps


def _online_tick_loops(P, q, A, b, G, h, lb, ub, xi, prm, sol):  # pragma: no cover - runs compiled
    """One call of the online network: :func:`_integrate_loops` plus its verdict.

    Returns ``4 * steps + 2 * note + ok`` (``ok``: primal residual and
    complementarity within ``prm[OK_PRIMAL]``, dual residual within
    ``prm[OK_DUAL]``; ``note``: the setting's step was clamped to the
    stability bound, or no step is proven stable, see :func:`step_note`), or
    :data:`SHAPE_MISMATCH` (also when the equality count is not the state's
    ``prm[STATE_ME]``), :data:`NO_STABLE_STEP` or :data:`DIVERGED`.
    """
    if prm[STATE_ME] >= 0.0 and b.shape[0] != prm[STATE_ME]:
        return SHAPE_MISMATCH
    steps = _integrate_jit(P, q, A, b, G, h, lb, ub, xi, prm, sol)
    if steps < 0:
        return steps
    obj = prm[OBJ]
    pr = prm[PRIMAL]
    if not (math.isfinite(obj) and math.isfinite(pr)):
        return DIVERGED
    ok = pr <= prm[OK_PRIMAL] and prm[DUAL] <= prm[OK_DUAL] and prm[COMPL] <= prm[OK_PRIMAL]
    return 4 * steps + (2 if prm[NOTE] != NOTE_NONE else 0) + (1 if ok else 0)


def _part_fits(off, size, length):  # pragma: no cover - runs compiled
    return off >= _HEADER and size >= 0 and off + size <= length


def _online_tick_packed_loops(buf, xi, prm, sol):  # pragma: no cover - runs compiled
    """:func:`_online_tick_loops` on a :class:`qpbench.packed.PackedProblem`'s buffer.

    Reads the header, checks that every part lies inside the buffer and that
    the sizes are the state's, and integrates on views of the buffer. A
    problem without ``lb`` or ``ub`` gives :data:`SHAPE_MISMATCH` (the general
    path handles it).
    """
    length = buf.shape[0]
    if length < _HEADER:
        return SHAPE_MISMATCH
    n = int(buf[0])
    me = int(buf[1])
    mi = int(buf[2])
    if n < 1 or me < 0 or mi < 0 or n + me + mi != xi.shape[0]:
        return SHAPE_MISMATCH
    oP = int(buf[3])
    oq = int(buf[4])
    oA = int(buf[5])
    ob = int(buf[6])
    oG = int(buf[7])
    oh = int(buf[8])
    olb = int(buf[9])
    oub = int(buf[10])
    if not (
        _part_fits_jit(oP, n * n, length)
        and _part_fits_jit(oq, n, length)
        and _part_fits_jit(olb, n, length)
        and _part_fits_jit(oub, n, length)
        and (me == 0 or (_part_fits_jit(oA, me * n, length) and _part_fits_jit(ob, me, length)))
        and (mi == 0 or (_part_fits_jit(oG, mi * n, length) and _part_fits_jit(oh, mi, length)))
    ):
        return SHAPE_MISMATCH
    if me == 0:
        oA = ob = _HEADER
    if mi == 0:
        oG = oh = _HEADER
    return _online_tick_jit(
        buf[oP : oP + n * n].reshape((n, n)),
        buf[oq : oq + n],
        buf[oA : oA + me * n].reshape((me, n)),
        buf[ob : ob + me],
        buf[oG : oG + mi * n].reshape((mi, n)),
        buf[oh : oh + mi],
        buf[olb : olb + n],
        buf[oub : oub + n],
        xi,
        prm,
        sol,
    )


# Names the compiled kernels call; bound to jitted functions by :func:`kernel`.
_sigma2_bound_jit = _sigma2_bound_loops
_ratio_max_jit = _ratio_max
_gershgorin_jit = _gershgorin
_frobenius2_jit = _frobenius2
_nominal_steps_jit = _nominal_steps
_clamped_steps_jit = _clamped_steps
_matvec_jit = _matvec_off
_grad_products_jit = _grad_products
_step_jit = _step
_residuals_jit = _residuals
_integrate_jit = _integrate_loops
_online_tick_jit = _online_tick_loops
_part_fits_jit = _part_fits
_COMPILED = None
_ONLINE = {}
_PACKED = None
_HEADER = 11  # qpbench.packed.HEADER (a test keeps them equal)


def numba_available() -> bool:
    """Whether numba can be imported here."""
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


def kernel(use_numba: bool = True) -> Callable:
    """The integrator ``f(P, q, A, b, G, h, lb, ub, xi, prm, sol) -> steps``.

    ``xi`` (the state ``[v; l1; l2]``) is updated in place; ``prm`` holds the
    inputs ``PMIN .. L1_CLIP`` and receives the outputs ``PRIMAL .. SIG2``
    (index constants of this module); ``sol`` (length ``2n + me + mi``, or 0
    to skip) receives ``[x; y; z; z_box]`` as :func:`duals` defines them.
    Returns the step count, :data:`NO_STABLE_STEP` or :data:`SHAPE_MISMATCH`.
    The numba version is compiled on the first call of this function's result
    (and cached on disk); the numpy version computes the same numbers.
    """
    if not use_numba:
        return _integrate_numpy
    global \
        _COMPILED, \
        _sigma2_bound_jit, \
        _ratio_max_jit, \
        _matvec_jit, \
        _grad_products_jit, \
        _integrate_jit
    global \
        _step_jit, \
        _residuals_jit, \
        _gershgorin_jit, \
        _frobenius2_jit, \
        _nominal_steps_jit, \
        _clamped_steps_jit
    if _COMPILED is None:
        import numba

        jit = numba.njit(cache=True)
        inline = numba.njit(cache=True, inline="always")
        _sigma2_bound_jit = jit(_sigma2_bound_loops)
        _ratio_max_jit = jit(_ratio_max)
        _gershgorin_jit = inline(_gershgorin)
        _frobenius2_jit = inline(_frobenius2)
        _nominal_steps_jit = inline(_nominal_steps)
        _clamped_steps_jit = inline(_clamped_steps)
        # inlined into their callers (numba IR): a call costs more than these small products,
        # and the Euler step's loop runs them hundreds of times a solve. The integrator itself
        # and the online tick are called once a solve and compiled as calls: inlining them
        # copied their IR into every caller and type, most of the compile time, for no speed
        # (``python bench/rnn_speed.py``; bench/README.md).
        _matvec_jit = inline(_matvec_off)
        _grad_products_jit = inline(_grad_products)
        _step_jit = inline(_step)
        _residuals_jit = inline(_residuals)
        _COMPILED = _integrate_jit = jit(_integrate_loops)
    return _COMPILED


def online_kernel(strict: bool = True) -> Callable:
    """The per-tick kernel ``f(P, q, A, b, G, h, lb, ub, xi, prm, sol) -> code``.

    Same arguments as :func:`kernel`'s result, ``sol`` of length
    ``3 n + 2 (me + mi)``; returns :func:`_online_tick_loops`'s code. With
    ``strict`` it is compiled for exactly one argument type (C-contiguous,
    writable float64 arrays; ``P``, ``A``, ``G`` 2-D) and compiles nothing
    else: any other argument (``None``, a sparse matrix, a list, another
    dtype or layout) raises ``TypeError`` in numba's dispatcher, which is the
    whole type check of the online backend's per-tick path. Without
    ``strict`` it compiles for what it is given (the general path, also
    called by :func:`packed_kernel`). Both compile the same code and give the
    same numbers.
    """
    fn = _ONLINE.get(strict)
    if fn is None:
        import numba

        kernel(True)  # binds the integrator the tick calls
        if strict:
            a1 = numba.types.Array(numba.float64, 1, "C")
            a2 = numba.types.Array(numba.float64, 2, "C")
            sig = numba.int64(a2, a1, a2, a1, a2, a1, a1, a1, a1, a1, a1)
            fn = numba.njit(sig, cache=True)(_online_tick_loops)
        else:
            fn = numba.njit(cache=True)(_online_tick_loops)
        _ONLINE[strict] = fn
    return fn


def packed_kernel() -> Callable:
    """The per-tick kernel on a packed buffer: ``f(buffer, xi, prm, sol) -> code``.

    Compiled for 1-D C-contiguous float64 arrays only. Returned is the
    compiled function's own entry point when numba exposes it: it skips the
    dispatcher's type matching (a quarter of a call's cost here), so every
    argument must be of that type. :class:`qpbench.packed.PackedProblem`
    guarantees it for its buffer (made by its checked constructor or by the
    controller, and never reassigned); the kernel checks the header against
    the buffer's length and the state before reading.
    """
    global _PACKED, _online_tick_jit, _part_fits_jit
    if _PACKED is None:
        import numba

        _online_tick_jit = online_kernel(strict=False)
        _part_fits_jit = numba.njit(cache=True, inline="always")(_part_fits)
        a1 = numba.types.Array(numba.float64, 1, "C")
        disp = numba.njit(numba.int64(a1, a1, a1, a1), cache=True)(_online_tick_packed_loops)
        try:
            _PACKED = disp.overloads[disp.signatures[0]].entry_point
        except (AttributeError, KeyError, IndexError):  # pragma: no cover - another numba
            _PACKED = disp
    return _PACKED

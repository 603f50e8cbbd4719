"""The network's kernels: its parameter block ``prm``, its step bound and its integrator as
loops (the ``*_jit`` names: docs/architecture.md, "The network")."""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache
from types import FunctionType
from typing import TYPE_CHECKING

import numpy as np

from ..exceptions import check_choice
from ..packed import HEADER

if TYPE_CHECKING:
    from collections.abc import Callable

#: Integration methods.
METHODS = ("euler", "semi-implicit")

#: Squarings in the trace-power bound of ``sigma_max(C)^2``.
SQUARINGS = 5

# Slots of the parameter block ``prm`` (:func:`make_params`).
#: Inputs.
PMIN, PMAX, SEMI, R_TOTAL, SUBSTEPS, SAFETY, MAX_STEPS, TOL, L1_CLIP = range(9)
#: Outputs.
PRIMAL, DUAL, COMPL, OBJ, RATIO, RATIO_MAX, SIG2 = range(9, 16)
#: Per-tick inputs (the residual bounds of ``optimal``, the state's equality count, -1: not
#: checked); output: the last call's step count (NaN: none yet).
OK_PRIMAL, OK_DUAL, STATE_ME, STEPS = range(16, 20)
#: Inputs: a fixed step's ratio (0: none), whether to clamp it; output: the steps it asked for.
R_STEP, CLAMP, NOMINAL = range(20, 23)
#: Output: what a fixed-duration call did against its setting (``NOTE_*``).
NOTE = 23
PRM_SIZE = 24

#: ``prm[NOTE]``: nothing; step clamped; no step proven stable; steps capped at ``MAX_STEPS``.
NOTE_NONE, NOTE_CLAMPED, NOTE_UNPROVEN, NOTE_CAPPED = 0, 1, 2, 3

#: Kernel return codes besides a step count.
NO_STABLE_STEP = -1
SHAPE_MISMATCH = -2
#: Per-tick kernel only: the state is no longer finite.
DIVERGED = -3


def make_params(
    *,
    p_range: tuple[float, float],
    method: str = "euler",
    r_total: float = 0.0,
    substeps: int = 0,
    safety: float = 0.9,
    max_steps: int = 100_000,
    tol: float = -1.0,
    l1_clip: float | None = None,
    step_ratio: float = 0.0,
    clamp: bool = True,
) -> np.ndarray:
    """The parameter block ``prm``. Fixed duration ``r_total = duration / eps > 0``: steps of
    ratio ``<= step_ratio``, else ``substeps``, else the fewest with ``r <= safety * ratio_max``
    (``clamp``: a forced step above it shortened); else ``r = safety * ratio_max`` until the
    residuals are ``<= tol`` or ``max_steps``. ``p_range``: ``P``'s eigenvalue range."""
    check_choice(method, METHODS, "method", "method")
    prm = np.zeros(PRM_SIZE)  # NOTE_NONE
    prm[PMIN], prm[PMAX] = p_range
    prm[[R_TOTAL, SUBSTEPS, SAFETY]] = r_total, substeps, safety
    prm[[MAX_STEPS, TOL, R_STEP]] = max_steps, tol, step_ratio
    prm[SEMI] = 1.0 if method == "semi-implicit" else 0.0
    prm[L1_CLIP] = np.inf if l1_clip is None else l1_clip
    prm[CLAMP] = 1.0 if clamp else 0.0
    prm[OK_PRIMAL] = prm[OK_DUAL] = prm[STATE_ME] = -1.0
    prm[STEPS] = np.nan
    return prm


@dataclass
class IntegrationResult:
    """What one integration did: ``steps`` (or ``NO_STABLE_STEP``); inf-norm residuals, primal
    ``max(|A v - b|, [G v - h]^+, [lb - v]^+, [v - ub]^+)``, dual ``|v - P_Omega(v - g)|`` (15a),
    complementarity ``|l2 - max(l2 + G v - h, 0)|``; ``ratio`` ``r = h / eps`` and its bound."""

    steps: int
    primal_residual: float
    dual_residual: float
    complementarity: float
    objective: float
    ratio: float
    ratio_max: float
    sigma2_bound: float
    nominal_steps: int = 0

    @property
    def clamped(self) -> bool:
        """The setting's step exceeded the stability bound and was shortened."""
        return self.steps > self.nominal_steps > 0


def result(prm: np.ndarray) -> IntegrationResult:
    """The :class:`IntegrationResult` of the last kernel call on ``prm``."""
    out = prm[[STEPS, PRIMAL, DUAL, COMPL, OBJ, RATIO, RATIO_MAX, SIG2, NOMINAL]].tolist()
    return IntegrationResult(int(out[0]), *out[1:-1], int(out[-1]))


def step_note(prm: np.ndarray) -> str | None:
    """What the last fixed-step call did against the setting (:data:`NOTE`), or ``None``."""
    note = prm[NOTE]
    nominal, steps = int(prm[NOMINAL]), int(prm[STEPS])
    if note == NOTE_CLAMPED:
        r_set = prm[R_TOTAL] / nominal
        return (
            f"step clamped to the stability bound: r = h/eps = {r_set:.3g} > {prm[SAFETY]:g} x {prm[RATIO_MAX]:.3g}; "
            f"{steps} steps instead of {nominal}"
        )
    if note == NOTE_UNPROVEN:
        return f"no step size is proven stable (P not positive definite); {steps} steps as set"
    if note == NOTE_CAPPED:
        return (
            f"step above the stability bound: r = h/eps = {prm[RATIO]:.3g} > {prm[SAFETY]:g} x {prm[RATIO_MAX]:.3g} "
            f"even at the step budget ({steps} steps, max_iter)"
        )
    return None


def ratio_max(pmin, pmax, sig2, semi):
    """Largest stable ``r = h/eps`` (derivation: docs/architecture.md); 0 if none."""
    if pmin <= 0.0:
        return 0.0
    if semi and pmin == pmax:
        return min(2.0 / pmax, 4.0 / (pmax + math.sqrt(pmax * pmax + 4.0 * sig2)))
    bound = 2.0 / pmax
    if sig2 > 0.0:
        bound = min(bound, pmin / sig2)
    return bound


def _gershgorin(P):
    """``(lower, upper, exact)``: Gershgorin bounds of ``(P + P^T) / 2`` (exact if diagonal)."""
    n = P.shape[0]
    lo = np.inf
    hi = -np.inf
    exact = True
    for i in range(n):
        radius = 0.0
        for j in range(n):
            if j != i:
                radius += abs(0.5 * (P[i, j] + P[j, i]))
        if radius != 0.0:
            exact = False
        lo = min(lo, P[i, i] - radius)
        hi = max(hi, P[i, i] + radius)
    if n == 0:
        return 1.0, 1.0, True
    return lo, hi, exact


def _frobenius2(A, G):
    """``|A|_F^2 + |G|_F^2``: an upper bound on ``sigma_max([A; G])^2``."""
    t = 0.0
    for i in range(A.shape[0]):
        for j in range(A.shape[1]):
            t += A[i, j] * A[i, j]
    for i in range(G.shape[0]):
        for j in range(G.shape[1]):
            t += G[i, j] * G[i, j]
    return t


def nominal_steps(r_total, r_step, substeps):
    """Steps of a fixed-duration call before any clamp (0: the bound decides)."""
    if r_total <= 0.0:
        return 0
    if r_step > 0.0:
        return max(1, int(math.ceil(r_total / r_step - 1e-9)))
    return substeps


def clamped_steps(r_total, r_max, at_least, max_steps):
    """The fewest steps (at least ``at_least``, at most ``max_steps``) of ratio ``<= r_max``."""
    need = r_total / r_max
    if not need < max_steps:  # also a tiny or zero bound (need inf or NaN)
        return int(max(at_least, max_steps))
    return max(at_least, int(math.ceil(need)))


def sigma2_bound(A, G):
    """Upper bound on ``lambda_max(A^T A + G^T G)``: ``tr(B^(2^k))^(1/2^k)``, ``k = SQUARINGS``."""
    n = A.shape[1]
    B, C = np.empty((n, n)), np.zeros((n, n))
    for k in range(A.shape[0]):
        for i in range(n):
            for j in range(n):
                C[i, j] += A[k, i] * A[k, j]
    for k in range(G.shape[0]):
        for i in range(n):
            for j in range(n):
                C[i, j] += G[k, i] * G[k, j]
    logc = 0.0
    for squaring in range(SQUARINGS + 1):  # C: the Gram matrix, then B^2; B: C / tr(C)
        if squaring:
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
    return math.exp(logc / 2.0**SQUARINGS)


def _matvec(M, xi, y):
    """``y = M @ xi[: M.shape[1]]``."""
    for i in range(M.shape[0]):
        s = 0.0
        for j in range(M.shape[1]):
            s += M[i, j] * xi[j]
        y[i] = s


def _grad_products(P, q, A, G, xi, g, Av, Gv, products):
    """``g = P v + q - A^T l1 + G^T l2`` and, with ``products``, ``Av = A v``, ``Gv = G v``."""
    n = P.shape[0]
    for j in range(n):
        s = q[j]
        for k in range(n):
            s += P[j, k] * xi[k]
        g[j] = s
    _add_rows_jit(A, xi, n, -1.0, g, Av, products)
    _add_rows_jit(G, xi, n + A.shape[0], 1.0, g, Gv, products)


def _add_rows(M, xi, off, sign, g, Mv, products):
    """``g += sign M^T xi[off:]`` (``-a c`` as ``a (-c)``: the same numbers) and, with
    ``products``, ``Mv = M v``: one pass over each row."""
    for i in range(M.shape[0]):
        c = sign * xi[off + i]
        s = 0.0
        for j in range(M.shape[1]):
            a = M[i, j]
            s += a * xi[j]
            g[j] += a * c
        if products:
            Mv[i] = s


def _step(P, q, A, b, G, h, lb, ub, xi, g, Av, Gv, r, semi, l1_clip):
    """One step of ratio ``r`` from ``xi`` and its ``g`` (and ``Av``, ``Gv``); refreshes them."""
    n = q.shape[0]
    me = b.shape[0]
    mi = h.shape[0]
    o1 = n
    o2 = n + me
    for j in range(n):
        w = min(max(xi[j] - g[j], lb[j]), ub[j])
        xi[j] += r * (w - xi[j])
    if semi:
        _matvec_jit(A, xi, Av)
        _matvec_jit(G, xi, Gv)
    for i in range(me):
        xi[o1 + i] += r * (b[i] - Av[i])
        if l1_clip < np.inf:
            xi[o1 + i] = min(max(xi[o1 + i], -l1_clip), l1_clip)
    for i in range(mi):
        xi[o2 + i] += r * (max(xi[o2 + i] + Gv[i] - h[i], 0.0) - xi[o2 + i])
    # the next step's g (and, for Euler, Av and Gv): one pass over each row
    _grad_products_jit(P, q, A, G, xi, g, Av, Gv, not semi)


def _residuals(b, h, lb, ub, xi, g, Av, Gv):
    """``(primal, dual, complementarity)`` residuals of the state, propagating NaN."""
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


# Over 80 lines: one compiled function, its per-step callees inlined by numba.
def _integrate_loops(P, q, A, b, G, h, lb, ub, xi, prm, sol):
    n = q.shape[0]
    me = b.shape[0]
    mi = h.shape[0]
    if (
        P.shape != (n, n)
        or A.shape != (me, n)
        or G.shape != (mi, n)
        or lb.shape[0] != n
        or ub.shape[0] != n
        or xi.shape[0] != n + me + mi
        or sol.shape[0] not in (0, 2 * n + me + mi, 3 * n + 2 * (me + mi))
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
            # the bound only when the step is above a cheap lower estimate of it
            glo, ghi, exact = _gershgorin_jit(P)
            low = _ratio_max_jit(glo, ghi, _frobenius2_jit(A, G), semi)
            if not r_total / nominal <= prm[SAFETY] * low:
                pmin = glo
                pmax = ghi
                if not exact:
                    w = np.linalg.eigvalsh(0.5 * (P + P.T))
                    pmin = w[0]
                    pmax = w[n - 1]
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


def _online_tick_loops(P, q, A, b, G, h, lb, ub, xi, prm, sol):  # pragma: no cover - compiled
    """:func:`_integrate_loops` and its verdict ``4 * steps + 2 * note + ok``, or a code < 0."""
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


def _part_fits(off, size, length):  # pragma: no cover - compiled
    return off >= HEADER and size >= 0 and off + size <= length


def _online_tick_packed_loops(buf, xi, prm, sol):  # pragma: no cover - compiled
    """:func:`_online_tick_loops` on views of a :class:`qpbench.packed.PackedProblem`'s buffer."""
    length = buf.shape[0]
    if length < HEADER:
        return SHAPE_MISMATCH
    n, me, mi = int(buf[0]), int(buf[1]), int(buf[2])
    if n < 1 or me < 0 or mi < 0 or n + me + mi != xi.shape[0]:
        return SHAPE_MISMATCH
    oP, oq, oA, ob = int(buf[3]), int(buf[4]), int(buf[5]), int(buf[6])
    oG, oh, olb, oub = int(buf[7]), int(buf[8]), int(buf[9]), int(buf[10])
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
        oA = ob = HEADER
    if mi == 0:
        oG = oh = HEADER
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


# The names the kernels call, compiled by kernel(), inlined except those of _CALLS.
_sigma2_bound_jit = sigma2_bound
_ratio_max_jit = ratio_max
_gershgorin_jit = _gershgorin
_frobenius2_jit = _frobenius2
_nominal_steps_jit = nominal_steps
_clamped_steps_jit = clamped_steps
_matvec_jit = _matvec
_grad_products_jit = _grad_products
_add_rows_jit = _add_rows
_step_jit = _step
_residuals_jit = _residuals
_integrate_jit = _integrate_loops
_online_tick_jit = _online_tick_loops
_part_fits_jit = _part_fits
_CALLS = ("_sigma2_bound_jit", "_ratio_max_jit", "_integrate_jit", "_online_tick_jit")
_COMPILED = None


def numba_available() -> bool:
    """Whether numba can be imported here."""
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


@cache
def _interpreted() -> Callable:
    """:func:`_integrate_loops` run by Python on the plain functions, whatever is compiled."""
    names = dict(globals())
    for name, fn in list(names.items()):
        if name.endswith("_jit"):
            names[name] = FunctionType(getattr(fn, "py_func", fn).__code__, names)
    return names["_integrate_jit"]


def kernel(use_numba: bool = True) -> Callable:
    """The integrator ``f(P, q, A, b, G, h, lb, ub, xi, prm, sol) -> steps`` (or a code < 0):
    ``xi = [v; l1; l2]`` updated in place, ``[x; y; z; z_box]`` into ``sol`` (or length 0)."""
    global _COMPILED
    if not use_numba:
        return _interpreted()
    if _COMPILED is None:
        from ..native import njit

        names = globals()
        for name in [k for k in names if k.endswith("_jit")]:
            inline = "never" if name in _CALLS else "always"
            names[name] = njit(inline=inline, nogil=False)(names[name])
        _COMPILED = names["_integrate_jit"]
    return _COMPILED


def _typed(fn, *ndims) -> Callable:
    """``fn`` compiled for C-contiguous float64 arrays of ``ndims`` dimensions, returning an
    int64 (the integrator it calls bound first)."""
    import numba

    from ..native import njit

    kernel(True)
    arrays = (numba.types.Array(numba.float64, d, "C") for d in ndims)
    return njit(numba.int64(*arrays), nogil=False)(fn)


@cache
def online_kernel() -> Callable:
    """:func:`_online_tick_loops` compiled for C-contiguous writable float64 arrays only."""
    return _typed(_online_tick_loops, 2, 1, 2, 1, 2, 1, 1, 1, 1, 1, 1)


@cache
def packed_kernel_dispatcher() -> Callable:
    """:func:`_online_tick_packed_loops` compiled for 1-D C-contiguous float64 arrays."""
    return _typed(_online_tick_packed_loops, 1, 1, 1, 1)


def packed_kernel() -> Callable:
    """:func:`packed_kernel_dispatcher`'s compiled function's entry point (no type matching)."""
    disp = packed_kernel_dispatcher()
    return disp.overloads[disp.signatures[0]].entry_point

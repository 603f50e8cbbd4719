"""The controller's compiled per-tick build (numba): kinematics, impedance reference (eq. 4),
escape-velocity bounds (eq. 11c) and obstacle rows (eqs. 8-10) of one tick's QP, written into one
packed buffer (:func:`packed_layout`, after the :mod:`qpbench.packed` header)."""

from __future__ import annotations

from functools import cache

import numpy as np

from ..packed import HEADER as PACKED_HEADER

# Layout of the kernel's parameter vector.
_T, _XDX, _XDY, _VDX, _VDY, _NX, _NY, _FD, _KP, _KD, _K, _DSAFE, _ALPHA, _RHO, _SOFT, _RADIUS = (
    range(16)
)
_NPAR = 16


@cache
def compiled_build_kernel():
    """The build kernel, compiled (or loaded from numba's cache) on the first call."""
    import numba

    return numba.njit(cache=True, fastmath=False, nogil=True)(_build_kernel_py)


def parameter_vector(
    normal, desired_force: float, k: float, d_safe: float, alpha: float, rho: float, radius: float
) -> np.ndarray:
    """The kernel's parameter vector with a controller's constants: pressing direction, ``Fd``
    [N], damper gain ``k`` [1/s], ``d_safe`` [m], escape gain ``alpha`` [1/s], ``rho``, key-point
    radius [m]. The controller sets the time, ``x_d``, ``xdot_d``, ``Kp``, ``Kd`` and the
    formulation flag (indices 0-4, 8, 9, 14) before each call."""
    par = np.zeros(_NPAR)
    constants = (*normal, desired_force, k, d_safe, alpha, rho, radius)
    par[[_NX, _NY, _FD, _K, _DSAFE, _ALPHA, _RHO, _RADIUS]] = constants
    return par


def packed_layout(n: int, n_rows: int) -> tuple[int, tuple[slice, ...]]:
    """Size of a tick's buffer and the slices of its P, q, G, h, J, b, lb, ub, ee and dist, in
    the order :func:`_build_kernel_py` lays them out."""
    sizes = (n * n, n, n_rows * n, n_rows, 2 * n, 2, n, n, 2, n_rows)
    ends = PACKED_HEADER + np.cumsum(sizes)
    return int(ends[-1]), tuple(slice(int(e - s), int(e)) for s, e in zip(sizes, ends))


# Over 80 lines, kept whole on purpose: numba compiles it as one function; split, each helper
# would have to be compiled too. Its numpy twin: tests/controller_numpy.py.
def _build_kernel_py(theta, lengths, kp_link, kp_frac, prims, lim, par, buf):  # pragma: no cover
    """Fill P, q, G, h, J, b (= b0), lb, ub, ee and dist of one tick into ``buf`` (layout of
    :func:`packed_layout`) and write its header."""
    n = theta.shape[0]
    nr = (buf.shape[0] - PACKED_HEADER - n * n - 5 * n - 4) // (n + 2)
    oP = PACKED_HEADER
    oq = oP + n * n
    oG = oq + n
    oh = oG + nr * n
    oJ = oh + nr
    ob = oJ + 2 * n
    olb = ob + 2
    oub = olb + n
    oee = oub + n
    od = oee + 2
    soft = par[_SOFT] != 0.0
    buf[0] = n
    buf[1] = 0 if soft else 2
    buf[2] = nr
    buf[3] = oP
    buf[4] = oq
    buf[5] = -1 if soft else oJ
    buf[6] = -1 if soft else ob
    buf[7] = oG if nr > 0 else -1
    buf[8] = oh if nr > 0 else -1
    buf[9] = olb
    buf[10] = oub
    P = buf[oP:oq].reshape((n, n))
    q = buf[oq:oG]
    G = buf[oG:oh].reshape((nr, n))
    h = buf[oh:oJ]
    J = buf[oJ:ob].reshape((2, n))
    b = buf[ob:olb]
    lb = buf[olb:oub]
    ub = buf[oub:oee]
    ee = buf[oee:od]
    dist = buf[od : od + nr]
    px = np.empty(n + 1)
    py = np.empty(n + 1)
    cs = np.empty(n)
    sn = np.empty(n)
    px[0] = 0.0
    py[0] = 0.0
    phi = 0.0
    for i in range(n):
        phi += theta[i]
        cs[i] = np.cos(phi)
        sn[i] = np.sin(phi)
        px[i + 1] = px[i] + lengths[i] * cs[i]
        py[i + 1] = py[i] + lengths[i] * sn[i]
    ex = px[n]
    ey = py[n]
    ee[0] = ex
    ee[1] = ey
    for k in range(n):
        J[0, k] = -(ey - py[k])
        J[1, k] = ex - px[k]
    # impedance reference, eq. 4
    kd = par[_KD]
    kpkd = par[_KP] / kd
    fkd = par[_FD] / kd
    b[0] = par[_VDX] - kpkd * (ex - par[_XDX]) + fkd * par[_NX]
    b[1] = par[_VDY] - kpkd * (ey - par[_XDY]) + fkd * par[_NY]
    # escape-velocity bounds, eq. 11c
    alpha = par[_ALPHA]
    for k in range(n):
        lo = alpha * (lim[0, k] - theta[k])
        vmin = lim[2, k]
        lb[k] = lo if lo > vmin else vmin
        up = alpha * (lim[1, k] - theta[k])
        vmax = lim[3, k]
        ub[k] = up if up < vmax else vmax
    # objective
    if soft:
        rho = par[_RHO]
        for r in range(n):
            for c in range(n):
                P[r, c] = rho * (J[0, r] * J[0, c] + J[1, r] * J[1, c])
            P[r, r] += 1.0
            q[r] = -rho * (J[0, r] * b[0] + J[1, r] * b[1])
    else:
        for r in range(n):
            for c in range(n):
                P[r, c] = 0.0
            P[r, r] = 1.0
            q[r] = 0.0
    # obstacle rows, eqs. 8-10 with the velocity-damper signs
    nb = prims.shape[0]
    t = par[_T]
    kgain = par[_K]
    dsafe = par[_DSAFE]
    radius = par[_RADIUS]
    for i in range(kp_link.shape[0]):
        L = kp_link[i]
        f = kp_frac[i] * lengths[L]
        ax = px[L] + f * cs[L]
        ay = py[L] + f * sn[L]
        for j in range(nb):
            kind = int(prims[j, 0])
            vx = prims[j, 6]
            vy = prims[j, 7]
            bx = prims[j, 1] + vx * t
            by = prims[j, 2] + vy * t
            if kind == 0:  # line, signed distance, u = normal
                ux = prims[j, 3]
                uy = prims[j, 4]
                d = (ax - bx) * ux + (ay - by) * uy
            else:
                if kind == 1:  # segment
                    abx = prims[j, 3] - prims[j, 1]
                    aby = prims[j, 4] - prims[j, 2]
                    s = ((ax - bx) * abx + (ay - by) * aby) / (abx * abx + aby * aby)
                    if s < 0.0:
                        s = 0.0
                    elif s > 1.0:
                        s = 1.0
                    bx += s * abx
                    by += s * aby
                dx = ax - bx
                dy = ay - by
                d = np.sqrt(dx * dx + dy * dy)
                if d > 0.0:
                    ux = dx / d
                    uy = dy / d
                else:
                    ux = 0.0
                    uy = 0.0
                if kind == 2:  # disk
                    d -= prims[j, 5]
            d -= radius
            r = i * nb + j
            for k in range(n):
                if k <= L:
                    G[r, k] = -(ux * (py[k] - ay) + uy * (ax - px[k]))
                else:
                    G[r, k] = 0.0
            h[r] = kgain * (d - dsafe) - (ux * vx + uy * vy)
            dist[r] = d

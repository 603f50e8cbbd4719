"""The controller's compiled per-tick build (numba): desired path, kinematics, impedance reference
(eq. 4), escape-velocity bounds (eq. 11c) and obstacle rows (eqs. 8-10) of one tick's QP, written
into one packed buffer (:func:`packed_layout`, after the :mod:`qpbench.packed` header).

Everything the build reads is named in one :class:`ControllerModel`; kinematics
(:func:`_chain_points`) and obstacle distances (:func:`_distance`) are functions of it, so the
build itself does not depend on how the arm or an obstacle is described.
"""

from __future__ import annotations

from functools import cache
from typing import NamedTuple

import numpy as np

from ..packed import HEADER as PACKED_HEADER
from ..robot.environment import DISK, KIND, LINE, P0X, P0Y, P1X, P1Y, RADIUS, SEGMENT, VX, VY

#: ``ControllerModel.path_kind``: ``x_d(t)`` per axis a cosine, or a polyline.
COSINE, POLYLINE = 0, 1


class ControllerModel(NamedTuple):
    """The constants of the paper's controller as the compiled kernels read them.

    Arm: planar serial chain of link ``lengths`` (n,) [m]. Key points: link index ``key_link``
    (a,) and fraction ``key_frac`` (a,) of the link's length, each a disk of ``key_radius``
    [m]. ``obstacles``: the obstacle table (m, :data:`~qpbench.robot.environment.OBSTACLE_COLUMNS`),
    one row per obstacle point at t = 0. Limits ``theta_min, theta_max`` [rad], ``v_min, v_max``
    [rad/s] (n,), escape gain ``alpha`` [1/s]. Task: pressing ``normal`` (2,), ``desired_force``
    [N]; damper gain ``k`` [1/s], ``d_safe`` [m]; ``rho`` [s^2/m^2] the task weight of the
    ``soft`` formulation. Path ``x_d(t)``: ``path_kind`` :data:`COSINE` with ``path_cosine`` =
    centre (2), amplitude (2) [m], omega (2) [rad/s], phase (2) [rad]; or :data:`POLYLINE`
    through ``path_points`` (p, 2) [m] at ``path_times`` (p,) [s].
    """

    lengths: np.ndarray
    key_link: np.ndarray
    key_frac: np.ndarray
    key_radius: float
    obstacles: np.ndarray
    theta_min: np.ndarray
    theta_max: np.ndarray
    v_min: np.ndarray
    v_max: np.ndarray
    alpha: float
    normal: np.ndarray
    desired_force: float
    k: float
    d_safe: float
    rho: float
    path_kind: int
    path_cosine: np.ndarray
    path_times: np.ndarray
    path_points: np.ndarray


@cache
def compiled_path():
    """``desired_state(kind, cosine, times, points, t, out)``: ``out = [x_d (2), xdot_d (2)]``
    [m, m/s] at ``t`` [s] of a path given as :class:`ControllerModel`'s ``path_*`` fields."""
    from ..native import compile_with

    return compile_with(_desired_state_py, name="desired_state", inline="always")


@cache
def compiled_build_kernel():
    """The build kernel ``build(model, theta, t, kp, kd, soft, buf)``, compiled (or loaded from
    numba's cache) on the first call."""
    from ..native import compile_with

    # inlined into the build (numba's IR): no call, no reference counts per tick
    helpers = {
        "_desired_state_py": compiled_path(),
        "_chain_points": compile_with(_chain_points, name="chain_points", inline="always"),
        "_distance": compile_with(_distance, name="obstacle_distance", inline="always"),
    }
    return compile_with(_build_kernel_py, helpers, name="build_tick")


def packed_layout(n: int, n_rows: int) -> tuple[int, tuple[slice, ...]]:
    """Size of a tick's buffer and the slices of its P, q, G, h, J, b, lb, ub, ee, dist and
    ``x_d = (x_d, xdot_d)``, in the order :func:`_build_kernel_py` lays them out; the buffer
    ends with the build's scratch, so a tick allocates nothing."""
    # scratch: joint positions px, py (n+1), link directions cs, sn (n), a direction u (2)
    sizes = (n * n, n, n_rows * n, n_rows, 2 * n, 2, n, n, 2, n_rows, 4, 4 * n + 4)
    ends = PACKED_HEADER + np.cumsum(sizes)
    return int(ends[-1]), tuple(slice(int(e - s), int(e)) for s, e in zip(sizes[:-1], ends))


def _desired_state_py(kind, c, times, pts, t, out):  # pragma: no cover - compiled
    """``x_d(t)``, ``xdot_d(t)`` of a path (:class:`ControllerModel`'s ``path_*``) into ``out``
    (4,); a polyline holds its first point before its first time and its last point after its
    last."""
    if kind == COSINE:
        for i in range(2):
            s = c[4 + i] * t + c[6 + i]
            out[i] = c[i] + c[2 + i] * np.cos(s)
            out[2 + i] = -c[2 + i] * c[4 + i] * np.sin(s)
        return
    last = times.shape[0] - 1
    if t <= times[0] or t >= times[last]:
        j = 0 if t <= times[0] else last
        out[0], out[1], out[2], out[3] = pts[j, 0], pts[j, 1], 0.0, 0.0
        return
    i = np.searchsorted(times, t, side="right") - 1
    span = times[i + 1] - times[i]
    s = (t - times[i]) / span
    for a in range(2):
        step = pts[i + 1, a] - pts[i, a]
        out[a] = pts[i, a] + s * step
        out[2 + a] = step / span


def _chain_points(cm, theta, px, py, cs, sn):  # pragma: no cover - compiled
    """Planar forward kinematics (eq. 1): joint positions ``px, py`` (n+1,) [m] and each link's
    direction ``cs, sn`` (n,)."""
    n = theta.shape[0]
    px[0] = 0.0
    py[0] = 0.0
    phi = 0.0
    for i in range(n):
        phi += theta[i]
        cs[i] = np.cos(phi)
        sn[i] = np.sin(phi)
        px[i + 1] = px[i] + cm.lengths[i] * cs[i]
        py[i + 1] = py[i] + cm.lengths[i] * sn[i]


def _distance(row, ax, ay, t, u):  # pragma: no cover - compiled
    """Signed distance [m] of point ``(ax, ay)`` to obstacle point ``row`` of the table at ``t``
    [s] (its radius included), and in ``u`` (2,) the unit direction from the obstacle to the
    point (the normal of a line; zero at distance 0)."""
    kind = int(row[KIND])
    bx = row[P0X] + row[VX] * t
    by = row[P0Y] + row[VY] * t
    if kind == LINE:  # signed distance, u = normal
        u[0] = row[P1X]
        u[1] = row[P1Y]
        return (ax - bx) * u[0] + (ay - by) * u[1]
    if kind == SEGMENT:
        abx = row[P1X] - row[P0X]
        aby = row[P1Y] - row[P0Y]
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
        u[0] = dx / d
        u[1] = dy / d
    else:
        u[0] = 0.0
        u[1] = 0.0
    if kind == DISK:
        d -= row[RADIUS]
    return d


# Over 80 lines, kept whole on purpose: numba compiles it as one function. Its numpy twin:
# tests/controller_numpy.py.
def _build_kernel_py(cm, theta, t, kp, kd, soft, buf):  # pragma: no cover - compiled
    """Fill P, q, G, h, J, b (= b0), lb, ub, ee, dist and x_d of one tick at joint angles
    ``theta`` [rad], time ``t`` [s], interaction coefficients ``kp`` [N/m], ``kd`` [N s/m] into
    ``buf`` (layout of :func:`packed_layout`; ``soft``: the soft formulation) and write its
    header."""
    n = theta.shape[0]
    nr = (buf.shape[0] - PACKED_HEADER - n * n - 9 * n - 12) // (n + 2)  # packed_layout's sizes
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
    oxd = od + nr
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
    dist = buf[od:oxd]
    xd = buf[oxd : oxd + 4]
    o = oxd + 4
    px, py = buf[o : o + n + 1], buf[o + n + 1 : o + 2 * n + 2]
    cs, sn, u = buf[o + 2 * n + 2 : o + 3 * n + 2], buf[o + 3 * n + 2 : o + 4 * n + 2], buf[-2:]
    u[0] = 0.0  # the whole buffer is the tick's, scratch included: no stale memory in it
    u[1] = 0.0
    _desired_state_py(cm.path_kind, cm.path_cosine, cm.path_times, cm.path_points, t, xd)
    _chain_points(cm, theta, px, py, cs, sn)
    ex = px[n]
    ey = py[n]
    ee[0] = ex
    ee[1] = ey
    for k in range(n):
        J[0, k] = -(ey - py[k])
        J[1, k] = ex - px[k]
    # impedance reference, eq. 4
    kpkd = kp / kd
    fkd = cm.desired_force / kd
    b[0] = xd[2] - kpkd * (ex - xd[0]) + fkd * cm.normal[0]
    b[1] = xd[3] - kpkd * (ey - xd[1]) + fkd * cm.normal[1]
    # escape-velocity bounds, eq. 11c
    alpha = cm.alpha
    for k in range(n):
        lo = alpha * (cm.theta_min[k] - theta[k])
        vmin = cm.v_min[k]
        lb[k] = lo if lo > vmin else vmin
        up = alpha * (cm.theta_max[k] - theta[k])
        vmax = cm.v_max[k]
        ub[k] = up if up < vmax else vmax
    # objective
    if soft:
        rho = cm.rho
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
    obstacles = cm.obstacles
    nb = obstacles.shape[0]
    for i in range(cm.key_link.shape[0]):
        L = cm.key_link[i]
        f = cm.key_frac[i] * cm.lengths[L]
        ax = px[L] + f * cs[L]
        ay = py[L] + f * sn[L]
        for j in range(nb):
            row = obstacles[j]
            d = _distance(row, ax, ay, t, u) - cm.key_radius
            r = i * nb + j
            for k in range(n):
                if k <= L:
                    G[r, k] = -(u[0] * (py[k] - ay) + u[1] * (ax - px[k]))
                else:
                    G[r, k] = 0.0
            h[r] = cm.k * (d - cm.d_safe) - (u[0] * row[VX] + u[1] * row[VY])
            dist[r] = d

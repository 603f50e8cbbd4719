"""The controller's compiled per-tick build (numba): desired path, kinematics, impedance reference
(eq. 4), escape-velocity bounds (eq. 11c) and obstacle rows (eqs. 8-10) of one tick's QP, written
into one packed buffer (:func:`packed_layout`, after the :mod:`qpbench.packed` header).

One build for a planar (``dim`` 2) or a spatial (``dim`` 3) arm: everything it reads is named in
one :class:`ControllerModel`; the kinematics are the chain's (:mod:`qpbench.robot.chain`) and
the distances the obstacle registry's (:func:`~qpbench.robot.obstacles.compiled_segment_distance`),
so the build does not depend on how the arm or an obstacle is described.
"""

from __future__ import annotations

from functools import cache
from typing import NamedTuple

import numpy as np

from ..packed import HEADER as PACKED_HEADER
from ..robot.chain import ChainData, ChainModel
from ..robot.obstacles import VX, VY, VZ

#: ``ControllerModel.path_kind``: ``x_d(t)`` per axis a cosine, or a polyline.
COSINE, POLYLINE = 0, 1


class ControllerModel(NamedTuple):
    """The constants of the paper's controller as the compiled kernels read them, and the
    workspace of its build (held once per run, written every tick).

    Arm: the ``chain`` (:class:`~qpbench.robot.chain.ChainModel`, ``dim`` 2 or 3) and its
    kinematics' workspace ``data``. Guarded elements (a,): link ``key_link``, from fraction
    ``key_f0`` to ``key_f1`` of it (a key point of the paper: ``f0 = f1``; a whole link, kind
    ``closest``: 0 to 1), a capsule of ``key_radius`` [m]. Obstacle row r (nr,) keeps element
    ``row_key[r]`` from primitive ``row_prim[r]`` of the obstacle table ``obstacles`` (m,
    :data:`~qpbench.robot.obstacles.OBSTACLE_COLUMNS`, at t = 0). Limits ``theta_min,
    theta_max`` [rad], ``v_min, v_max`` [rad/s] (n,), escape gain ``alpha`` [1/s]. Task:
    pressing ``normal`` (dim,), ``desired_force`` [N]; damper gain ``k`` [1/s], ``d_safe`` [m];
    ``rho`` [s^2/m^2] the task weight of the ``soft`` formulation. Path ``x_d(t)``:
    ``path_kind`` :data:`COSINE` with ``path_cosine`` = centre, amplitude [m], omega [rad/s],
    phase [rad] (dim each); or :data:`POLYLINE` through ``path_points`` (p, dim) [m] at
    ``path_times`` (p,) [s]. ``scratch`` (9,): the build's 3-vectors.
    """

    chain: ChainModel
    data: ChainData
    key_link: np.ndarray
    key_f0: np.ndarray
    key_f1: np.ndarray
    key_radius: float
    row_key: np.ndarray
    row_prim: np.ndarray
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
    scratch: np.ndarray


@cache
def compiled_path():
    """``desired_state(kind, cosine, times, points, t, out)``: ``out = [x_d (dim), xdot_d
    (dim)]`` [m, m/s] at ``t`` [s] of a path given as :class:`ControllerModel`'s ``path_*``
    fields (``dim``: half of ``out``'s length)."""
    from ..native import compile_with

    return compile_with(_desired_state_py, name="desired_state", inline="always")


@cache
def compiled_build_kernel():
    """The build kernel ``build(model, theta, t, kp, kd, soft, buf)``, compiled (or loaded from
    numba's cache) on the first call; inlined into a compiled caller (why:
    :mod:`qpbench.engine.compiled`)."""
    from ..native import compile_with
    from ..robot.chain import compiled_chain
    from ..robot.obstacles import compiled_segment_distance

    # the path inlined into the build (numba's IR); the kinematics and distances are calls
    # (inlined, no gain measured: bench/README.md)
    helpers = {
        "_desired_state_py": compiled_path(),
        "_forward_kinematics": compiled_chain().forward_kinematics,
        "_segment_distance": compiled_segment_distance(),
    }
    return compile_with(_build_kernel_py, helpers, name="build_tick", inline="always")


def packed_layout(n: int, n_rows: int, dim: int = 2) -> tuple[int, tuple[slice, ...]]:
    """Size of a tick's buffer and the slices of its P, q, G, h, J, b, lb, ub, ee, dist and
    ``x_d = (x_d, xdot_d)``, in the order :func:`_build_kernel_py` lays them out (``dim``: the
    task's rows)."""
    sizes = (n * n, n, n_rows * n, n_rows, dim * n, dim, n, n, dim, n_rows, 2 * dim)
    ends = PACKED_HEADER + np.cumsum(sizes)
    return int(ends[-1]), tuple(slice(int(e - s), int(e)) for s, e in zip(sizes, ends))


def _desired_state_py(kind, c, times, pts, t, out):  # pragma: no cover - compiled
    """``x_d(t)``, ``xdot_d(t)`` of a path (:class:`ControllerModel`'s ``path_*``) into ``out``
    (2 dim,); a polyline holds its first point before its first time and its last point after
    its last."""
    dim = out.shape[0] // 2
    if kind == COSINE:
        for i in range(dim):
            s = c[2 * dim + i] * t + c[3 * dim + i]
            out[i] = c[i] + c[dim + i] * np.cos(s)
            out[dim + i] = -c[dim + i] * c[2 * dim + i] * np.sin(s)
        return
    last = times.shape[0] - 1
    if t <= times[0] or t >= times[last]:
        j = 0 if t <= times[0] else last
        for a in range(dim):
            out[a] = pts[j, a]
            out[dim + a] = 0.0
        return
    i = np.searchsorted(times, t, side="right") - 1
    span = times[i + 1] - times[i]
    s = (t - times[i]) / span
    for a in range(dim):
        step = pts[i + 1, a] - pts[i, a]
        out[a] = pts[i, a] + s * step
        out[dim + a] = step / span


# Over 80 lines, kept whole on purpose: numba compiles it as one function. Its numpy twin:
# tests/controller_numpy.py. It indexes the buffer by offset rather than through views (a view
# costs a reference count's increment and decrement, a reshape a call).
def _build_kernel_py(cm, theta, t, kp, kd, soft, buf):  # pragma: no cover - compiled
    """Fill P, q, G, h, J, b (= b0), lb, ub, ee, dist and x_d of one tick at joint angles
    ``theta`` [rad], time ``t`` [s], interaction coefficients ``kp`` [N/m], ``kd`` [N s/m] into
    ``buf`` (layout of :func:`packed_layout`; ``soft``: the soft formulation) and write its
    header."""
    n = theta.shape[0]
    dim = cm.normal.shape[0]
    nr = cm.row_key.shape[0]
    oP = PACKED_HEADER
    oq = oP + n * n
    oG = oq + n
    oh = oG + nr * n
    oJ = oh + nr
    ob = oJ + dim * n
    olb = ob + dim
    oub = olb + n
    oee = oub + n
    od = oee + dim
    oxd = od + nr
    buf[0] = n
    buf[1] = 0 if soft else dim
    buf[2] = nr
    buf[3] = oP
    buf[4] = oq
    buf[5] = -1 if soft else oJ
    buf[6] = -1 if soft else ob
    buf[7] = oG if nr > 0 else -1
    buf[8] = oh if nr > 0 else -1
    buf[9] = olb
    buf[10] = oub
    _desired_state_py(
        cm.path_kind, cm.path_cosine, cm.path_times, cm.path_points, t, buf[oxd : oxd + 2 * dim]
    )
    _forward_kinematics(cm.chain, theta, cm.data)  # noqa: F821 - bound
    p = cm.data.position
    w = cm.data.axis
    # end effector and its Jacobian: columns w_k x (x - p_k) (eq. 2); impedance reference, eq. 4
    kpkd = kp / kd
    fkd = cm.desired_force / kd
    for i in range(dim):
        buf[oee + i] = p[n, i]
        buf[ob + i] = buf[oxd + dim + i] - kpkd * (p[n, i] - buf[oxd + i]) + fkd * cm.normal[i]
    for k in range(n):
        dx, dy, dz = p[n, 0] - p[k, 0], p[n, 1] - p[k, 1], p[n, 2] - p[k, 2]
        buf[oJ + k] = w[k, 1] * dz - w[k, 2] * dy
        buf[oJ + n + k] = w[k, 2] * dx - w[k, 0] * dz
        if dim == 3:
            buf[oJ + 2 * n + k] = w[k, 0] * dy - w[k, 1] * dx
    # escape-velocity bounds, eq. 11c
    alpha = cm.alpha
    for k in range(n):
        lo = alpha * (cm.theta_min[k] - theta[k])
        vmin = cm.v_min[k]
        buf[olb + k] = lo if lo > vmin else vmin
        up = alpha * (cm.theta_max[k] - theta[k])
        vmax = cm.v_max[k]
        buf[oub + k] = up if up < vmax else vmax
    # objective
    rho = cm.rho
    for r in range(n):
        acc = 0.0
        for c in range(n):
            pc = 0.0
            if soft:
                for i in range(dim):
                    pc += buf[oJ + i * n + r] * buf[oJ + i * n + c]
                pc *= rho
            buf[oP + r * n + c] = pc
        buf[oP + r * n + r] += 1.0
        if soft:
            for i in range(dim):
                acc += buf[oJ + i * n + r] * buf[ob + i]
            acc *= -rho
        buf[oq + r] = acc
    # obstacle rows, eqs. 8-10 with the velocity-damper signs: element [a, e] of a link, its
    # point x = a + s (e - a) closest to the primitive, u the distance's gradient at x; each
    # row reads its primitive's row of the table (a cloud's cost linear in its points)
    a = cm.scratch[0:3]
    e = cm.scratch[3:6]
    u = cm.scratch[6:9]
    for r in range(nr):
        row = cm.obstacles[cm.row_prim[r]]
        i = cm.row_key[r]
        L = cm.key_link[i]
        f0, f1 = cm.key_f0[i], cm.key_f1[i]
        for c in range(3):
            step = p[L + 1, c] - p[L, c]
            a[c] = p[L, c] + f0 * step
            e[c] = p[L, c] + f1 * step
        d, s = _segment_distance(row, a, e, t, u)  # noqa: F821 - bound
        d -= cm.key_radius
        x0 = a[0] + s * (e[0] - a[0])
        x1 = a[1] + s * (e[1] - a[1])
        x2 = a[2] + s * (e[2] - a[2])
        g = oG + r * n
        for k in range(n):  # G = -u^T J_x, J_x's columns w_k x (x - p_k) up to link L
            if k <= L:
                dx, dy, dz = x0 - p[k, 0], x1 - p[k, 1], x2 - p[k, 2]
                buf[g + k] = -(
                    u[0] * (w[k, 1] * dz - w[k, 2] * dy)
                    + u[1] * (w[k, 2] * dx - w[k, 0] * dz)
                    + u[2] * (w[k, 0] * dy - w[k, 1] * dx)
                )
            else:
                buf[g + k] = 0.0
        toward = u[0] * row[VX] + u[1] * row[VY] + u[2] * row[VZ]  # the primitive's speed
        buf[oh + r] = cm.k * (d - cm.d_safe) - toward
        buf[od + r] = d

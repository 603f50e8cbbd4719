"""The closed loop's per-tick compiled step: write the tick's log row (:mod:`qpbench.sim.log`)
by named column, sense the end effector's velocity and the contact force, advance
``theta += dt v``. Both engines call it (:mod:`qpbench.sim.loop`, :mod:`qpbench.engine.compiled`).
"""

from __future__ import annotations

import math
from functools import cache
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from . import log

if TYPE_CHECKING:
    from collections.abc import Callable

    from ..control.controller import Controller

#: ``mode`` of the post kernel: the tick's own answer applied, the soft fallback's, zero velocity.
APPLIED, FALLBACK, ZERO = 0, 1, 2


#: The :class:`LogColumns` fields that index one column of the log, and that column.
_COLUMN_OF = {
    "t": log.T,
    "theta": log.theta_columns(1)[0],
    "v": log.velocity_columns(1)[0],
    "ee": log.EE_X,
    "force": log.FORCE,
    "d": log.D_MIN,
    "fallback": log.FALLBACK,
    "zero": log.ZERO_VELOCITY,
    "y": log.Y_0,
    "z_max": log.Z_MAX,
    "kp": log.KP_HAT,
    "kd": log.KD_HAT,
    "solve_time": log.SOLVE_TIME,
    "solver_time": log.SOLVER_TIME,
    "build_time": log.BUILD_TIME,
    "fallback_build_time": log.FALLBACK_BUILD_TIME,
    "fallback_solve_time": log.FALLBACK_SOLVE_TIME,
    "tick_time": log.TICK_TIME,
}

#: Indices of the tick log's float columns (:func:`qpbench.sim.log.float_columns`) the kernels
#: write: the first of ``theta_i``, ``v_i``; ``ee`` the first of ``ee_x, ee_y, [ee_z], xd_x,
#: xd_y, [xd_z], tracking_error``; ``force`` (then ``force_error``); ``d`` the first distance
#: column, whose points lie in ``dist_start[c]:dist_stop[c]`` of the flat distances (then
#: ``d_min``, ``v_sq``, ``task_residual``); ``y`` the first of ``y_0, y_1, [y_2]``.
LogColumns = NamedTuple(
    "LogColumns",
    [(name, int) for name in _COLUMN_OF] + [("dist_start", np.ndarray), ("dist_stop", np.ndarray)],
)


def log_columns(controller: Controller) -> tuple[list[str], LogColumns]:
    """The tick log's float columns for ``controller`` and their :class:`LogColumns`."""
    obstacle_cols = controller.obstacle_columns()
    cols = log.float_columns(controller.n, [(a, o) for a, o, _ in obstacle_cols], controller.dim)
    at = {c: i for i, c in enumerate(cols)}
    index = {name: at[column] for name, column in _COLUMN_OF.items()}
    index["d"] -= len(obstacle_cols)  # the first distance column, before d_min
    return cols, LogColumns(
        **index,
        dist_start=np.array([s.start for _, _, s in obstacle_cols], dtype=np.int64),
        dist_stop=np.array([s.stop for _, _, s in obstacle_cols], dtype=np.int64),
    )


@cache
def get_post_kernel() -> Callable:
    """The compiled :func:`_post_py` (compiled, or loaded from numba's cache, on first call);
    inlined into a compiled caller (why: :mod:`qpbench.engine.compiled`)."""
    from ..native import compile_with

    return compile_with(_post_py, name="post_tick", inline="always")


def _post_py(
    model, cols, theta, v, ee, sensed, J, b0, dist, xd, y, z, data, k, t, mode, kp, kd
):  # pragma: no cover - compiled
    """Log tick ``k`` into ``data[k]`` and advance the plant ``theta += dt v`` (``model``: the
    :class:`~qpbench.engine.model.RunModel`, ``cols``: :class:`LogColumns`); returns the
    noise-free contact force [N] (-1.0, nothing written, when ``v`` is not finite) and leaves
    the end-effector position [m] and velocity [m/s] in ``sensed`` (2 dim,). The tracking
    error [m]: ``t . (x - x_d)`` on a planar arm, ``|x - x_d|`` in the contact plane on a
    spatial one."""
    n = theta.shape[0]
    dim = ee.shape[0]
    for i in range(n):
        if not math.isfinite(v[i]):
            return -1.0
    row = data[k]
    dt = model.dt
    row[cols.t] = t
    row[cols.fallback] = 1.0 if mode == FALLBACK else 0.0
    row[cols.zero] = 1.0 if mode == ZERO else 0.0
    for i in range(y.shape[0]):
        row[cols.y + i] = y[i]
    for i in range(z.shape[0]):  # their max, NaN if any (np.max needs numba's runtime)
        if i == 0 or z[i] > row[cols.z_max] or z[i] != z[i]:
            row[cols.z_max] = z[i]
    row[cols.kp], row[cols.kd] = kp, kd
    # sense: velocity by finite difference, spring-damper force along the normal
    normal = model.controller.normal
    delta = ndot = 0.0
    for i in range(dim):
        xdot = (ee[i] - sensed[i]) / dt if k > 0 else 0.0
        sensed[i], sensed[dim + i] = ee[i], xdot
        delta += normal[i] * ee[i]
        ndot += normal[i] * xdot
    delta -= model.surface_offset
    force = 0.0
    if delta > 0.0:
        force = model.stiffness * delta + model.damping * ndot
        if force < 0.0:
            force = 0.0
    row[cols.force] = force
    row[cols.force + 1] = force - model.controller.desired_force
    vsq = 0.0
    for i in range(n):
        row[cols.theta + i] = theta[i]
        row[cols.v + i] = v[i]
        vsq += v[i] * v[i]
        theta[i] += dt * v[i]
    c_ee = cols.ee
    along = res = 0.0  # along: the tangential error (dim 2), the error along the normal (dim 3)
    for i in range(dim):
        row[c_ee + i] = ee[i]
        row[c_ee + dim + i] = xd[i]
        along += (model.tangent[i] if dim == 2 else normal[i]) * (ee[i] - xd[i])
        r = b0[i]
        for j in range(n):
            r -= J[i, j] * v[j]
        res += r * r
    if dim == 3:
        plane = 0.0
        for i in range(3):
            e = ee[i] - xd[i] - along * normal[i]
            plane += e * e
        along = math.sqrt(plane)
    row[c_ee + 2 * dim] = along
    ncol = cols.dist_start.shape[0]
    dmin = np.inf
    for c in range(ncol):
        m = np.inf
        for j in range(cols.dist_start[c], cols.dist_stop[c]):
            if dist[j] < m:
                m = dist[j]
        row[cols.d + c] = m
        if m < dmin:
            dmin = m
    row[cols.d + ncol] = dmin if ncol > 0 else np.nan
    row[cols.d + ncol + 1] = vsq
    row[cols.d + ncol + 2] = math.sqrt(res)
    return force

"""The closed loop's per-tick compiled step: write the tick's log row (:mod:`qpbench.sim.log`)
by index, sense the end effector's velocity and the contact force, advance ``theta += dt v``."""

from __future__ import annotations

import math
from functools import cache
from typing import TYPE_CHECKING

import numpy as np

from ..control.controller import Controller, TickArrays
from . import log

if TYPE_CHECKING:
    from collections.abc import Callable

    from ..robot.environment import ContactSurface


@cache
def get_post_kernel() -> Callable:
    """The compiled :func:`_post_py` (compiled, or loaded from numba's cache, on first call)."""
    import numba

    return numba.njit(cache=True, nogil=True)(_post_py)


#: ``mode`` of the post kernel: the tick's own answer applied, the soft fallback's, zero velocity.
APPLIED, FALLBACK, ZERO = 0, 1, 2

# Layout of the kernel's constant float block ``cf``: tangent (2), surface (6), dt.
_CF_TANGENT, _CF_SURF, _CF_DT = 0, 2, 8
# Layout of the kernel's constant int block ``ci``: 12 column indices, then the
# obstacle columns' [start, end) ranges in the flat distance array.
_CI_COLS = 12


def _post_py(
    theta, v, ee, sensed, J, b0, dist, xd, y, z, data, k, ci, cf, t, mode, kp, kd, solve_time
):  # pragma: no cover - compiled
    """Log tick ``k`` into ``data[k]`` and advance the plant ``theta += dt v``.

    Returns the noise-free contact force [N] (-1.0, nothing written, when ``v`` is not finite);
    leaves the end-effector position [m] and velocity [m/s] in ``sensed``.
    """
    n = theta.shape[0]
    for i in range(n):
        if not math.isfinite(v[i]):
            return -1.0
    row = data[k]
    dt = cf[_CF_DT]
    c_theta, c_v, c_ee, c_d, c_force = ci[0], ci[1], ci[2], ci[3], ci[4]
    row[0] = t
    row[ci[5]] = 1.0 if mode == FALLBACK else 0.0
    row[ci[6]] = 1.0 if mode == ZERO else 0.0
    row[ci[7]] = solve_time
    if y.shape[0] == 2:
        row[ci[8]] = y[0]
        row[ci[8] + 1] = y[1]
    if z.shape[0] > 0:
        zmax = z[0]
        for i in range(1, z.shape[0]):
            if z[i] > zmax:
                zmax = z[i]
        row[ci[9]] = zmax
    row[ci[10]] = kp
    row[ci[11]] = kd
    # sense: velocity by finite difference, spring-damper force
    xd0 = xd1 = 0.0
    if k > 0:
        xd0 = (ee[0] - sensed[0]) / dt
        xd1 = (ee[1] - sensed[1]) / dt
    sensed[0], sensed[1], sensed[2], sensed[3] = ee[0], ee[1], xd0, xd1
    # the contact force law (noise-free; surf = [nx, ny, n . point, stiffness, damping, Fd])
    nx, ny = cf[_CF_SURF], cf[_CF_SURF + 1]
    delta = nx * ee[0] + ny * ee[1] - cf[_CF_SURF + 2]
    force = 0.0
    if delta > 0.0:
        force = cf[_CF_SURF + 3] * delta + cf[_CF_SURF + 4] * (nx * xd0 + ny * xd1)
        if force < 0.0:
            force = 0.0
    row[c_force] = force
    row[c_force + 1] = force - cf[_CF_SURF + 5]
    vsq = 0.0
    for i in range(n):
        row[c_theta + i] = theta[i]
        row[c_v + i] = v[i]
        vsq += v[i] * v[i]
        theta[i] += dt * v[i]
    row[c_ee] = ee[0]
    row[c_ee + 1] = ee[1]
    row[c_ee + 2] = xd[0]
    row[c_ee + 3] = xd[1]
    row[c_ee + 4] = cf[_CF_TANGENT] * (ee[0] - xd[0]) + cf[_CF_TANGENT + 1] * (ee[1] - xd[1])
    r0, r1 = b0[0], b0[1]
    for j in range(n):
        r0 -= J[0, j] * v[j]
        r1 -= J[1, j] * v[j]
    ncol = (ci.shape[0] - _CI_COLS) // 2
    dmin = np.inf
    for c in range(ncol):
        m = np.inf
        for j in range(ci[_CI_COLS + c], ci[_CI_COLS + ncol + c]):
            if dist[j] < m:
                m = dist[j]
        row[c_d + c] = m
        if m < dmin:
            dmin = m
    row[c_d + ncol] = dmin if ncol > 0 else np.nan
    row[c_d + ncol + 1] = vsq
    row[c_d + ncol + 2] = math.sqrt(r0 * r0 + r1 * r1)
    return force


def post_constants(
    controller: Controller, surface: ContactSurface, dt: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The tick log's float columns and the post kernel's constant blocks ``(cols, cidx, ci, cf)``."""
    obstacle_cols = controller.obstacle_columns()
    cols = log.float_columns(controller.n, [(a, o) for a, o, _ in obstacle_cols])
    cidx = {c: i for i, c in enumerate(cols)}
    first = (log.theta_columns(1)[0], log.velocity_columns(1)[0], log.EE_X)
    flags = (log.FALLBACK, log.ZERO_VELOCITY, log.SOLVE_TIME, log.Y_0, log.Z_MAX)
    names = (*first, None, log.FORCE, *flags, log.KP_HAT, log.KD_HAT)  # None: the first distance
    ci = np.array(
        [cidx[log.D_MIN] - len(obstacle_cols) if c is None else cidx[c] for c in names]
        # log column c: its (key point, obstacle)'s points in the flat distance array
        + [s.start for _, _, s in obstacle_cols]
        + [s.stop for _, _, s in obstacle_cols],
        dtype=np.int64,
    )
    normal = controller.task.normal
    surf = [*normal, float(normal @ surface.point), surface.stiffness, surface.damping]
    # tangent, surface, Fd, dt
    cf = np.array([-normal[1], normal[0], *surf, controller.task.desired_force, dt])
    return cols, cidx, ci, cf


def warm_post_kernel(
    controller: Controller,
    surface: ContactSurface,
    dt: float,
    theta: np.ndarray,
    arrays: TickArrays,
) -> None:
    """Compile (or load) the post kernel for the argument types the loop passes (``theta`` is
    not changed)."""
    cols, _, ci, cf = post_constants(controller, surface, dt)
    post = get_post_kernel()
    none, v = np.zeros(0), np.zeros(controller.n)
    row = np.zeros((1, len(cols)))
    kp, kd = controller.kp, controller.kd
    geometry = (arrays.ee, np.zeros(4), arrays.J, arrays.b0, arrays.dist, arrays.xd)
    # an applied answer with duals, and a fallback/zero-velocity tick without
    for y, z, mode in (
        (np.zeros(2), np.zeros(max(controller.n_rows, 1)), APPLIED),
        (none, none, ZERO),
    ):
        post(theta.copy(), v, *geometry, y, z, row, 0, ci, cf, 0.0, mode, kp, kd, 0.0)

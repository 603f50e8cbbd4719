"""The controller: one control tick's QP (paper eq. 11) in joint velocities ``v`` [rad/s].

``paper`` (hard task, eq. 11)::

    minimize 1/2 v^T v   s.t.  J v = b0,  G v <= h,  lb <= v <= ub

``soft`` (task as a weighted cost; feasible whenever the robot is within its limits and static
obstacles are at least ``d_safe`` away)::

    minimize 1/2 v^T (I + rho J^T J) v - rho b0^T J v   s.t.  G v <= h,  lb <= v <= ub

``G`` holds one row per (key point, obstacle point) pair, key point major (a fixed count; no
obstacle: ``G = h = None``); key points of kind ``closest`` are built by the numpy terms
(:mod:`qpbench.control.terms`), the paper's by the compiled build
(:mod:`qpbench.control.build_kernel`) into one fresh buffer per tick.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import qpsolvers

from ..exceptions import ParamError
from ..native import entry_point
from ..packed import PackedProblem
from ..robot.environment import OBSTACLE_COLUMNS, Obstacle
from ..robot.kinematics import KeyPoints, PlanarArm
from ..statuses import FORMULATIONS
from .build_kernel import ControllerModel, compiled_build_kernel, packed_layout
from .terms import EscapeVelocityLimits, ImpedanceTask, closest_rows


class TickArrays(NamedTuple):
    """One tick's arrays: cost and obstacle rows ``P, q, G, h``, task row ``J v = b0`` (eq. 11),
    escape-velocity bounds ``lb, ub`` [rad/s], end effector ``ee`` [m], key-point distances
    ``dist`` [m] (flat, key point major), ``xd = (x_d, xdot_d)`` [m, m/s], the packed ``buffer``
    the others view (``None`` for key points of kind ``closest``)."""

    P: np.ndarray
    q: np.ndarray
    G: np.ndarray
    h: np.ndarray
    J: np.ndarray
    b0: np.ndarray
    lb: np.ndarray
    ub: np.ndarray
    ee: np.ndarray
    dist: np.ndarray
    xd: np.ndarray
    buffer: np.ndarray | None = None


@dataclass
class TickQP:
    """One tick's QP, its Jacobian ``J`` [m/rad], impedance reference ``b0`` (eq. 4) [m/s], end
    effector ``ee`` [m] and the ``distances`` of each key point to each obstacle point (a, m) [m]."""

    problem: qpsolvers.Problem
    J: np.ndarray
    b0: np.ndarray
    ee: np.ndarray
    distances: np.ndarray


class Controller:
    """Builds the per-tick QP of the paper's collision-free compliance controller.

    ``k``: obstacle damper gain [1/s]; ``d_safe`` [m]; ``rho``: task weight of the ``soft``
    formulation [s^2/m^2]; ``kp`` [N/m], ``kd`` [N s/m]: the interaction coefficients (an
    adaptive estimate overrides them per call); ``exempt``: per obstacle, it is the contact
    surface (no rows of the end effector's link against it, key points of kind ``closest``).
    """

    def __init__(
        self,
        arm: PlanarArm,
        key_points: KeyPoints,
        task: ImpedanceTask,
        limits: EscapeVelocityLimits,
        obstacles: list[Obstacle],
        k: float,
        d_safe: float,
        rho: float,
        kp: float,
        kd: float,
        exempt: list[bool] | None = None,
    ):
        self.arm = arm
        self.key_points = key_points
        self.task = task
        self.limits = limits
        self.obstacles = list(obstacles)
        self.k = float(k)
        self.d_safe = float(d_safe)
        self.rho = float(rho)
        self.kp = float(kp)
        self.kd = float(kd)
        self.n = arm.n
        self.points_per_obstacle = [o.n_points for o in self.obstacles]
        self.n_obstacle_points = int(sum(self.points_per_obstacle))
        self.closest = key_points.kind == "closest"
        self.exempt = list(exempt) if exempt is not None else [False] * len(self.obstacles)
        #: (key point, obstacle) pairs with rows, in row order; the end effector's link
        #: against the contact surface is left out for key points of kind ``closest``.
        self.pairs = [
            (i, j)
            for i in range(len(key_points))
            for j in range(len(self.obstacles))
            if not (self.closest and self.exempt[j] and i == self.n - 1)
        ]
        #: Inequality rows per tick (fixed).
        self.n_rows = sum(self.points_per_obstacle[j] for _, j in self.pairs)
        prims = [o.primitives() for o in self.obstacles] or [np.zeros((0, len(OBSTACLE_COLUMNS)))]
        path_kind, path_cosine, path_times, path_points = task.path.fields

        def f64(a):
            return np.ascontiguousarray(a, dtype=np.float64)

        #: Everything the compiled build reads (:class:`ControllerModel`).
        self.model = ControllerModel(
            lengths=f64(arm.lengths),
            key_link=np.ascontiguousarray(key_points.links, dtype=np.int64),
            key_frac=f64(key_points.fracs),
            key_radius=float(key_points.radius),
            obstacles=f64(np.vstack(prims)),
            theta_min=f64(limits.theta_min),
            theta_max=f64(limits.theta_max),
            v_min=f64(limits.v_min),
            v_max=f64(limits.v_max),
            alpha=float(limits.alpha),
            normal=f64(task.normal),
            desired_force=float(task.desired_force),
            k=self.k,
            d_safe=self.d_safe,
            rho=self.rho,
            path_kind=int(path_kind),
            path_cosine=f64(path_cosine),
            path_times=f64(path_times),
            path_points=f64(path_points),
        )
        self._packed_size, self._packed_slices = packed_layout(self.n, self.n_rows)
        self._build = None  # the compiled build for the model's types (on first use)

    # -- fast path -------------------------------------------------------------
    def build_arrays(
        self,
        theta: np.ndarray,
        t: float,
        kp: float | None = None,
        kd: float | None = None,
        soft: bool = False,
    ) -> TickArrays:
        """The tick's :class:`TickArrays`, freshly allocated (the loop's hot path: ``theta``
        must be a contiguous float64 array; :meth:`build` converts)."""
        if self.closest:
            return self._closest_arrays(theta, t, kp, kd, soft)
        n = self.n
        nr = self.n_rows
        kp = float(self.kp if kp is None else kp)
        kd = float(self.kd if kd is None else kd)
        buf = np.empty(self._packed_size)
        args = (self.model, theta, float(t), kp, kd, bool(soft), buf)
        if self._build is None:
            self._build = entry_point(compiled_build_kernel(), *args)
        self._build(*args)
        sP, sq, sG, sh, sJ, sb, slb, sub, see, sd, sxd = self._packed_slices
        return TickArrays(
            buf[sP].reshape(n, n),
            buf[sq],
            buf[sG].reshape(nr, n),
            buf[sh],
            buf[sJ].reshape(2, n),
            buf[sb],
            buf[slb],
            buf[sub],
            buf[see],
            buf[sd],
            buf[sxd],
            buf,
        )

    def make_problem(self, arrays: TickArrays, soft: bool) -> qpsolvers.Problem:
        """A :class:`qpsolvers.Problem` of :meth:`build_arrays`' output (a
        :class:`~qpbench.packed.PackedProblem` on the compiled build's buffer)."""
        P, q, G, h, J, b, lb, ub = arrays[:8]
        if self.n_rows == 0:
            G = h = None
        if soft:
            J = b = None
        if arrays.buffer is not None:  # one buffer (the kernel's): its header says the same
            return PackedProblem.from_views(arrays.buffer, P, q, G, h, J, b, lb, ub)
        return qpsolvers.Problem(P, q, G, h, J, b, lb, ub)

    def build(
        self,
        theta: np.ndarray,
        t: float,
        kp: float | None = None,
        kd: float | None = None,
        formulation: str = "paper",
    ) -> TickQP:
        """The tick's QP at joint angles ``theta`` [rad], time ``t`` [s], ``kp, kd`` (default: the
        controller's)."""
        soft = check_formulation(formulation)
        theta = np.ascontiguousarray(theta, dtype=np.float64)
        if theta.shape != (self.n,):
            raise ParamError(f"theta must have shape ({self.n},), got {theta.shape}", key="theta")
        arrays = self.build_arrays(theta, float(t), kp, kd, soft)
        problem = self.make_problem(arrays, soft)
        return TickQP(problem, arrays.J, arrays.b0, arrays.ee, self._distance_grid(arrays.dist))

    def _distance_grid(self, dist: np.ndarray) -> np.ndarray:
        """The flat distances as (key point, obstacle point), ``inf`` for a pair without rows."""
        a, m = len(self.key_points), self.n_obstacle_points
        if self.n_rows == a * m:
            return dist.reshape(a, m)
        grid = np.full((a, m), np.inf)
        starts = np.concatenate([[0], np.cumsum(self.points_per_obstacle)])
        for (i, j), (_, _, s) in zip(self.pairs, self.obstacle_columns()):
            grid[i, starts[j] : starts[j + 1]] = dist[s]
        return grid

    # -- key points of kind closest: the numpy terms ----------------------------
    def _closest_arrays(self, theta, t, kp, kd, soft):
        theta = np.asarray(theta, dtype=float)
        kp = self.kp if kp is None else kp
        kd = self.kd if kd is None else kd
        n = self.n
        ee_arr, J = self.arm.points_jacobians(theta, [n - 1], [1.0])
        ee, J = ee_arr[0], J[0]
        xd = np.asarray(self.task.path(t))
        b0 = self.task.impedance_reference(ee, t, kp, kd)
        lb, ub = self.limits.escape_velocity_bounds(theta)
        if soft:  # 1/2 v^T v + rho/2 |J v - b0|^2
            P, q = np.eye(n) + self.rho * J.T @ J, -self.rho * J.T @ b0
        else:
            P, q = np.eye(n), np.zeros(n)
        a, radius = len(self.key_points), self.key_points.radius
        if not self.pairs:
            G, h, dist = np.zeros((0, n)), np.zeros(0), np.zeros(0)
            return TickArrays(P, q, G, h, J, b0, lb, ub, ee.copy(), dist, xd)
        # one key point per link: its point closest to each obstacle point
        joints = self.arm.joint_positions(theta)
        per = [closest_rows(o, self.k, self.d_safe, joints, t, radius) for o in self.obstacles]
        # each term's rows are key point major; the QP's rows follow the pairs
        G = np.concatenate([per[j][0].reshape(a, -1, n)[i] for i, j in self.pairs])
        h = np.concatenate([per[j][1].reshape(a, -1)[i] for i, j in self.pairs])
        dist = np.concatenate([per[j][2][i] for i, j in self.pairs])
        return TickArrays(P, q, G, h, J, b0, lb, ub, ee.copy(), dist, xd)

    def obstacle_columns(self) -> list[tuple[str, str, slice]]:
        """``(key point name, obstacle name, slice of the flat distance array)`` for each log
        column: one per pair of :attr:`pairs`, in row order."""
        cols, start = [], 0
        for i, j in self.pairs:
            m = self.points_per_obstacle[j]
            cols.append((self.key_points.names[i], self.obstacles[j].name, slice(start, start + m)))
            start += m
        return cols


def check_formulation(formulation: str, key: str = "formulation") -> bool:
    """Whether ``formulation`` (one of :data:`FORMULATIONS`) is ``soft``; else :class:`ParamError`
    naming ``key``."""
    if formulation not in FORMULATIONS:
        raise ParamError(
            f"unknown formulation '{formulation}' (choose from {', '.join(FORMULATIONS)})",
            key=key,
        )
    return formulation == "soft"

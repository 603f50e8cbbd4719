"""The controller: one control tick's QP (paper eq. 11) in joint velocities ``v`` [rad/s].

``paper`` (hard task, eq. 11)::

    minimize 1/2 v^T v   s.t.  J v = b0,  G v <= h,  lb <= v <= ub

``soft`` (task as a weighted cost; feasible whenever the robot is within its limits and static
obstacles are at least ``d_safe`` away)::

    minimize 1/2 v^T (I + rho J^T J) v - rho b0^T J v   s.t.  G v <= h,  lb <= v <= ub

``J`` has ``dim`` rows (2: a planar arm; 3: a spatial one, whose orientation is left free).
``G`` holds one row per (key point, obstacle primitive) pair, key point major (a fixed count; no
obstacle: ``G = h = None``); a key point is a point of a link (the paper's) or, of kind
``closest``, the whole link (its point closest to the primitive, found every tick). The compiled
build (:mod:`qpbench.control.build_kernel`) writes them into one fresh buffer per tick.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from typing import NamedTuple

import numpy as np
import qpsolvers

from ..exceptions import ParamError, check_choice
from ..native import entry_point
from ..packed import PackedProblem
from ..robot.chain import chain_data
from ..robot.kinematics import Arm, KeyPoints
from ..robot.obstacles import OBSTACLE_COLUMNS, Obstacle
from ..statuses import FORMULATIONS
from .build_kernel import ControllerModel, compiled_build_kernel, packed_layout
from .terms import EscapeVelocityLimits, ImpedanceTask


class TickArrays(NamedTuple):
    """One tick's arrays: cost and obstacle rows ``P, q, G, h``, task row ``J v = b0`` (eq. 11),
    escape-velocity bounds ``lb, ub`` [rad/s], end effector ``ee`` [m], key-point distances
    ``dist`` [m] (flat, key point major), ``xd = (x_d, xdot_d)`` [m, m/s], the packed ``buffer``
    the others view."""

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
        arm: Arm,
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
        self.arm, self.key_points, self.task, self.limits = arm, key_points, task, limits
        self.obstacles = list(obstacles)
        self.k, self.d_safe, self.rho, self.kp, self.kd = map(float, (k, d_safe, rho, kp, kd))
        self.n, self.dim = arm.n, arm.dim
        self.points_per_obstacle = [o.n_points for o in self.obstacles]
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
        # each obstacle's first point among all obstacles' points
        self._starts = starts = np.cumsum([0, *self.points_per_obstacle])
        rows = [(i, p) for i, j in self.pairs for p in range(starts[j], starts[j + 1])]
        rows = np.array(rows, dtype=np.int64).reshape(-1, 2)
        path_kind, path_cosine, path_times, path_points = task.path.fields
        f1 = np.ones(len(key_points)) if self.closest else key_points.fracs
        f0 = np.zeros(len(key_points)) if self.closest else key_points.fracs
        f64 = partial(np.ascontiguousarray, dtype=np.float64)
        #: Everything the compiled build reads (:class:`ControllerModel`).
        self.model = ControllerModel(
            chain=arm.model,
            data=chain_data(arm.model),
            key_link=np.ascontiguousarray(key_points.links, dtype=np.int64),
            key_f0=f64(f0),
            key_f1=f64(f1),
            key_radius=float(key_points.radius),
            row_key=np.ascontiguousarray(rows[:, 0]),
            row_prim=np.ascontiguousarray(rows[:, 1]),
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
            scratch=np.zeros(9),
        )
        self._packed_size, self._packed_slices = packed_layout(self.n, self.n_rows, self.dim)
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
        n = self.n
        kp = float(self.kp if kp is None else kp)
        kd = float(self.kd if kd is None else kd)
        buf = np.empty(self._packed_size)
        args = (self.model, theta, float(t), kp, kd, bool(soft), buf)
        if self._build is None:
            self._build = entry_point(compiled_build_kernel(), *args)
        self._build(*args)
        P, q, G, h, J, *rest = (buf[s] for s in self._packed_slices)
        P, G, J = P.reshape(n, n), G.reshape(self.n_rows, n), J.reshape(self.dim, n)
        return TickArrays(P, q, G, h, J, *rest, buf)

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
        a, m = len(self.key_points), int(self._starts[-1])
        if self.n_rows == a * m:
            return dist.reshape(a, m)
        grid, starts = np.full((a, m), np.inf), self._starts
        for (i, j), (_, _, s) in zip(self.pairs, self.obstacle_columns()):
            grid[i, starts[j] : starts[j + 1]] = dist[s]
        return grid

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
    return check_choice(formulation, FORMULATIONS, "formulation", key) == "soft"

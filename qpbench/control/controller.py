"""The controller: build one control tick's QP (paper eq. 11) as a :class:`qpsolvers.Problem`.

Two formulations of the same tick, both with ``n`` variables ``v`` (joint
velocities in [rad/s]):

``paper`` (hard task, eq. 11)::

    minimize 1/2 v^T v   s.t.  J v = b0,  G v <= h,  lb <= v <= ub

``soft`` (task as a weighted cost; feasible whenever the robot is within its
limits and static obstacles are at least ``d_safe`` away)::

    minimize 1/2 v^T (I + rho J^T J) v - rho b0^T J v   s.t.  G v <= h,  lb <= v <= ub

``G`` holds one row per (key point, obstacle point) pair, ordered key point by
key point (A1 against every obstacle point, then A2, ...), every pair kept so
the row count is fixed for a scenario and a solver can keep a persistent
object. ``P`` is a dense ndarray; no obstacle means ``G = h = None``.

Key points of kind ``closest`` (``[key_points] kind = "closest"``, beyond the
paper): the key point of link i against an obstacle point is the link's point
closest to it at this tick (end effector's link included), with that point's
Jacobian and its distance to the link's capsule
(:meth:`qpbench.control.terms.ObstacleAvoidance.closest_rows`), one row per
(link, obstacle point), link major. The end effector's link has no rows
against an obstacle that is the contact surface (``exempt``; the lower line
of ``narrow``: it presses into it by design; :mod:`qpbench.robot.body`). These
ticks are built by the numpy terms (the compiled kernel knows fixed key points only).

The per-tick build runs one compiled numba kernel (kinematics, impedance
reference, bounds, obstacle rows; :mod:`qpbench.control.build_kernel`, compiled
on first call and cached on disk)
writing into one freshly allocated buffer, so a returned problem is never
changed by a later build. The problem is a :class:`qpbench.packed.PackedProblem`:
its arrays are views of that buffer, and a backend that knows the layout (the
online network) hands the kernel one array instead of eight. :meth:`Controller.build_reference` assembles the same
problem from the numpy terms of :mod:`qpbench.control.terms`; the tests
check the two agree.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import qpsolvers

from ..exceptions import ParamError
from ..packed import PackedProblem
from ..robot.environment import PRIMITIVE_WIDTH, Obstacle
from ..robot.kinematics import KeyPoints, PlanarArm
from ..statuses import FORMULATIONS
from .build_kernel import compiled_build_kernel, packed_layout, parameter_vector
from .terms import EscapeVelocityLimits, ImpedanceTask, ObstacleAvoidance

__all__ = ["FORMULATIONS", "Controller", "TickArrays", "TickQP", "build_problem"]


class TickArrays(NamedTuple):
    """One tick's arrays (:meth:`Controller.build_arrays`): cost and obstacle rows ``P, q, G, h``,
    task row ``J v = b0`` (eq. 11), escape-velocity bounds ``lb, ub`` [rad/s], end effector ``ee``
    [m], key-point distances ``dist`` [m] (flat, key point major), ``xd = (x_d, xdot_d)`` [m, m/s],
    the packed ``buffer`` the others view (``None`` on the numpy reference path)."""

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


_kernel = None
_Problem = qpsolvers.Problem
_new_problem = object.__new__
_trusted = PackedProblem.from_views
_empty = np.empty


def _get_kernel():
    """The compiled packed build kernel (:mod:`qpbench.control.build_kernel`), kept here so
    the per-tick call reads a global of this module."""
    global _kernel
    if _kernel is None:
        _kernel = compiled_build_kernel()
    return _kernel


@dataclass
class TickQP:
    """One tick's QP and the robot quantities it was built from.

    Attributes:
        problem: The QP.
        formulation: ``paper`` or ``soft``.
        J: End-effector Jacobian (2, n) in [m/rad].
        b0: Impedance reference (eq. 4) in [m/s].
        ee: End-effector position in [m].
        distances: Distance of each key point to each obstacle point (a, m) in [m].
        x_d: Desired position in [m]; ``xdot_d`` desired velocity in [m/s].
    """

    problem: qpsolvers.Problem
    formulation: str
    J: np.ndarray
    b0: np.ndarray
    ee: np.ndarray
    distances: np.ndarray
    x_d: np.ndarray
    xdot_d: np.ndarray


class Controller:
    """Builds the per-tick QP of the paper's collision-free compliance controller.

    Args:
        arm: The robot.
        key_points: Points of the robot kept away from obstacles.
        task: The impedance task (path, pressing direction, desired force).
        limits: Joint-angle and joint-velocity limits and the escape gain.
        obstacles: The obstacles.
        k: Obstacle damper gain in [1/s].
        d_safe: Safety distance in [m].
        rho: Task weight of the ``soft`` formulation [s^2/m^2 relative to ``|v|^2``].
        kp, kd: The controller's interaction coefficients ``Kp`` [N/m], ``Kd`` [N s/m]
            (overridden per call by an adaptive estimate).
        exempt: Per obstacle, it is the contact surface: no rows of the end
            effector's link against it (key points of kind ``closest``; the
            paper's key points never include the end effector).
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
        self.avoidance = [ObstacleAvoidance(o, k, d_safe) for o in self.obstacles]
        self.k = float(k)
        self.d_safe = float(d_safe)
        self.rho = float(rho)
        self.kp = float(kp)
        self.kd = float(kd)
        self.n = arm.n
        #: Obstacle points per obstacle, and the total per key point.
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
        self._compiled = not self.closest and all(o.KERNEL_KIND is not None for o in self.obstacles)
        if self.obstacles:
            self._prims = np.ascontiguousarray(
                np.vstack([o.primitives() for o in self.obstacles]), dtype=float
            )
        else:
            self._prims = np.zeros((0, PRIMITIVE_WIDTH))
        self._lengths = np.ascontiguousarray(arm.lengths, dtype=float)
        self._kp_link = np.ascontiguousarray(key_points.links, dtype=np.int64)
        self._kp_frac = np.ascontiguousarray(key_points.fracs, dtype=float)
        self._lim = np.ascontiguousarray(
            np.vstack([limits.theta_min, limits.theta_max, limits.v_min, limits.v_max]), dtype=float
        )
        self._par = parameter_vector(
            task.normal,
            task.desired_force,
            self.k,
            self.d_safe,
            limits.alpha,
            self.rho,
            key_points.radius,
        )
        self._path = task.path
        self._packed_size, layout = packed_layout(self.n, self.n_rows)
        self._packed_slices = tuple(
            slice(off, off + int(np.prod(shape))) for off, shape in layout.values()
        )

    # -- fast path -------------------------------------------------------------
    def build_arrays(
        self,
        theta: np.ndarray,
        t: float,
        kp: float | None = None,
        kd: float | None = None,
        soft: bool = False,
    ) -> TickArrays:
        """The tick's :class:`TickArrays` ``(P, q, G, h, J, b0, lb, ub, ee, dist, xd, buffer)``, freshly allocated.

        All but ``xd`` are views of ``buffer``, the tick's
        :class:`qpbench.packed.PackedProblem` buffer (layout of :func:`packed_layout`).
        On the numpy reference path (obstacles without a kernel) ``buffer`` is ``None``.

        ``xd`` is ``(x_d_x, x_d_y, xdot_d_x, xdot_d_y)``; ``dist`` is flat
        (a * m,), key point major. This is the loop's hot path: ``theta`` must
        be a contiguous float64 array (:meth:`build` converts; it wraps the
        result into a :class:`TickQP`).
        """
        if not self._compiled:
            return self._arrays_from_terms(theta, t, kp, kd, soft)
        n = self.n
        nr = self.n_rows
        xd = self._path(t)
        par = self._par
        par[0] = t
        par[1], par[2], par[3], par[4] = xd
        par[8] = self.kp if kp is None else kp
        par[9] = self.kd if kd is None else kd
        par[14] = 1.0 if soft else 0.0
        buf = _empty(self._packed_size)
        (_kernel or _get_kernel())(
            theta,
            self._lengths,
            self._kp_link,
            self._kp_frac,
            self._prims,
            self._lim,
            par,
            buf,
        )
        sP, sq, sG, sh, sJ, sb, slb, sub, see, sd = self._packed_slices
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
            xd,
            buf,
        )

    def make_problem(self, arrays: TickArrays, soft: bool) -> qpsolvers.Problem:
        """A :class:`qpsolvers.Problem` from :meth:`build_arrays`' output
        (a :class:`~qpbench.packed.PackedProblem` when it came with its buffer).

        The arrays already have the types and shapes :class:`qpsolvers.Problem`
        checks for (dense float64 matrices, 1-D vectors), so its fields are set
        directly: the constructor's checks cost more than the kernel that fills
        them. The tests check the result equals the constructor's.
        """
        P, q, G, h, J, b, lb, ub = arrays[:8]
        if self.n_rows == 0:
            G = h = None
        if soft:
            J = b = None
        if arrays.buffer is not None:  # one buffer (the kernel's): its header says the same
            return _trusted(arrays.buffer, P, q, G, h, J, b, lb, ub)
        problem = _new_problem(_Problem)
        problem.P = P
        problem.q = q
        problem.G = G
        problem.h = h
        problem.A = J
        problem.b = b
        problem.lb = lb
        problem.ub = ub
        return problem

    # build, build_reference and build_problem take the same arguments on purpose: the reference
    # path is called like the compiled one (tests/test_controller.py compares them tick by tick),
    # and build_problem is build for callers that want only the qpsolvers Problem.
    def build(
        self,
        theta: np.ndarray,
        t: float,
        kp: float | None = None,
        kd: float | None = None,
        formulation: str = "paper",
    ) -> TickQP:
        """Build the tick's QP at joint angles ``theta`` [rad] and time ``t`` [s].

        Args:
            theta: Joint angles in [rad], shape (n,).
            t: Time in [s] (sets ``x_d(t)`` and moving obstacles' positions).
            kp, kd: Interaction coefficients (default: the controller's).
            formulation: ``paper`` or ``soft``.
        """
        soft = _check_formulation(formulation)
        theta = np.ascontiguousarray(theta, dtype=np.float64)
        if theta.shape != (self.n,):
            raise ParamError(f"theta must have shape ({self.n},), got {theta.shape}", key="theta")
        arrays = self.build_arrays(theta, float(t), kp, kd, soft)
        return self._tick(arrays, soft, formulation)

    def _tick(self, arrays, soft, formulation) -> TickQP:
        problem = self.make_problem(arrays, soft)
        xd = arrays.xd
        return TickQP(
            problem=problem,
            formulation=formulation,
            J=arrays.J,
            b0=arrays.b0,
            ee=arrays.ee,
            distances=self._distance_grid(arrays.dist),
            x_d=np.array(xd[:2]),
            xdot_d=np.array(xd[2:]),
        )

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

    # -- numpy reference path ---------------------------------------------------
    def _arrays_from_terms(self, theta, t, kp, kd, soft):
        theta = np.asarray(theta, dtype=float)
        kp = self.kp if kp is None else kp
        kd = self.kd if kd is None else kd
        n = self.n
        ee_arr, J = self.arm.points_jacobians(theta, [n - 1], [1.0])
        ee, J = ee_arr[0], J[0]
        xd = self._path(t)
        b0 = self.task.impedance_reference(ee, t, kp, kd)
        lb, ub = self.limits.escape_velocity_bounds(theta)
        if soft:
            P, q = self.task.cost(J, b0, self.rho)
        else:
            P, q = np.eye(n), np.zeros(n)
        if self.closest:
            G, h, dist = self._closest_rows(theta, t)
            return TickArrays(P, q, G, h, J, b0, lb, ub, ee.copy(), dist, xd)
        a = len(self.key_points)
        key_xy, key_J = self.arm.points_jacobians(
            theta, self.key_points.links, self.key_points.fracs
        )
        Gs, hs, ds = [], [], []
        for term in self.avoidance:
            G, h, dist = term.rows(key_xy, key_J, t, self.key_points.radius)
            m = dist.shape[1]
            Gs.append(G.reshape(a, m, n))
            hs.append(h.reshape(a, m))
            ds.append(dist)
        if Gs:
            G = np.concatenate(Gs, axis=1).reshape(a * self.n_obstacle_points, n)
            h = np.concatenate(hs, axis=1).reshape(-1)
            dist = np.concatenate(ds, axis=1).reshape(-1)
        else:
            G, h, dist = np.zeros((0, n)), np.zeros(0), np.zeros(0)
        return TickArrays(P, q, G, h, J, b0, lb, ub, ee.copy(), dist, xd)

    def _closest_rows(self, theta, t) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``G, h, dist`` of key points of kind ``closest``, in the order of :attr:`pairs`."""
        n = self.n
        if not self.pairs:
            return np.zeros((0, n)), np.zeros(0), np.zeros(0)
        joints = self.arm.joint_positions(theta)
        radius = self.key_points.radius
        per = [term.closest_rows(joints, t, radius) for term in self.avoidance]
        G = np.concatenate([per[j][0].reshape(n, -1, n)[i] for i, j in self.pairs])
        h = np.concatenate([per[j][1].reshape(n, -1)[i] for i, j in self.pairs])
        dist = np.concatenate([per[j][2][i] for i, j in self.pairs])
        return G, h, dist

    # Same arguments as build (see there): its numpy reference, for checks.
    def build_reference(
        self,
        theta: np.ndarray,
        t: float,
        kp: float | None = None,
        kd: float | None = None,
        formulation: str = "paper",
    ) -> TickQP:
        """Same as :meth:`build`, assembled from the numpy terms (slower; for checks)."""
        soft = _check_formulation(formulation)
        arrays = self._arrays_from_terms(theta, t, kp, kd, soft)
        return self._tick(arrays, soft, formulation)

    def obstacle_columns(self) -> list[tuple[str, str, slice]]:
        """``(key point name, obstacle name, slice of the flat distance array)`` for each log
        column: one per pair of :attr:`pairs`, in row order."""
        cols, start = [], 0
        for i, j in self.pairs:
            m = self.points_per_obstacle[j]
            cols.append((self.key_points.names[i], self.obstacles[j].name, slice(start, start + m)))
            start += m
        return cols


def _check_formulation(formulation: str) -> bool:
    if formulation not in FORMULATIONS:
        raise ParamError(
            f"unknown formulation '{formulation}' (choose from {', '.join(FORMULATIONS)})",
            key="formulation",
        )
    return formulation == "soft"


# Same arguments as Controller.build (see there), which it calls.
def build_problem(
    controller: Controller,
    theta: np.ndarray,
    t: float,
    kp: float | None = None,
    kd: float | None = None,
    formulation: str = "paper",
) -> qpsolvers.Problem:
    """The tick's :class:`qpsolvers.Problem` at joint angles ``theta`` [rad], time ``t`` [s] (paper eq. 11)."""
    return controller.build(theta, t, kp, kd, formulation).problem

"""The robot's surroundings: the contact surface and the obstacles (paper sections 2.1, 2.2, 4).

Contact surface: a line through ``point`` with unit normal ``normal`` (the pressing direction);
penetration ``delta = n . (x - point)``; a spring-damper force while penetrating (paper eq. 3
read as the environment's law; computed by :mod:`qpbench.sim.tick_kernel`)::

    F = max(0, Kp_env delta + Kd_env deltadot)   if delta > 0, else 0     [N]

Obstacles (:class:`Obstacle`) give, for key points or link segments, one or more obstacle points
(the closest point of a shape, or each point of a cloud) and the signed distance [m] (negative
inside; a ``line`` is a wall, a half-plane); they may translate with a constant ``velocity``
[m/s]. Between two samples, for the body rule (:func:`qpbench.robot.body.body_crossings`), each
kind bounds its distance to a segment swept with linearly moving ends from below
(:meth:`Obstacle.swept_distance_bound`) and says whether a point passed through the segment or
the segment through a point (:meth:`Obstacle.passed_through`).
"""

from __future__ import annotations

import math

import numpy as np

from ..exceptions import InputError

#: Columns of the obstacle table the compiled kernels read, one row per obstacle point at t = 0
#: (:meth:`Obstacle.primitives`), and their indices.
OBSTACLE_COLUMNS = ("kind", "p0x", "p0y", "p1x", "p1y", "radius", "vx", "vy")
KIND, P0X, P0Y, P1X, P1Y, RADIUS, VX, VY = range(len(OBSTACLE_COLUMNS))
#: The ``kind`` codes of the table: one per obstacle class (its ``KERNEL_KIND``).
LINE, SEGMENT, DISK, POINT = range(4)


def _vec2(value, key: str) -> np.ndarray:
    arr = np.asarray(value, dtype=float)
    if arr.shape != (2,) or not np.all(np.isfinite(arr)):
        raise InputError(f"expected two finite numbers, got {value!r}", key=key)
    return arr


def _not_negative(value, key: str, unit: str, strict: bool = False) -> float:
    """``value`` as a float if ``>= 0`` (``> 0`` when ``strict``), else an :class:`InputError`."""
    if not (value > 0 if strict else value >= 0):
        raise InputError(f"must be {'>' if strict else '>='} 0 {unit}, got {value}", key=key)
    return float(value)


def _unit(value, key: str) -> np.ndarray:
    arr = _vec2(value, key)
    norm = math.hypot(arr[0], arr[1])
    if norm < 1e-12:
        raise InputError(f"a direction must not be zero, got {value!r}", key=key)
    return arr / norm


class ContactSurface:
    """A line the end effector presses on (paper section 2.1, Figure 1): ``point`` [m], pressing
    ``normal`` (normalised here), ``stiffness`` ``Kp_env`` [N/m], ``damping`` ``Kd_env``
    [N s/m], force-sensor noise ``noise_std`` [N] drawn from ``seed``."""

    def __init__(
        self,
        point,
        normal,
        stiffness: float,
        damping: float,
        noise_std: float = 0.0,
        seed: int | None = 0,
    ):
        self.point = _vec2(point, "contact.point")
        self.normal = _unit(normal, "contact.normal")
        self.stiffness = _not_negative(stiffness, "contact.stiffness", "[N/m]", strict=True)
        self.damping = _not_negative(damping, "contact.damping", "[N s/m]")
        self.noise_std = _not_negative(noise_std, "contact.force_noise_std", "[N]")
        self.seed = seed
        self.reset()

    def reset(self) -> None:
        """Restart the noise sequence from the seed."""
        self._rng = np.random.default_rng(self.seed)

    def noise(self) -> float:
        """One sample of the force-sensor noise in [N] (0.0 when ``noise_std`` is 0)."""
        if self.noise_std <= 0.0:
            return 0.0
        return self.noise_std * float(self._rng.standard_normal())


class Obstacle:
    """Base class of the obstacle kinds: ``name`` (in log columns, ``d_A2_wall``), constant
    ``velocity`` [m/s], ``n_points`` obstacle points ``B_j`` per key point."""

    KIND: str = ""
    #: Code of the shape in the controller's compiled kernel.
    KERNEL_KIND: int
    n_points: int = 1

    def __init__(self, name: str, velocity=(0.0, 0.0)):
        self.name = str(name)
        self.velocity = _vec2(velocity, f"obstacles.{name}.velocity")

    def closest(self, A: np.ndarray, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Obstacle points ``B`` (a, m, 2) [m] nearest to key points ``A`` (a, 2) at time ``t``
        [s], ``dist`` (a, m) [m] and ``u`` (a, m, 2) from ``B`` to ``A`` (zero where ``dist`` is 0):
        :meth:`closest_on_segments` of the points as segments of length 0."""
        A = np.asarray(A, dtype=float)
        _, B, dist, u = self.closest_on_segments(A, A, t)
        return B, dist, u

    def primitives(self) -> np.ndarray:
        """Rows of the obstacle table (m, :data:`OBSTACLE_COLUMNS`) of the compiled kernels, at t = 0."""
        raise NotImplementedError

    def closest_on_segments(
        self, P0: np.ndarray, P1: np.ndarray, t
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Exact closest points of segments ``P0 -> P1`` (s, 2) [m] to the obstacle at ``t`` [s]
        (a number or one per segment): per segment and obstacle point, ``A`` (s, m, 2) on the
        segment, ``B`` (s, m, 2) on the obstacle [m], the signed ``dist`` (s, m) [m] (``< 0``:
        inside, by that depth) and ``u`` (s, m, 2), the way moving ``A`` increases ``dist``."""
        raise NotImplementedError

    def swept_distance_bound(self, P0a, P1a, P0b, P1b, t) -> np.ndarray:
        """A lower bound [m] of the signed distance (as :meth:`closest_on_segments`, smallest over
        the obstacle's points) to every segment ``P0(l) -> P1(l)``, ``P(l) = (1 - l) Pa + l Pb``
        for ``l`` in [0, 1] (ends (s, 2) [m]), the obstacle held as at ``t`` [s]: the sweep of a
        link in the obstacle's frame. Exact where the kind says so; a value ``<= 0`` says the
        sweep may reach the obstacle (a bar's says no more: not how deep)."""
        raise NotImplementedError

    def passed_through(self, P0a, P1a, P0b, P1b, t) -> np.ndarray:
        """Per sweep (as :meth:`swept_distance_bound`), ``True`` where a point of the obstacle
        went from one side of the segment to the other within it, or an end of the segment
        through the obstacle's outline (the crossings a shape without inside makes)."""
        raise NotImplementedError

    def _at(self, start: np.ndarray, t, s: int) -> np.ndarray:
        """``start + velocity * t`` for each of ``s`` segments, shape (s, 2)."""
        t = np.broadcast_to(np.asarray(t, dtype=float), (s,))
        return start + t[:, None] * self.velocity

    @staticmethod
    def _from_diff(diff: np.ndarray, radius: float = 0.0):
        dist = np.sqrt(np.einsum("...i,...i->...", diff, diff))
        safe = np.where(dist > 0, dist, 1.0)
        u = np.where(dist[..., None] > 0, diff / safe[..., None], 0.0)
        return dist - radius, u


class LineObstacle(Obstacle):
    """An infinite line (a wall) through ``point`` [m] at t = 0; ``normal`` points to the free
    side (normalised here), the half-plane ``normal . (x - point) < 0`` is forbidden."""

    KIND = "line"
    KERNEL_KIND = LINE

    def __init__(self, name: str, point, normal, velocity=(0.0, 0.0)):
        super().__init__(name, velocity)
        self.point = _vec2(point, f"obstacles.{name}.point")
        self.normal = _unit(normal, f"obstacles.{name}.normal")

    def primitives(self) -> np.ndarray:
        return np.array([[self.KERNEL_KIND, *self.point, *self.normal, 0.0, *self.velocity]])

    def closest_on_segments(self, P0, P1, t):
        P0, P1 = np.asarray(P0, dtype=float), np.asarray(P1, dtype=float)
        p = self._at(self.point, t, P0.shape[0])
        # the signed distance is linear along a segment: its minimum is at an end
        d0 = np.einsum("si,i->s", P0 - p, self.normal)
        d1 = np.einsum("si,i->s", P1 - p, self.normal)
        first = d0 <= d1
        A = np.where(first[:, None], P0, P1)
        dist = np.where(first, d0, d1)
        B = A - dist[:, None] * self.normal
        u = np.broadcast_to(self.normal, A.shape).copy()
        return A[:, None, :], B[:, None, :], dist[:, None], u[:, None, :]

    def swept_distance_bound(self, P0a, P1a, P0b, P1b, t):
        """Exact: the signed distance of a point is linear along the sweep, so its least is at
        one of the four ends (a half-plane cannot be passed through)."""
        p = self._at(self.point, t, np.shape(P0a)[0])
        ends = np.stack([P0a, P1a, P0b, P1b], axis=1) - p[:, None, :]
        return np.einsum("sei,i->se", ends, self.normal).min(axis=1)

    def passed_through(self, P0a, P1a, P0b, P1b, t):
        return np.zeros(np.shape(P0a)[0], dtype=bool)


class SegmentObstacle(Obstacle):
    """A segment from ``a`` to ``b`` (a thin bar)."""

    KIND = "segment"
    KERNEL_KIND = SEGMENT

    def __init__(self, name: str, a, b, velocity=(0.0, 0.0)):
        super().__init__(name, velocity)
        self.a = _vec2(a, f"obstacles.{name}.a")
        self.b = _vec2(b, f"obstacles.{name}.b")
        if np.allclose(self.a, self.b):
            raise InputError("segment end points must differ", key=f"obstacles.{name}.b")

    def primitives(self) -> np.ndarray:
        return np.array([[self.KERNEL_KIND, *self.a, *self.b, 0.0, *self.velocity]])

    def closest_on_segments(self, P0, P1, t):
        """Segment to segment. Apart, ``dist`` is their distance. Crossing, it is minus the
        smallest distance of one segment's end to the other segment (the shortest way out
        along the crossing; 0 when an end touches), and ``u`` points from ``A`` to ``B``:
        the witness end and its foot, the way the link must move to come free."""
        P0, P1 = np.asarray(P0, dtype=float), np.asarray(P1, dtype=float)
        a = self._at(self.a, t, P0.shape[0])
        b = a + (self.b - self.a)
        # four candidate pairs: each end of one segment against the other segment
        cand_A = np.stack([P0, P1, _foot(a, P0, P1), _foot(b, P0, P1)], axis=1)
        cand_B = np.stack([_foot(P0, a, b), _foot(P1, a, b), a, b], axis=1)
        gap = np.linalg.norm(cand_A - cand_B, axis=2)
        j = np.argmin(gap, axis=1)
        rows = np.arange(P0.shape[0])
        A, B, dist = cand_A[rows, j], cand_B[rows, j], gap[rows, j]
        crossing = _segments_cross(P0, P1, a, b)
        diff = A - B
        norm = np.where(dist > 0, dist, 1.0)
        u = np.where((dist > 0)[:, None], diff / norm[:, None], 0.0)
        u = np.where(crossing[:, None], -u, u)
        dist = np.where(crossing, -dist, dist)
        return A[:, None, :], B[:, None, :], dist[:, None], u[:, None, :]

    def swept_distance_bound(self, P0a, P1a, P0b, P1b, t):
        """The closest pair of two segments has an end of one on the other: the link's ends run
        along the chords ``P0a -> P0b`` and ``P1a -> P1b``, the bar's ends are points swept over
        (:func:`_swept_point_bound`). Positive, no crossing begins in the sweep (one begins with
        an end on the other), nor is there one at its ends (their signed distances are in the
        bound); ``<= 0`` otherwise."""
        a = self._at(self.a, t, len(P0a))
        b = a + (self.b - self.a)
        return np.minimum.reduce(
            [
                _segment_distance(P0a, P0b, a, b),
                _segment_distance(P1a, P1b, a, b),
                _swept_point_bound(a, P0a, P1a, P0b, P1b),
                _swept_point_bound(b, P0a, P1a, P0b, P1b),
                self.closest_on_segments(P0a, P1a, t)[2][:, 0],
                self.closest_on_segments(P0b, P1b, t)[2][:, 0],
            ]
        )

    def passed_through(self, P0a, P1a, P0b, P1b, t):
        """An end of the bar through the link, or an end of the link through the bar."""
        a = self._at(self.a, t, len(P0a))
        b = a + (self.b - self.a)
        return (
            _passes_through(a, a, P0a, P1a, P0b, P1b)
            | _passes_through(b, b, P0a, P1a, P0b, P1b)
            | _passes_through(P0a, P0b, a, b, a, b)
            | _passes_through(P1a, P1b, a, b, a, b)
        )


class DiskObstacle(Obstacle):
    """A disk of centre ``center`` and radius ``radius`` in [m]."""

    KIND = "disk"
    KERNEL_KIND = DISK

    def __init__(self, name: str, center, radius: float, velocity=(0.0, 0.0)):
        super().__init__(name, velocity)
        self.center = _vec2(center, f"obstacles.{name}.center")
        self.radius = _not_negative(radius, f"obstacles.{name}.radius", "[m]", strict=True)

    def primitives(self) -> np.ndarray:
        return np.array([[self.KERNEL_KIND, *self.center, 0.0, 0.0, self.radius, *self.velocity]])

    def closest_on_segments(self, P0, P1, t):
        P0, P1 = np.asarray(P0, dtype=float), np.asarray(P1, dtype=float)
        c = self._at(self.center, t, P0.shape[0])
        A = _foot(c, P0, P1)
        dist, u = self._from_diff(A - c, self.radius)
        u = _normal_where_zero(u, P0, P1)
        B = c + self.radius * u
        return A[:, None, :], B[:, None, :], dist[:, None], u[:, None, :]

    def swept_distance_bound(self, P0a, P1a, P0b, P1b, t):
        c = self._at(self.center, t, len(P0a))
        return _swept_point_bound(c, P0a, P1a, P0b, P1b) - self.radius

    def passed_through(self, P0a, P1a, P0b, P1b, t):
        c = self._at(self.center, t, len(P0a))
        return _passes_through(c, c, P0a, P1a, P0b, P1b)


class PointCloudObstacle(Obstacle):
    """A set of points ``B_1..B_m`` in [m] (paper section 2.2: obstacles as key points)."""

    KIND = "points"
    KERNEL_KIND = POINT

    def __init__(self, name: str, points, velocity=(0.0, 0.0)):
        super().__init__(name, velocity)
        pts = np.asarray(points, dtype=float)
        if pts.ndim != 2 or pts.shape[1] != 2 or pts.shape[0] < 1 or not np.all(np.isfinite(pts)):
            raise InputError(
                f"expected a list of [x, y] points, got {points!r}", key=f"obstacles.{name}.points"
            )
        self.points = pts
        self.n_points = pts.shape[0]

    def closest_on_segments(self, P0, P1, t):
        """Each cloud point against each segment; a point on a segment is at distance 0."""
        P0, P1 = np.asarray(P0, dtype=float), np.asarray(P1, dtype=float)
        s, m = P0.shape[0], self.n_points
        t = np.broadcast_to(np.asarray(t, dtype=float), (s,))
        C = self.points[None, :, :] + t[:, None, None] * self.velocity  # (s, m, 2)
        Q0 = np.broadcast_to(P0[:, None, :], C.shape).reshape(-1, 2)
        Q1 = np.broadcast_to(P1[:, None, :], C.shape).reshape(-1, 2)
        A = _foot(C.reshape(-1, 2), Q0, Q1)
        dist, u = self._from_diff(A - C.reshape(-1, 2))
        u = _normal_where_zero(u, Q0, Q1)
        return A.reshape(s, m, 2), C, dist.reshape(s, m), u.reshape(s, m, 2)

    def swept_distance_bound(self, P0a, P1a, P0b, P1b, t):
        C, ends = self._each_point(t, P0a, P1a, P0b, P1b)
        return _swept_point_bound(C, *ends).reshape(-1, self.n_points).min(axis=1)

    def passed_through(self, P0a, P1a, P0b, P1b, t):
        C, ends = self._each_point(t, P0a, P1a, P0b, P1b)
        return _passes_through(C, C, *ends).reshape(-1, self.n_points).any(axis=1)

    def _each_point(self, t, *ends):
        """The cloud's points at ``t`` [s] (s * m, 2) and each of the ``ends`` (s, 2) repeated
        for each point, (s * m, 2)."""
        s, m = len(ends[0]), self.n_points
        t = np.broadcast_to(np.asarray(t, dtype=float), (s,))
        C = (self.points[None, :, :] + t[:, None, None] * self.velocity).reshape(-1, 2)
        return C, [np.repeat(np.asarray(E, dtype=float), m, axis=0) for E in ends]

    def primitives(self) -> np.ndarray:
        m = self.n_points
        rows = np.zeros((m, len(OBSTACLE_COLUMNS)))
        rows[:, KIND] = self.KERNEL_KIND
        rows[:, P0X : P0Y + 1] = self.points
        rows[:, VX : VY + 1] = self.velocity
        return rows


def _foot(X: np.ndarray, P0: np.ndarray, P1: np.ndarray) -> np.ndarray:
    """The point of each segment ``P0 -> P1`` closest to ``X`` (all (s, 2)) [m]."""
    e = P1 - P0
    ee = np.einsum("si,si->s", e, e)
    f = np.einsum("si,si->s", X - P0, e) / np.where(ee > 0, ee, 1.0)
    return P0 + np.clip(f, 0.0, 1.0)[:, None] * e


def _cross(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0]


def _segments_cross(P0, P1, Q0, Q1) -> np.ndarray:
    """Segments ``P0 -> P1`` and ``Q0 -> Q1`` cross strictly (each splits the other's ends)."""
    e, f = P1 - P0, Q1 - Q0
    s1, s2 = _cross(e, Q0 - P0), _cross(e, Q1 - P0)
    s3, s4 = _cross(f, P0 - Q0), _cross(f, P1 - Q0)
    return (s1 * s2 < 0) & (s3 * s4 < 0)


def _point_segment_distance(X, P0, P1) -> np.ndarray:
    """Distance [m] of each point ``X`` to its segment ``P0 -> P1`` (all (s, 2))."""
    return np.linalg.norm(X - _foot(X, P0, P1), axis=1)


def _segment_distance(P0, P1, Q0, Q1) -> np.ndarray:
    """Distance [m] between segments ``P0 -> P1`` and ``Q0 -> Q1`` (0 where they cross)."""
    ends = np.minimum.reduce(
        [
            _point_segment_distance(P0, Q0, Q1),
            _point_segment_distance(P1, Q0, Q1),
            _point_segment_distance(Q0, P0, P1),
            _point_segment_distance(Q1, P0, P1),
        ]
    )
    return np.where(_segments_cross(P0, P1, Q0, Q1), 0.0, ends)


def _swept_point_bound(C, P0a, P1a, P0b, P1b) -> np.ndarray:
    """A lower bound [m] of the distance of points ``C`` to the segments ``P0(l) -> P1(l)``,
    ``P(l) = (1 - l) Pa + l Pb``, ``l`` in [0, 1] (all (s, 2)); 0 where one passes over ``C``.

    The closest point of segment ``l`` is an end (on a chord ``P0a -> P0b`` or ``P1a -> P1b``)
    or its foot, at distance ``|g(l)| / |e(l)|``: ``e(l) = P1(l) - P0(l)``, ``g(l) = e(l) x (C -
    P0(l))`` a quadratic in ``l`` (its least magnitude on [0, 1] from its ends and its vertex)
    and ``|e(l)|`` convex (at most its larger end). For a rigid link that moves little between
    ``a`` and ``b`` the bound is within the square of that motion of the exact least distance.
    """
    Q, D0 = C - P0a, P0b - P0a
    E = P1a - P0a
    DE = (P1b - P0b) - E
    c0 = _cross(E, Q)
    c1 = _cross(DE, Q) - _cross(E, D0)
    c2 = -_cross(DE, D0)
    g1 = c0 + c1 + c2
    with np.errstate(divide="ignore", invalid="ignore"):
        lv = np.where(c2 != 0.0, -c1 / (2.0 * c2), -1.0)
    vertex = (lv > 0.0) & (lv < 1.0)
    gv = c0 + lv * (c1 + lv * c2)
    root = (c0 * g1 <= 0.0) | (vertex & (gv * c0 <= 0.0))
    least = np.minimum(np.abs(c0), np.abs(g1))
    least = np.where(vertex, np.minimum(least, np.abs(gv)), least)
    e_max = np.maximum(np.linalg.norm(E, axis=1), np.linalg.norm(E + DE, axis=1))
    interior = np.where(root, 0.0, least / np.where(e_max > 0, e_max, 1.0))
    return np.minimum.reduce(
        [
            interior,
            _point_segment_distance(C, P0a, P0b),
            _point_segment_distance(C, P1a, P1b),
        ]
    )


#: Slack [m] of "within the segment" in :func:`_passes_through` (rounding at a segment's end).
PASS_TOL = 1e-12


def _passes_through(Xa, Xb, P0a, P1a, P0b, P1b) -> np.ndarray:
    """Point ``X`` moving from ``Xa`` to ``Xb`` while its segment moves from ``P0a -> P1a`` to
    ``P0b -> P1b`` (all (s, 2)): ``True`` where the side of ``X`` changes sign (or is 0 at one
    end: on the segment there) and ``X`` projects within the segment at both ends (to
    :data:`PASS_TOL`): over a motion short against the distances involved, it went through the
    segment."""
    ea, eb = P1a - P0a, P1b - P0b
    ha, hb = _cross(ea, Xa - P0a), _cross(eb, Xb - P0b)

    def within(X, P0, e):
        length = np.linalg.norm(e, axis=1)
        along = np.einsum("si,si->s", X - P0, e) / np.where(length > 0, length, 1.0)
        return (along >= -PASS_TOL) & (along <= length + PASS_TOL)

    sides = (ha * hb <= 0.0) & ((ha != 0.0) | (hb != 0.0))
    return sides & within(Xa, P0a, ea) & within(Xb, P0b, eb)


def _normal_where_zero(u: np.ndarray, P0: np.ndarray, P1: np.ndarray) -> np.ndarray:
    """``u``, with a unit normal of the segment where ``u`` is zero (the shape's centre on the
    segment: any way off the segment's line is a way out)."""
    e = P1 - P0
    norm = np.linalg.norm(e, axis=1)
    n = np.stack([-e[:, 1], e[:, 0]], axis=1) / np.where(norm > 0, norm, 1.0)[:, None]
    zero = ~np.any(u != 0, axis=1)
    return np.where(zero[:, None], n, u)


#: Obstacle kind name (as written in scenario files) -> class.
OBSTACLE_KINDS: dict[str, type[Obstacle]] = {
    cls.KIND: cls for cls in (LineObstacle, SegmentObstacle, DiskObstacle, PointCloudObstacle)
}

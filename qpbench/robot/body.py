"""The whole body: exact clearance of the arm's link capsules to the obstacles, at the ticks
(:func:`body_clearance`) and between them (:func:`body_crossings`); the rule, the exemption of
the contact surface and the bounds that decide an interval: docs/body.md.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .environment import ContactSurface
from .kinematics import Arm
from .obstacles import Obstacle, project
from .obstacles.plane import PlaneObstacle

#: Tolerance of "the same line" (an obstacle recognised as the contact surface) [m, rad].
SAME_LINE_TOL = 1e-9

#: The body rule between samples is decided to this distance [m]: a piece of an interval is
#: proven clear when its clearance is at least this (a margin over rounding), and not cut again
#: when the link moves at most this far against the obstacle in it.
SWEEP_TOL = 1e-12

#: Most pieces one interval is cut into for one link and obstacle; a pair touching an obstacle
#: along a stretch of time (clearance 0 to within :data:`SWEEP_TOL`) is judged on its pieces then.
MAX_PIECES = 256


def contact_obstacles(obstacles: list[Obstacle], surface: ContactSurface) -> list[bool]:
    """For each obstacle: it is the contact surface (a static ``plane`` or ``line`` through its
    point, free side against the pressing direction)."""
    return [
        isinstance(o, PlaneObstacle)
        and not np.any(o.velocity)
        and float(o.normal @ surface.normal) <= -1.0 + SAME_LINE_TOL
        and abs(float(o.normal @ (surface.point - o.point))) <= SAME_LINE_TOL
        for o in obstacles
    ]


def link_label(link: int, n: int) -> str:
    """``"link 4 (end effector)"`` for the last of ``n`` links (1-based ``link``), else ``"link 2"``."""
    return f"link {link} (end effector)" if link == n else f"link {link}"


class BodyClearance(NamedTuple):
    """Clearance ``d`` (T, n, o) [m] of every link to every obstacle per tick (``+inf`` where
    exempt); per tick its smallest ``d_min`` [m] (NaN without obstacles), that one's 1-based
    ``link`` (0 without) and ``obstacle`` index (-1 without)."""

    d: np.ndarray
    d_min: np.ndarray
    link: np.ndarray
    obstacle: np.ndarray


def body_clearance(
    arm: Arm,
    theta: np.ndarray,
    t: np.ndarray,
    obstacles: list[Obstacle],
    radius: float = 0.0,
    exempt: list[bool] | None = None,
) -> BodyClearance:
    """Clearance of the arm's capsules of ``radius`` [m] at joint angles ``theta`` (T, n) [rad]
    and times ``t`` (T,) [s]; ``exempt``: per obstacle, the end effector's link is not judged."""
    theta = np.atleast_2d(np.asarray(theta, dtype=float))
    T, n = theta.shape
    t = np.broadcast_to(np.asarray(t, dtype=float), (T,))
    if not obstacles or T == 0:
        none = np.zeros(T, dtype=np.int64)
        return BodyClearance(np.empty((T, n, 0)), np.full(T, np.nan), none, none - 1)
    d = _clearances(project(arm.joint_positions(theta), "xyz"), t, obstacles, radius, exempt)
    flat = d.reshape(T, -1)
    arg = np.argmin(np.where(np.isnan(flat), -np.inf, flat), axis=1)
    m = len(obstacles)
    return BodyClearance(d, flat[np.arange(T), arg], arg // m + 1, arg % m)


def _clearances(p: np.ndarray, t: np.ndarray, obstacles, radius: float, exempt) -> np.ndarray:
    """Clearance (T, n, o) [m] of the links between joint positions ``p`` (T, n+1, 3) [m] at
    times ``t`` (T,) [s] (:func:`body_clearance`)."""
    T, n = p.shape[0], p.shape[1] - 1
    d = np.empty((T, n, len(obstacles)))
    P0 = p[:, :-1].reshape(-1, 3)
    P1 = p[:, 1:].reshape(-1, 3)
    ts = np.repeat(t, n)
    for j, o in enumerate(obstacles):
        _, _, dist, _ = o.closest_on_segments(P0, P1, ts)
        d[:, :, j] = dist.min(axis=1).reshape(T, n) - radius
        if exempt is not None and exempt[j]:
            d[:, n - 1, j] = np.inf
    return d


class BodyCrossings(NamedTuple):
    """Intervals between samples in which a link went inside an obstacle it was clear of at both
    samples: per such interval, its index ``tick`` (from sample ``tick``), the first time ``t``
    [s] the link was found inside (to :data:`SWEEP_TOL` of motion), the 1-based ``link`` and the
    ``obstacle`` index (the earliest found, when several)."""

    tick: np.ndarray
    t: np.ndarray
    link: np.ndarray
    obstacle: np.ndarray


def body_crossings(
    arm: Arm,
    theta: np.ndarray,
    t: np.ndarray,
    dt: float,
    obstacles: list[Obstacle],
    radius: float = 0.0,
    exempt: list[bool] | None = None,
    theta_end: np.ndarray | None = None,
    d_min: np.ndarray | None = None,
) -> BodyCrossings:
    """The body rule between the samples ``theta`` (T, n) [rad] at ``t`` (T,) [s], ``dt`` [s]
    apart, and on to ``theta_end`` (n,) [rad] (the last command's motion) when given; ``radius``,
    ``exempt`` as :func:`body_clearance`. ``d_min`` (T,) [m]: the samples' known
    :attr:`BodyClearance.d_min`; the intervals it proves clear are not looked at again."""
    theta = np.atleast_2d(np.asarray(theta, dtype=float))
    t = np.asarray(t, dtype=float).reshape(-1)
    known = np.full(len(theta), -np.inf) if d_min is None else np.asarray(d_min, dtype=float)
    if theta_end is not None and len(theta):
        theta = np.vstack([theta, np.asarray(theta_end, dtype=float)])
        t = np.append(t, t[-1] + dt)
        known = np.append(known, -np.inf)
    n, o = theta.shape[1], len(obstacles)
    found = _Found(max(len(theta) - 1, 0))
    if len(theta) < 2 or not obstacles:
        return found.crossings(t)
    link_speed, accel = _motion_bounds(arm, np.diff(theta, axis=0) / dt)
    own = np.array([math.hypot(*ob.velocity) for ob in obstacles])
    speed = link_speed[:, :, None] + own  # (K, n, o) [m/s]
    with np.errstate(invalid="ignore"):
        skip = (known[:-1] + known[1:] - speed.max(axis=(1, 2)) * dt) / 2.0 > SWEEP_TOL
    look = np.flatnonzero(~skip)  # the intervals to look at
    rows = np.unique(np.concatenate([look, look + 1]))
    at = np.zeros(len(theta), dtype=np.int64)
    at[rows] = np.arange(rows.size)
    p = project(arm.joint_positions(theta[rows]), "xyz")
    d = _clearances(p, t[rows], obstacles, radius, exempt)
    da, db, pa, pb = d[at[look]], d[at[look + 1]], p[at[look]], p[at[look + 1]]
    vs = speed[look]
    with np.errstate(invalid="ignore"):
        clear = (da >= 0.0) & (db >= 0.0) & np.isfinite(da + db + vs)
        proven = ((da + db - vs * dt) / 2.0 > SWEEP_TOL) | (vs == 0.0)
    if theta_end is not None:  # the last motion ends inside: no later sample says so
        i, j = np.nonzero((da[-1] >= 0.0) & (db[-1] < 0.0))
        found.add(np.full(i.size, len(theta) - 2), np.full(i.size, dt), i, j)
    q, i, j = np.nonzero(clear & ~proven)
    zero = np.zeros(q.size)
    piece = _Pieces(
        look[q], i, j, zero, zero + dt, da[q, i, j], db[q, i, j], pa[q, i], pa[q, i + 1],
        pb[q, i], pb[q, i + 1],
    )  # fmt: skip
    while piece.k.size:
        piece = piece.take(piece.a < found.s[piece.k])
        width, V = piece.b - piece.a, speed[piece.k, piece.i, piece.j]
        bound = _bound(piece, V, accel, obstacles, t, radius)
        piece = piece.take(~(bound > SWEEP_TOL) & (V * width > 0.0))
        width, V = piece.b - piece.a, speed[piece.k, piece.i, piece.j]
        key = (piece.k * n + piece.i) * o + piece.j
        _, inverse, counts = np.unique(key, return_inverse=True, return_counts=True)
        last = (V * width <= SWEEP_TOL) | (width <= dt * 2.0**-52) | (counts[inverse] > MAX_PIECES)
        _judge_last(piece.take(last), obstacles, t, found)
        piece = _split(piece.take(~last), arm, theta, t, dt, obstacles, radius, found)
    return found.crossings(t)


def _motion_bounds(arm, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bounds of every point's speed ``V`` [m/s] and acceleration ``A`` [m/s^2] on each link
    (K, n) while the joint velocities ``v`` (K, n) [rad/s] hold (docs/body.md: the planar arm's,
    and any other chain's of revolute joints)."""
    lengths = np.asarray(arm.lengths, dtype=float)
    if arm.dim == 2:  # a planar chain (:func:`~qpbench.robot.chain.planar_chain`)
        w = np.cumsum(v, axis=1)  # absolute angular speed of each link
        return np.cumsum(lengths * np.abs(w), axis=1), np.cumsum(lengths * w**2, axis=1)
    # R[j, i] = sum_{j<=k<=i} l_k for j <= i, else 0
    upper = np.triu(np.ones((len(lengths), len(lengths))))
    R = np.cumsum(upper * lengths[None, :], axis=1) * upper
    V = np.abs(v) @ R
    return V, np.cumsum(np.abs(v), axis=1) * V


class _Pieces(NamedTuple):
    """Pieces ``[a, b]`` [s from the interval's start] of intervals ``k``, for link ``i``
    (0-based) and obstacle ``j``: the clearances ``da, db`` [m] and the link's ends [m] there."""

    k: np.ndarray
    i: np.ndarray
    j: np.ndarray
    a: np.ndarray
    b: np.ndarray
    da: np.ndarray
    db: np.ndarray
    P0a: np.ndarray
    P1a: np.ndarray
    P0b: np.ndarray
    P1b: np.ndarray

    def take(self, rows) -> _Pieces:
        return _Pieces(*(x[rows] for x in self))

    def in_frame(self, rows, obstacle: Obstacle, t: np.ndarray) -> tuple:
        """The ``rows``' link ends at ``a`` and ``b`` in the obstacle's frame (it held as at
        ``a``), and the time [s] of ``a`` (from the intervals' start times ``t``)."""
        back = obstacle.velocity3 * (self.b[rows] - self.a[rows])[:, None]
        at = t[self.k[rows]] + self.a[rows]
        return self.P0a[rows], self.P1a[rows], self.P0b[rows] - back, self.P1b[rows] - back, at


def _bound(piece: _Pieces, V, accel, obstacles, t, radius) -> np.ndarray:
    """A lower bound [m] of each piece's clearance: the larger of the speed bound (``V`` [m/s])
    and the sweep bound (``accel`` (K, n) [m/s^2]), as the module docstring says."""
    width = piece.b - piece.a
    bound = (piece.da + piece.db - V * width) / 2.0
    sweep = ~(bound > SWEEP_TOL)
    for jj in np.unique(piece.j[sweep]):
        sel = np.flatnonzero(sweep & (piece.j == jj))
        swept = obstacles[jj].swept_distance_bound(*piece.in_frame(sel, obstacles[jj], t))
        delta = accel[piece.k[sel], piece.i[sel]] * width[sel] ** 2 / 8.0
        bound[sel] = np.maximum(bound[sel], swept - radius - delta)
    return bound


class _Found:
    """Per interval, the first time found inside [s from its start], its link and obstacle."""

    def __init__(self, intervals: int):
        self.s = np.full(intervals, np.inf)
        self.i = np.zeros(intervals, dtype=np.int64)
        self.j = np.zeros(intervals, dtype=np.int64)

    def add(self, k, s, i, j) -> None:
        earlier = s < self.s[k]
        k, s, i, j = k[earlier], s[earlier], i[earlier], j[earlier]
        order = np.lexsort((s, k))
        _, first = np.unique(k[order], return_index=True)
        rows = order[first]
        self.s[k[rows]], self.i[k[rows]], self.j[k[rows]] = s[rows], i[rows], j[rows]

    def crossings(self, t: np.ndarray) -> BodyCrossings:
        k = np.flatnonzero(np.isfinite(self.s))
        return BodyCrossings(k, t[k] + self.s[k], self.i[k] + 1, self.j[k])


def _judge_last(piece: _Pieces, obstacles, t, found: _Found) -> None:
    """Pieces not cut again: a point through the link (or the link's end through a bar) inside
    them is a crossing, at the piece's middle."""
    for jj in np.unique(piece.j):
        sel = np.flatnonzero(piece.j == jj)
        sel = sel[obstacles[jj].passed_through(*piece.in_frame(sel, obstacles[jj], t))]
        mid = (piece.a[sel] + piece.b[sel]) / 2.0
        found.add(piece.k[sel], mid, piece.i[sel], piece.j[sel])


def _split(piece: _Pieces, arm, theta, t, dt, obstacles, radius, found: _Found) -> _Pieces:
    """Cut each piece in halves; a link inside its obstacle at the cut is found there, and only
    the first half, where it went in, is kept."""
    if not piece.k.size:
        return piece
    m = (piece.a + piece.b) / 2.0
    k, i = piece.k, piece.i
    at = theta[k] + (m / dt)[:, None] * (theta[k + 1] - theta[k])
    p = project(arm.joint_positions(at), "xyz")
    rows = np.arange(k.size)
    P0m, P1m = p[rows, i], p[rows, i + 1]
    dm = np.empty(k.size)
    for jj in np.unique(piece.j):
        sel = np.flatnonzero(piece.j == jj)
        _, _, dist, _ = obstacles[jj].closest_on_segments(P0m[sel], P1m[sel], t[k[sel]] + m[sel])
        dm[sel] = dist.min(axis=1) - radius
    inside = dm < 0.0
    found.add(k[inside], m[inside], i[inside], piece.j[inside])
    first = _Pieces(k, i, piece.j, piece.a, m, piece.da, dm, piece.P0a, piece.P1a, P0m, P1m)
    second = _Pieces(k, i, piece.j, m, piece.b, dm, piece.db, P0m, P1m, piece.P0b, piece.P1b)
    second = second.take(~inside)
    return _Pieces(*(np.concatenate([x, y]) for x, y in zip(first, second)))

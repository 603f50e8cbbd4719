"""Drawing on matplotlib axes, shared by the kinds: a 3-D scene seen along one axis (an
orthographic view on the plane of two axes, ``("x", "y")`` the planar view), lengths [m]."""

from __future__ import annotations

import numpy as np

#: Colour of obstacles: neutral, so that a backend's look is the only colour that names one.
OBSTACLE_COLOR = "#868e96"
_AXES = {"x": 0, "y": 1, "z": 2}


def project(points, plane=("x", "y")) -> np.ndarray:
    """Points (..., d) [m] (d = 2: in z = 0) on the view ``plane`` (..., 2)."""
    points = np.asarray(points, dtype=float)
    full = np.zeros((*points.shape[:-1], 3))
    full[..., : points.shape[-1]] = points
    return full[..., [_AXES[plane[0]], _AXES[plane[1]]]]


def look(name: str, faint: bool, color=None) -> dict:
    """Colour, opacity and label of an obstacle (an earlier time's: paler, no label)."""
    alpha = 0.25 if faint else 1.0
    return dict(color=color or OBSTACLE_COLOR, alpha=alpha, label=None if faint else name)


def draw_line(ax, point, normal, xlim, ylim, **line) -> None:
    """The line through ``point`` perpendicular to ``normal`` (both 2-D), its solid side (away
    from the normal) lightly filled, across the view's limits."""
    normal = np.asarray(normal, dtype=float)
    tangent = np.array([-normal[1], normal[0]])
    span = 4.0 * max(xlim[1] - xlim[0], ylim[1] - ylim[0])
    a, b = point - span * tangent, point + span * tangent
    ax.plot([a[0], b[0]], [a[1], b[1]], **line)
    depth = 0.04 * span
    poly = np.array([a, b, b - depth * normal, a - depth * normal])
    ax.fill(poly[:, 0], poly[:, 1], color=line.get("color", OBSTACLE_COLOR), alpha=0.12, lw=0)


def draw_outline(ax, points, radius: float, **style) -> None:
    """The convex hull of ``points`` (k, 2) [m] swollen by ``radius`` [m], filled (a disk, a
    capsule's or a box's shadow)."""
    from matplotlib.patches import Polygon

    angles = np.linspace(0.0, 2.0 * np.pi, 48, endpoint=False)
    ring = np.stack([np.cos(angles), np.sin(angles)], axis=1) * radius
    cloud = (np.asarray(points, dtype=float)[:, None, :] + ring[None]).reshape(-1, 2)
    if radius == 0.0:
        cloud = np.asarray(points, dtype=float)
    hull = _hull(cloud)
    style = {**style, "alpha": 0.35 * style.get("alpha", 1.0)}
    ax.add_patch(Polygon(hull, closed=True, lw=0, **style))


def _hull(points: np.ndarray) -> np.ndarray:
    """Convex hull of planar points (monotone chain), counter-clockwise."""
    pts = sorted(set(map(tuple, np.round(points, 15))))
    if len(pts) < 3:
        return np.array(pts)

    def half(seq):
        out: list = []
        for p in seq:
            while len(out) >= 2 and _turn(out[-2], out[-1], p) <= 0:
                out.pop()
            out.append(p)
        return out[:-1]

    return np.array(half(pts) + half(pts[::-1]))


def _turn(o, a, b) -> float:
    return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

"""Drawing on matplotlib axes, shared by the kinds: a 3-D scene seen along one axis (an
orthographic view on the plane of two axes, ``("x", "y")`` the planar view), lengths [m]."""

from __future__ import annotations

import numpy as np

#: Colour of obstacles: neutral, so that a backend's look is the only colour that names one.
OBSTACLE_COLOR = "#868e96"
_AXES = {"x": 0, "y": 1, "z": 2}


def project(points, plane=("x", "y")) -> np.ndarray:
    """Points (..., d) [m] (d = 2: in z = 0) on the view ``plane`` (..., 2): their coordinates
    along its axes, in order (``("x", "y", "z")``: the points in 3-D)."""
    points = np.asarray(points, dtype=float)
    full = np.zeros((*points.shape[:-1], 3))
    full[..., : points.shape[-1]] = points
    return full[..., [_AXES[a] for a in plane]]


def trace(point, normal, plane=("x", "y")):
    """The line a plane through ``point`` [m] with ``normal`` (2-D: a line of z = 0) leaves on
    the view ``plane``: a point of it [m] and its unit normal there (each (2,)); ``None`` when
    the plane is seen face on. Exact when seen edge on (the normal in the view plane, as a
    line's always is); else the plane's section through the origin of the third axis."""
    n = project(normal, plane)
    if np.linalg.norm(n) < 1e-12:
        return None
    offset = float(project(normal, "xyz") @ project(point, "xyz")) / float(n @ n)
    return offset * n, n / np.linalg.norm(n)


def draw_trace(ax, point, normal, plane, limits, **line) -> None:
    """The plane through ``point`` [m] with ``normal`` (towards its free side) on the view
    ``plane`` (:func:`trace`): its line across ``limits`` (xlim, ylim) [m], its solid side (away
    from the normal) lightly filled."""
    seen = trace(point, normal, plane)
    if seen is None:
        return
    point, normal = seen
    (x0, x1), (y0, y1) = limits
    tangent = np.array([-normal[1], normal[0]])
    span = 4.0 * max(x1 - x0, y1 - y0)
    a, b = point - span * tangent, point + span * tangent
    ax.plot([a[0], b[0]], [a[1], b[1]], **line)
    depth = 0.04 * span
    poly = np.array([a, b, b - depth * normal, a - depth * normal])
    ax.fill(poly[:, 0], poly[:, 1], color=line.get("color", OBSTACLE_COLOR), alpha=0.12, lw=0)


def look(name: str, faint: bool, color=None) -> dict:
    """Colour, opacity and label of an obstacle (an earlier time's: paler, no label)."""
    alpha = 0.25 if faint else 1.0
    return dict(color=color or OBSTACLE_COLOR, alpha=alpha, label=None if faint else name)


def outline(points, radius: float) -> np.ndarray:
    """The convex hull (k, 2) [m], counter-clockwise, of ``points`` (k, 2) [m] swollen by
    ``radius`` [m] (a disk's, a capsule's or a box's shadow)."""
    from scipy.spatial import ConvexHull

    points = np.asarray(points, dtype=float)
    if radius != 0.0:
        angles = np.linspace(0.0, 2.0 * np.pi, 48, endpoint=False)
        ring = np.stack([np.cos(angles), np.sin(angles)], axis=1) * radius
        points = (points[:, None, :] + ring[None]).reshape(-1, 2)
    hull = points[ConvexHull(points).vertices]
    return np.roll(hull, -np.lexsort(hull.T[::-1])[0], axis=0)  # from the least (x, y)


def draw_outline(ax, points, radius: float, **style):
    """:func:`outline` filled; the patch."""
    from matplotlib.patches import Polygon

    style = {**style, "alpha": 0.35 * style.get("alpha", 1.0)}
    return ax.add_patch(Polygon(outline(points, radius), closed=True, lw=0, **style))

"""``points``: a cloud of points of the plane (paper section 2.2: obstacles as key points), each
a sphere of radius 0 in z = 0."""

from __future__ import annotations

from typing import Literal

import numpy as np

from . import register
from ._base import Obstacle, PlanarSchema, Points2, planar_ends
from ._draw import look, project
from ._planar import passes_through, swept_point_bound
from ._table import POINT, table_rows


class PointsSchema(PlanarSchema):
    """``points``: ``[[x, y], ...]`` [m] at t = 0."""

    kind: Literal["points"]
    points: Points2


@register
class PointCloudObstacle(Obstacle):
    """A set of points ``B_1..B_m`` in [m] (paper section 2.2: obstacles as key points)."""

    KIND = "points"
    KERNEL_KIND = POINT
    Schema = PointsSchema
    DIM = 2

    def __init__(self, name: str, points, velocity=(0.0, 0.0)):
        super().__init__(name=name, points=points, velocity=velocity)
        self.points = np.array(self.fields.points, dtype=float)

    def primitives(self) -> np.ndarray:
        return table_rows(self.KERNEL_KIND, len(self.points), p0=self.points, v=self.velocity)

    def swept_distance_bound(self, P0a, P1a, P0b, P1b, t):
        """In the plane: each point against the swept segment."""
        ends = planar_ends(P0a, P1a, P0b, P1b)
        if ends is None:
            return super().swept_distance_bound(P0a, P1a, P0b, P1b, t)
        C, ends = self._each_point(t, *ends)
        return swept_point_bound(C, *ends).reshape(-1, len(self.points)).min(axis=1)

    def passed_through(self, P0a, P1a, P0b, P1b, t):
        """In the plane: a point that changes sides of the segment within it (3-D: a point
        through a segment is not a crossing of any extent, ``False``)."""
        ends = planar_ends(P0a, P1a, P0b, P1b)
        if ends is None:
            return super().passed_through(P0a, P1a, P0b, P1b, t)
        C, ends = self._each_point(t, *ends)
        return passes_through(C, C, *ends).reshape(-1, len(self.points)).any(axis=1)

    def _each_point(self, t, *ends):
        """The cloud's points at ``t`` [s] (s * m, 2) and each of the ``ends`` (s, 2) repeated
        for each point, (s * m, 2)."""
        s, m = len(ends[0]), len(self.points)
        t = np.broadcast_to(np.asarray(t, dtype=float), (s,))
        C = (self.points[None, :, :] + t[:, None, None] * self.velocity).reshape(-1, 2)
        return C, [np.repeat(E, m, axis=0) for E in ends]

    def draw(self, ax, t=0.0, plane=("x", "y"), limits=None, faint=False, color=None):
        """Each point as a dot."""
        pts = project(self.points + t * self.velocity, plane)
        ax.scatter(pts[:, 0], pts[:, 1], s=6, **look(self.name, faint, color))

    def view_points(self, plane=("x", "y")):
        return project(self.points, plane)

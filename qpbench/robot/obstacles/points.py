"""``points``: a cloud of points of the plane (paper section 2.2: obstacles as key points), each
a sphere of radius 0 in z = 0."""

from __future__ import annotations

from typing import Literal

import numpy as np

from . import register
from ._base import PlanarObstacle, PlanarSchema, Points2
from ._draw import look, project
from ._planar import passes_through, swept_point_bound
from ._table import POINT, table_rows


class PointsSchema(PlanarSchema):
    """``points``: ``[[x, y], ...]`` [m] at t = 0."""

    kind: Literal["points"]
    points: Points2


@register
class PointCloudObstacle(PlanarObstacle):
    """A set of points ``B_1..B_m`` in [m] (paper section 2.2: obstacles as key points)."""

    KIND = "points"
    KERNEL_KIND = POINT
    Schema = PointsSchema

    def __init__(self, name: str, points, velocity=(0.0, 0.0)):
        super().__init__(name=name, points=points, velocity=velocity)
        self.points = np.array(self.fields.points, dtype=float)

    def primitives(self) -> np.ndarray:
        return table_rows(self.KERNEL_KIND, len(self.points), p0=self.points, v=self.velocity)

    def _swept_in_plane(self, t, *ends):
        """Each point against the swept segment."""
        C, ends = self._each_point(t, *ends)
        return swept_point_bound(C, *ends).reshape(-1, len(self.points)).min(axis=1)

    def _passed_in_plane(self, t, *ends):
        """A point that changes sides of the segment within it (3-D: a point through a segment
        is not a crossing of any extent, ``False``)."""
        C, ends = self._each_point(t, *ends)
        return passes_through(C, C, *ends).reshape(-1, len(self.points)).any(axis=1)

    def _each_point(self, t, *ends):
        """The cloud's points at ``t`` [s] (s * m, 2) and each of the ``ends`` (s, 2) repeated
        for each point, (s * m, 2)."""
        C = self._at(self.points, t, len(ends[0])).reshape(-1, 2)
        return C, [np.repeat(E, len(self.points), axis=0) for E in ends]

    def draw(self, ax, t=0.0, plane=("x", "y"), limits=None, faint=False, color=None):
        """Each point as a dot."""
        pts = project(self.points + t * self.velocity, plane)
        ax.scatter(pts[:, 0], pts[:, 1], s=6, **look(self.name, faint, color))

    def view_points(self, plane=("x", "y")):
        return project(self.points, plane)

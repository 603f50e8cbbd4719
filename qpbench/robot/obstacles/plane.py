"""``plane``: a half-space (3-D); the planar ``line`` is one whose normal lies in the xy-plane."""

from __future__ import annotations

from typing import Literal

import numpy as np

from . import register
from ._base import Obstacle, SpatialSchema, Vec3, unit
from ._draw import draw_trace, look, project, trace
from ._table import PLANE, table_rows


class PlaneSchema(SpatialSchema):
    """``point`` [m] on the plane at t = 0, ``normal`` towards the free side."""

    kind: Literal["plane"]
    point: Vec3
    normal: Vec3


@register
class PlaneObstacle(Obstacle):
    """A plane through ``point`` [m] at t = 0; ``normal`` points to the free side (normalised
    here), the half-space ``normal . (x - point) < 0`` is forbidden; its distance is signed."""

    KIND = "plane"
    KERNEL_KIND = PLANE
    Schema = PlaneSchema

    def __init__(self, name: str, point, normal, velocity=None):
        super().__init__(name=name, point=point, normal=normal, velocity=velocity)
        self.point = np.array(self.fields.point, dtype=float)
        self.normal = unit(self.fields.normal, self._key("normal"))

    def primitives(self) -> np.ndarray:
        return table_rows(self.KERNEL_KIND, p0=self.point, p1=self.normal, v=self.velocity)

    def swept_distance_bound(self, P0a, P1a, P0b, P1b, t):
        """Exact: the signed distance of a point is linear along the sweep, so its least is at
        one of the four ends (a half-space cannot be passed through)."""
        axes = "xyz"[: np.shape(P0a)[1]]  # the ends' (2: in z = 0)
        t = np.broadcast_to(np.asarray(t, dtype=float), (np.shape(P0a)[0],))
        p = project(self.point, axes)[None, :] + t[:, None] * project(self.velocity, axes)
        ends = np.stack([P0a, P1a, P0b, P1b], axis=1) - p[:, None, :]
        return np.einsum("sei,i->se", ends, project(self.normal, axes)).min(axis=1)

    def draw(self, ax, t=0.0, plane=("x", "y"), limits=None, faint=False, color=None):
        """The plane's trace on the view plane (:func:`~._draw.trace`), its solid side lightly
        filled; a static one is not drawn again ``faint``."""
        if faint and not np.any(self.velocity):
            return
        point = project(self.point, "xyz") + t * self.velocity3
        draw_trace(ax, point, self.normal, plane, limits, lw=2, **look(self.name, faint, color))

    def view_points(self, plane=("x", "y")):
        seen = trace(self.point, self.normal, plane)
        return np.empty((0, 2)) if seen is None else seen[0][None]

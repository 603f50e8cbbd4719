"""``sphere``: a ball (3-D); the planar ``disk`` and a cloud's points are spheres too."""

from __future__ import annotations

from typing import Literal

import numpy as np

from . import register
from ._base import Obstacle, Positive, SpatialSchema, Vec3
from ._draw import draw_outline, look, project
from ._table import SPHERE, table_rows


class SphereSchema(SpatialSchema):
    """``center`` [m] at t = 0 and ``radius`` [m]."""

    kind: Literal["sphere"]
    center: Vec3
    radius: Positive


@register
class SphereObstacle(Obstacle):
    """A ball of centre ``center`` and radius ``radius`` in [m]."""

    KIND = "sphere"
    KERNEL_KIND = SPHERE
    Schema = SphereSchema

    def __init__(self, name: str, center, radius: float, velocity=None):
        super().__init__(name=name, center=center, radius=radius, velocity=velocity)
        self.center = np.array(self.fields.center, dtype=float)
        self.radius = float(self.fields.radius)

    def primitives(self) -> np.ndarray:
        return table_rows(self.KERNEL_KIND, p0=self.center, radius=self.radius, v=self.velocity)

    def draw(self, ax, t=0.0, plane=("x", "y"), limits=None, faint=False, color=None):
        """Its shadow on the view plane, a disk."""
        c = project(project(self.center, "xyz") + t * self.velocity3, plane)
        draw_outline(ax, c[None], self.radius, **look(self.name, faint, color))

    def view_points(self, plane=("x", "y")):
        c = project(self.center, plane)
        return c + self.radius * np.array([[1, 0], [-1, 0], [0, 1], [0, -1]])

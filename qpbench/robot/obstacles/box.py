"""``box``: an oriented box (3-D)."""

from __future__ import annotations

from itertools import product
from typing import Annotated, Literal

import numpy as np

from . import register
from ._base import Obstacle, Positive, Quat, SpatialSchema, Vec3, unit, vector
from ._draw import draw_outline, look, project
from ._table import BOX, table_rows


class BoxSchema(SpatialSchema):
    """``center`` [m] at t = 0, ``half_extents`` [m] along the box's axes, and ``quaternion``
    ``[w, x, y, z]`` (box frame to world; normalised; default the identity)."""

    kind: Literal["box"]
    center: Vec3
    half_extents: Annotated[tuple[Positive, Positive, Positive], vector(3)]
    quaternion: Quat = (1.0, 0.0, 0.0, 0.0)


@register
class BoxObstacle(Obstacle):
    """A box of centre ``center``, half extents ``half_extents`` [m] and orientation
    ``quaternion``; inside, a segment's distance is minus its deepest point's depth."""

    KIND = "box"
    KERNEL_KIND = BOX
    Schema = BoxSchema

    def __init__(
        self, name: str, center, half_extents, quaternion=(1.0, 0.0, 0.0, 0.0), velocity=(0, 0, 0)
    ):
        fields = dict(center=center, half_extents=half_extents, quaternion=quaternion)
        super().__init__(name=name, velocity=velocity, **fields)
        self.center = np.array(self.fields.center, dtype=float)
        self.half_extents = np.array(self.fields.half_extents, dtype=float)
        self.quaternion = unit(self.fields.quaternion, self._key("quaternion"))

    def primitives(self) -> np.ndarray:
        rows = dict(p0=self.center, h=self.half_extents, q=self.quaternion, v=self.velocity)
        return table_rows(self.KERNEL_KIND, **rows)

    def rotation(self) -> np.ndarray:
        """The rotation matrix (3, 3) of :attr:`quaternion` (box frame to world)."""
        from scipy.spatial.transform import Rotation

        return Rotation.from_quat(np.roll(self.quaternion, -1)).as_matrix()  # scalar last

    def corners(self, t: float = 0.0) -> np.ndarray:
        """The 8 corners (8, 3) [m] at ``t`` [s]."""
        signs = np.array(list(product((-1.0, 1.0), repeat=3)))
        return self.center + t * self.velocity3 + (signs * self.half_extents) @ self.rotation().T

    def draw(self, ax, t=0.0, plane=("x", "y"), limits=None, faint=False, color=None):
        """Its shadow on the view plane (the hull of its corners)."""
        draw_outline(ax, project(self.corners(t), plane), 0.0, **look(self.name, faint, color))

    def view_points(self, plane=("x", "y")):
        return project(self.corners(), plane)

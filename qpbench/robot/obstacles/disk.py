"""``disk``: a disk of the plane (a ``sphere`` in z = 0)."""

from __future__ import annotations

from typing import Literal

from . import register
from ._base import PlanarObstacle, PlanarSchema, Positive, Vec2
from ._planar import passes_through, swept_point_bound
from ._table import DISK
from .sphere import SphereObstacle


class DiskSchema(PlanarSchema):
    """``center`` [m] at t = 0 and ``radius`` [m]."""

    kind: Literal["disk"]
    center: Vec2
    radius: Positive


@register
class DiskObstacle(PlanarObstacle, SphereObstacle):
    """A disk of centre ``center`` and radius ``radius`` in [m]."""

    KIND = "disk"
    KERNEL_KIND = DISK
    Schema = DiskSchema

    def _swept_in_plane(self, t, *ends):
        """The centre against the swept segment minus the radius."""
        return swept_point_bound(self._at(self.center, t, len(ends[0])), *ends) - self.radius

    def _passed_in_plane(self, t, *ends):
        """The centre through the segment."""
        c = self._at(self.center, t, len(ends[0]))
        return passes_through(c, c, *ends)

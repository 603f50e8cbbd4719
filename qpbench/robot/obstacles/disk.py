"""``disk``: a disk of the plane (a ``sphere`` in z = 0)."""

from __future__ import annotations

from typing import Literal

import numpy as np

from . import register
from ._base import PlanarSchema, Positive, Vec2, planar_ends
from ._planar import passes_through, swept_point_bound
from ._table import DISK
from .sphere import SphereObstacle


class DiskSchema(PlanarSchema):
    """``center`` [m] at t = 0 and ``radius`` [m]."""

    kind: Literal["disk"]
    center: Vec2
    radius: Positive


@register
class DiskObstacle(SphereObstacle):
    """A disk of centre ``center`` and radius ``radius`` in [m]."""

    KIND = "disk"
    KERNEL_KIND = DISK
    Schema = DiskSchema
    DIM = 2

    def _centre(self, t, s: int) -> np.ndarray:
        t = np.broadcast_to(np.asarray(t, dtype=float), (s,))
        return self.center + t[:, None] * self.velocity

    def swept_distance_bound(self, P0a, P1a, P0b, P1b, t):
        """In the plane: the centre against the swept segment minus the radius."""
        ends = planar_ends(P0a, P1a, P0b, P1b)
        if ends is None:
            return super().swept_distance_bound(P0a, P1a, P0b, P1b, t)
        return swept_point_bound(self._centre(t, len(P0a)), *ends) - self.radius

    def passed_through(self, P0a, P1a, P0b, P1b, t):
        """In the plane: the centre through the segment."""
        ends = planar_ends(P0a, P1a, P0b, P1b)
        if ends is None:
            return super().passed_through(P0a, P1a, P0b, P1b, t)
        c = self._centre(t, len(P0a))
        return passes_through(c, c, *ends)

"""The obstacle table the compiled code reads: one row per obstacle primitive at t = 0.

Columns (:data:`OBSTACLE_COLUMNS`, their indices by the same names in capitals): the kind code,
a first point ``p0`` [m] (a plane's point, a sphere's or a box's centre, a capsule's first end),
a second ``p1`` (a plane's unit normal, a capsule's second end) [m], the ``radius`` [m], the
velocity ``v`` [m/s], a box's half extents ``h`` [m] and its orientation as a unit quaternion
``q = (w, x, y, z)`` (box frame to world). The first eight columns are the planar table's (a
planar kind fills ``z = 0``): a planar scenario's table reads the same in them.
"""

from __future__ import annotations

import numpy as np

OBSTACLE_COLUMNS = (
    *("kind", "p0x", "p0y", "p1x", "p1y", "radius", "vx", "vy"),
    *("p0z", "p1z", "vz", "hx", "hy", "hz", "qw", "qx", "qy", "qz"),
)
KIND, P0X, P0Y, P1X, P1Y, RADIUS, VX, VY = range(8)
P0Z, P1Z, VZ, HX, HY, HZ, QW, QX, QY, QZ = range(8, len(OBSTACLE_COLUMNS))
#: The ``kind`` codes: the planar kinds' (a line is a plane with its normal in the xy-plane, a
#: segment a capsule of radius 0, a disk a sphere, a cloud point a sphere of radius 0) and the
#: spatial kinds'.
LINE, SEGMENT, DISK, POINT, PLANE, SPHERE, CAPSULE, BOX = range(8)


def table_rows(kind: int, count: int = 1, **columns) -> np.ndarray:
    """``count`` rows of kind code ``kind``: each keyword a column name (``p0``, ``p1``, ``v``,
    ``h``, ``q`` for their xyz or wxyz columns, a vector or one per row) or a scalar column; a
    vector of two entries fills x and y. Unset columns are 0 (``q``: the identity)."""
    rows = np.zeros((count, len(OBSTACLE_COLUMNS)))
    rows[:, KIND] = kind
    rows[:, QW] = 1.0
    groups = {
        "p0": (P0X, P0Y, P0Z),
        "p1": (P1X, P1Y, P1Z),
        "v": (VX, VY, VZ),
        "h": (HX, HY, HZ),
        "q": (QW, QX, QY, QZ),
    }
    for name, value in columns.items():
        value = np.asarray(value, dtype=float)
        cols = groups[name] if name in groups else (OBSTACLE_COLUMNS.index(name),)
        width = value.shape[-1] if value.ndim else 1
        rows[:, list(cols[:width])] = value
    return rows

"""The compiled geometry every kind shares: the signed distance of an obstacle row of the table
(:mod:`._table`) to a segment, with its gradient direction (:func:`compiled_segment_distance`).

Planes (``line``, ``plane``), spheres (``disk``, ``points``, ``sphere``), capsules (``segment``,
``capsule``) and boxes, in 3-D; a 2-D point is one with ``z = 0``.
"""

from __future__ import annotations

from functools import cache

import numpy as np

from ._table import (
    BOX,
    CAPSULE,
    HX,
    HY,
    HZ,
    KIND,
    LINE,
    P0X,
    P0Y,
    P0Z,
    P1X,
    P1Y,
    P1Z,
    PLANE,
    QW,
    QX,
    QY,
    QZ,
    RADIUS,
    SEGMENT,
    VX,
    VY,
    VZ,
)


@cache
def compiled_segment_distance():
    """``segment_distance(row, a, b, t, u) -> (d, s)``, compiled (numba, cached) on first call.

    ``row``: one row of the obstacle table (float64); ``a``, ``b``: the segment's ends [m]
    (float64 arrays of length 2 or 3, a capsule's axis; 2 means ``z = 0``; ``a == b`` is a
    point); ``t``: time [s] (the obstacle moved by its velocity times ``t``); ``u``: float64
    array of the length of ``a``, filled with the unit direction from the obstacle's closest
    point to the segment's (the obstacle row's gradient: ``d d / d x`` of the segment's closest
    point ``x``; for a plane its normal). Returns the signed distance ``d`` [m] (the caller
    subtracts the link's radius; ``< 0``: inside) and ``s`` in [0, 1], the segment's closest
    point ``a + s (b - a)`` (the deepest, inside). No allocation per call.

    Per kind: a plane's distance is signed (its least at an end of the segment); a sphere's
    is the distance to its centre minus its radius; a capsule's the segments' distance
    (closest points of two segments, the parallel case included) minus its radius, and a
    planar ``segment`` crossing the segment in the plane gives minus the least distance of an
    end of one to the other (the way out); a box's is exact outside (the squared distance to
    the box is convex and piecewise quadratic in ``s`` with at most 6 breakpoints in the box's
    frame: every piece's minimiser in closed form and the breakpoints are compared) and, where
    the segment enters the box, minus the depth of its deepest point (the distance of that
    point to its nearest face; ``u`` that face's outward normal). Where the direction is
    undefined (a centre or an axis on the segment), ``u`` is a unit normal of the segment
    (in the xy-plane when the segment is not along z).
    """
    from ...native import compile_with

    closest = compile_with(_closest_params, name="closest_params")
    box_helpers = {"_excess": compile_with(_excess, name="box_excess")}
    box_helpers["_box_depth"] = compile_with(_box_depth, name="box_depth")
    box = compile_with(_box, box_helpers, name="box")
    helpers = {"_closest_params": closest, "_box": box}
    helpers["_planar_segments"] = compile_with(
        _planar_segments,
        {"_crosses": compile_with(_crosses, name="crosses")},
        name="planar_segments",
    )
    return compile_with(_segment_distance, helpers, name="segment_distance", _nrt=False)


def _segment_distance(row, a, b, t, u):  # pragma: no cover - compiled
    """See :func:`compiled_segment_distance`."""
    kind = int(row[KIND])
    dim = a.shape[0]
    ax, ay, az = a[0], a[1], a[2] if dim == 3 else 0.0
    ex, ey, ez = b[0] - ax, b[1] - ay, (b[2] if dim == 3 else 0.0) - az
    cx, cy, cz = row[P0X] + row[VX] * t, row[P0Y] + row[VY] * t, row[P0Z] + row[VZ] * t
    bx, by, bz = b[0], b[1], b[2] if dim == 3 else 0.0
    planar = az == 0.0 and bz == 0.0 and row[P0Z] == 0.0 and row[P1Z] == 0.0 and row[VZ] == 0.0
    if kind == LINE or kind == PLANE:
        nx, ny, nz = row[P1X], row[P1Y], row[P1Z]
        d = (ax - cx) * nx + (ay - cy) * ny + (az - cz) * nz
        d1 = (bx - cx) * nx + (by - cy) * ny + (bz - cz) * nz
        s = 0.0
        if d1 < d:
            d, s = d1, 1.0
        ux, uy, uz = nx, ny, nz
    elif kind == BOX:
        q = (row[QW], row[QX], row[QY], row[QZ])
        h = (row[HX], row[HY], row[HZ])
        d, s, ux, uy, uz = _box(ax - cx, ay - cy, az - cz, ex, ey, ez, h, q)
    elif kind == SEGMENT and planar:
        qx, qy = cx + (row[P1X] - row[P0X]), cy + (row[P1Y] - row[P0Y])
        d, s, ux, uy = _planar_segments(ax, ay, bx, by, cx, cy, qx, qy)
        uz = 0.0
    else:
        if kind == SEGMENT or kind == CAPSULE:
            fx, fy, fz = row[P1X] - row[P0X], row[P1Y] - row[P0Y], row[P1Z] - row[P0Z]
            s, w = _closest_params(ax - cx, ay - cy, az - cz, ex, ey, ez, fx, fy, fz)
            cx, cy, cz = cx + w * fx, cy + w * fy, cz + w * fz
        else:  # a sphere: the foot of its centre
            ee = ex * ex + ey * ey + ez * ez
            s = ((cx - ax) * ex + (cy - ay) * ey + (cz - az) * ez) / (ee if ee > 0.0 else 1.0)
            s = min(max(s, 0.0), 1.0)
        dx, dy, dz = ax + s * ex - cx, ay + s * ey - cy, az + s * ez - cz
        dist = np.sqrt(dx * dx + dy * dy + dz * dz)
        if dist > 0.0:
            ux, uy, uz = dx / dist, dy / dist, dz / dist
        else:
            norm = np.sqrt(ex * ex + ey * ey)
            ux, uy, uz = (-ey / norm, ex / norm, 0.0) if norm > 0.0 else (1.0, 0.0, 0.0)
        d = dist - row[RADIUS]
    u[0], u[1] = ux, uy
    if dim == 3:
        u[2] = uz
    return d, s


def _closest_params(rx, ry, rz, ex, ey, ez, fx, fy, fz):  # pragma: no cover - compiled
    """Parameters ``(s, w)`` in [0, 1] of the closest points of the segments ``a + s e`` and
    ``c + w f`` with ``r = a - c`` (parallel and degenerate segments included)."""
    aa = ex * ex + ey * ey + ez * ez
    ff = fx * fx + fy * fy + fz * fz
    rf = fx * rx + fy * ry + fz * rz
    if aa <= 0.0:
        return 0.0, (min(max(rf / ff, 0.0), 1.0) if ff > 0.0 else 0.0)
    re = ex * rx + ey * ry + ez * rz
    if ff <= 0.0:
        return min(max(-re / aa, 0.0), 1.0), 0.0
    ef = ex * fx + ey * fy + ez * fz
    denom = aa * ff - ef * ef
    s = min(max((ef * rf - re * ff) / denom, 0.0), 1.0) if denom > 1e-14 * aa * ff else 0.0
    w = (ef * s + rf) / ff
    if w < 0.0:
        return min(max(-re / aa, 0.0), 1.0), 0.0
    if w > 1.0:
        return min(max((ef - re) / aa, 0.0), 1.0), 1.0
    return s, w


def _crosses(p0x, p0y, p1x, p1y, q0x, q0y, q1x, q1y):  # pragma: no cover - compiled
    """Planar segments ``p`` and ``q`` cross strictly (each splits the other's ends)."""
    ex, ey, fx, fy = p1x - p0x, p1y - p0y, q1x - q0x, q1y - q0y
    s1 = (ex * (q0y - p0y) - ey * (q0x - p0x)) * (ex * (q1y - p0y) - ey * (q1x - p0x))
    s2 = (fx * (p0y - q0y) - fy * (p0x - q0x)) * (fx * (p1y - q0y) - fy * (p1x - q0x))
    return s1 < 0.0 and s2 < 0.0


def _planar_segments(ax, ay, bx, by, px, py, qx, qy):  # pragma: no cover - compiled
    """Planar segments ``a -> b`` and ``p -> q``: ``(d, s, ux, uy)``. Their closest pair has an
    end of one on the other (four candidates); apart, ``d`` is their distance and ``u`` points
    from the bar's point to the segment's; crossing, ``d`` is minus the least distance of an end
    of one to the other (the shortest way out) and ``u`` points from the segment's point of that
    pair to the other's (the way the segment must move to come free)."""
    ex, ey, fx, fy = bx - ax, by - ay, qx - px, qy - py
    ee, ff = ex * ex + ey * ey, fx * fx + fy * fy
    ee, ff = ee if ee > 0.0 else 1.0, ff if ff > 0.0 else 1.0
    best, s_best, vx, vy = np.inf, 0.0, 0.0, 0.0
    for k in range(4):
        if k < 2:  # an end of the segment against p -> q
            s = float(k)
            xx, xy = (ax, ay) if k == 0 else (bx, by)
            w = min(max(((xx - px) * fx + (xy - py) * fy) / ff, 0.0), 1.0)
            yx, yy = px + w * fx, py + w * fy
        else:  # an end of p -> q against the segment
            yx, yy = (px, py) if k == 2 else (qx, qy)
            s = min(max(((yx - ax) * ex + (yy - ay) * ey) / ee, 0.0), 1.0)
            xx, xy = ax + s * ex, ay + s * ey
        gap = np.sqrt((xx - yx) ** 2 + (xy - yy) ** 2)
        if gap < best:
            best, s_best, vx, vy = gap, s, xx - yx, xy - yy
    if best > 0.0:
        vx, vy = vx / best, vy / best
    if _crosses(ax, ay, bx, by, px, py, qx, qy):
        return -best, s_best, -vx, -vy
    return best, s_best, vx, vy


def _excess(x, h):  # pragma: no cover - compiled
    """How far ``x`` lies beyond the slab ``[-h, h]`` (signed; 0 inside)."""
    return x - h if x > h else (x + h if x < -h else 0.0)


def _box(rx, ry, rz, ex, ey, ez, h, q):  # pragma: no cover - compiled
    """Box of half extents ``h`` [m] and orientation ``q`` (w, x, y, z) against the segment
    ``c + r + s e`` (``c`` its centre): ``(d, s, ux, uy, uz)`` as in
    :func:`compiled_segment_distance`."""
    w, x, y, z = q
    r00, r01, r02 = 1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)
    r10, r11, r12 = 2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)
    r20, r21, r22 = 2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)
    # the segment in the box's frame (R^T r, R^T e)
    p = (
        r00 * rx + r10 * ry + r20 * rz,
        r01 * rx + r11 * ry + r21 * rz,
        r02 * rx + r12 * ry + r22 * rz,
    )
    e = (
        r00 * ex + r10 * ey + r20 * ez,
        r01 * ex + r11 * ey + r21 * ez,
        r02 * ex + r12 * ey + r22 * ez,
    )
    best, s_best = np.inf, 0.0
    # candidates: the ends, the 6 breakpoints, and each piece's minimiser; a piece is fixed by
    # each axis' side (below, within, above: 27 sign patterns, those of no piece only add values
    # not below the least)
    for k in range(35):
        if k < 2:
            s = float(k)
        elif k < 8:
            i, side = (k - 2) // 2, 1.0 if k % 2 else -1.0
            if e[i] == 0.0:
                continue
            s = (side * h[i] - p[i]) / e[i]
        else:
            num, den, code = 0.0, 0.0, k - 8
            for i in range(3):
                side = float(code % 3 - 1)
                code //= 3
                if side != 0.0:
                    num -= e[i] * (p[i] - side * h[i])
                    den += e[i] * e[i]
            if den == 0.0:
                continue
            s = num / den
        s = min(max(s, 0.0), 1.0)
        f = 0.0
        for i in range(3):
            f += _excess(p[i] + s * e[i], h[i]) ** 2
        if f < best:
            best, s_best = f, s
    if best > 0.0:
        d = np.sqrt(best)
        gx = _excess(p[0] + s_best * e[0], h[0]) / d
        gy = _excess(p[1] + s_best * e[1], h[1]) / d
        g = (gx, gy, _excess(p[2] + s_best * e[2], h[2]) / d)
    else:
        depth, s_best = _box_depth(p, e, h)
        d = -depth
        face, least = 0, np.inf
        for i in range(3):
            gap = h[i] - abs(p[i] + s_best * e[i])
            if gap < least:
                face, least = i, gap
        sign = -1.0 if p[face] + s_best * e[face] < 0.0 else 1.0
        g = (sign if face == 0 else 0.0, sign if face == 1 else 0.0, sign if face == 2 else 0.0)
    ux = r00 * g[0] + r01 * g[1] + r02 * g[2]
    uy = r10 * g[0] + r11 * g[1] + r12 * g[2]
    uz = r20 * g[0] + r21 * g[1] + r22 * g[2]
    return d, s_best, ux, uy, uz


def _box_depth(p, e, h):  # pragma: no cover - compiled
    """The largest depth ``min_i (h_i - |x_i(s)|)`` [m] of the points ``x(s) = p + s e`` in the
    box's frame (half extents ``h``), and its ``s``."""
    # the depth min_i (h_i - |x_i(s)|) is concave and piecewise linear in s; its
    # largest is at an end, where an x_i is 0, or where two of its lines meet
    depth, s_best = -np.inf, 0.0
    for k in range(17):
        if k < 2:
            s = float(k)
        elif k < 5:
            if e[k - 2] == 0.0:
                continue
            s = -p[k - 2] / e[k - 2]
        else:
            i, j = (k - 5) // 4 % 3, ((k - 5) // 4 + 1) % 3
            si, sj = 1.0 if (k - 5) % 2 else -1.0, 1.0 if (k - 5) // 2 % 2 else -1.0
            den = sj * e[j] - si * e[i]
            if den == 0.0:
                continue
            s = (h[j] - h[i] - sj * p[j] + si * p[i]) / den
        s = min(max(s, 0.0), 1.0)
        g_s = np.inf
        for i in range(3):
            g_s = min(g_s, h[i] - abs(p[i] + s * e[i]))
        if g_s > depth:
            depth, s_best = g_s, s
    return depth, s_best


@cache
def compiled_closest():
    """``closest(rows, P0, P1, t, A, dist, u)``: for each segment ``P0[k] -> P1[k]`` (s, dim)
    [m] at time ``t[k]`` [s] and each row ``j`` of ``rows``, the segment's closest point
    ``A[k, j]`` (s, m, dim) [m], the signed distance ``dist[k, j]`` [m] and ``u[k, j]``
    (:func:`compiled_segment_distance`), compiled on first call."""
    from ...native import compile_with

    return compile_with(_closest, {"_distance": compiled_segment_distance()}, name="closest_all")


def _closest(rows, P0, P1, t, A, dist, u):  # pragma: no cover - compiled
    for k in range(P0.shape[0]):
        for j in range(rows.shape[0]):
            d, s = _distance(rows[j], P0[k], P1[k], t[k], u[k, j])  # noqa: F821 - bound
            dist[k, j] = d
            for i in range(P0.shape[1]):
                A[k, j, i] = P0[k, i] + s * (P1[k, i] - P0[k, i])

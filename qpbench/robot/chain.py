"""Serial chain of n revolute joints in the plane or in space: the model (constants), the
workspace, and forward kinematics and Jacobians, in numpy (any batch of configurations) and
compiled (numba, one configuration, into arrays the caller owns).

Joint k's frame is placed in joint k-1's frame (joint 0's: in the base frame) by a fixed
rotation ``rotation[k]`` and translation ``translation[k]``, then turned by ``q[k]`` [rad] about
its unit ``axis[k]`` (in its own frame); the end effector is placed in joint n-1's frame by
``tool_rotation``, ``tool_translation``. World frames (paper eq. 1 in the plane)::

    A_k = R_{k-1} rotation[k],   R_k = A_k Rot(axis[k], q[k]),   p_k = p_{k-1} + R_{k-1} translation[k]

with ``R_{-1} = I``, ``p_{-1} = 0``; the end effector is ``p_n = p_{n-1} + R_{n-1}
tool_translation``. Link i is the segment from ``p_i`` to ``p_{i+1}`` (a capsule of
``radius[i]``); a point on it is ``(link, frac)``, ``x = p_i + frac (p_{i+1} - p_i)``. Its
Jacobian (eqs. 2, 7b) has columns ``w_k x (x - p_k)`` for k <= link (``w_k = A_k axis[k]`` the
world axis) and zero after, rows 0..dim-1: a planar chain (``dim`` 2) turns about z in the xy
plane and keeps the rows x, y.
"""

from __future__ import annotations

from functools import cache
from typing import NamedTuple

import numpy as np

from ..exceptions import InputError


class ChainModel(NamedTuple):
    """The constants of a serial chain of n revolute joints (see the module's docstring).

    ``dim`` 2 (planar: positions and Jacobians with rows x, y) or 3; ``rotation`` (n, 3, 3) and
    ``translation`` (n, 3) [m]: joint k's frame in joint k-1's (the base's for k = 0); ``axis``
    (n, 3): joint k's unit axis in its own frame; ``tool_rotation`` (3, 3), ``tool_translation``
    (3,) [m]: the end effector in joint n-1's frame; ``q_min``, ``q_max`` (n,) [rad], ``v_max``
    (n,) [rad/s]: joint limits; ``radius`` (n,) [m]: link i's capsule radius.
    """

    dim: int
    rotation: np.ndarray
    translation: np.ndarray
    axis: np.ndarray
    tool_rotation: np.ndarray
    tool_translation: np.ndarray
    q_min: np.ndarray
    q_max: np.ndarray
    v_max: np.ndarray
    radius: np.ndarray

    @property
    def n(self) -> int:
        """Number of joints."""
        return int(self.axis.shape[0])

    @property
    def lengths(self) -> np.ndarray:
        """Link lengths ``|p_{i+1} - p_i|`` [m] (n,): fixed, the translations' norms."""
        t = np.vstack([self.translation[1:], self.tool_translation[None]])
        return np.linalg.norm(t, axis=1)


class ChainData(NamedTuple):
    """The workspace of a chain's kinematics (:func:`chain_data`): world ``rotation`` (n+1, 3,
    3) of each joint frame after its turn (row n: the end effector), ``position`` (n+1, 3) [m]
    of each joint origin and the end effector, ``axis`` (n, 3) each joint's world axis."""

    rotation: np.ndarray
    position: np.ndarray
    axis: np.ndarray


def chain_data(model: ChainModel) -> ChainData:
    """A workspace for ``model`` (allocated once; the compiled functions write into it)."""
    n = model.n
    return ChainData(np.zeros((n + 1, 3, 3)), np.zeros((n + 1, 3)), np.zeros((n, 3)))


def _f64(a) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float64)


def make_model(
    rotation,
    translation,
    axis,
    tool_rotation,
    tool_translation,
    dim: int = 3,
    q_min=None,
    q_max=None,
    v_max=None,
    radius=0.0,
) -> ChainModel:
    """A checked :class:`ChainModel` in the dtypes the compiled functions take (fields as
    there); limits default to none (infinite), ``radius`` [m] is one per link or one for all;
    errors name the key ``robot``."""
    rotation, translation, axis = _f64(rotation), _f64(translation), _f64(axis)
    n = axis.shape[0] if axis.ndim == 2 else 0
    if n < 1 or rotation.shape != (n, 3, 3) or translation.shape != (n, 3) or axis.shape[1] != 3:
        raise InputError(
            f"a chain needs n >= 1 joints: rotations (n, 3, 3), offsets and axes (n, 3), got "
            f"{rotation.shape}, {translation.shape}, {axis.shape}",
            key="robot",
        )
    norms = np.linalg.norm(axis, axis=1)
    if not np.all(np.abs(norms - 1.0) < 1e-9):
        raise InputError(
            f"joint axes must be unit vectors, got norms {norms.tolist()}", key="robot"
        )
    if dim not in (2, 3):
        raise InputError(f"dim must be 2 or 3, got {dim}", key="robot")
    lim = {}
    for name, v, default in (("q_min", q_min, -np.inf), ("q_max", q_max, np.inf),
                             ("v_max", v_max, np.inf), ("radius", radius, 0.0)):  # fmt: skip
        v = np.asarray(default if v is None else v, dtype=float)
        if v.ndim > 1 or v.size not in (1, n) or np.isnan(v).any():
            raise InputError(f"needs 1 or {n} numbers, got {v.tolist()}", key=f"robot.{name}")
        lim[name] = _f64(np.broadcast_to(v, (n,)))
    if (
        np.any(lim["q_min"] >= lim["q_max"])
        or np.any(lim["v_max"] <= 0)
        or np.any(lim["radius"] < 0)
    ):
        raise InputError(
            "need q_min < q_max, v_max > 0 and radius >= 0, got "
            + ", ".join(f"{k} {v.tolist()}" for k, v in lim.items()),
            key="robot",
        )
    tool = (_f64(tool_rotation), _f64(tool_translation))
    return ChainModel(int(dim), rotation, translation, axis, *tool, **lim)


def planar_chain(lengths, **fields) -> ChainModel:
    """The planar arm of link ``lengths`` (n,) [m], n >= 2, as a chain: joints turn about z,
    joint k sits ``lengths[k-1]`` along joint k-1's x axis (joint 0 at the origin), the end
    effector ``lengths[n-1]`` along the last; ``fields``: limits and radius (:func:`make_model`)."""
    lengths = np.asarray(lengths, dtype=float)
    ok = lengths.ndim == 1 and lengths.size >= 2 and np.all(np.isfinite(lengths) & (lengths > 0))
    if not ok:
        raise InputError(
            f"a planar arm needs at least 2 finite link lengths > 0 [m], got {lengths.tolist()}",
            key="robot.link_lengths",
        )
    n = lengths.size
    translation = np.zeros((n, 3))
    translation[1:, 0] = lengths[:-1]
    axis = np.tile([0.0, 0.0, 1.0], (n, 1))
    rotation = np.tile(np.eye(3), (n, 1, 1))
    tool = np.array([lengths[-1], 0.0, 0.0])
    return make_model(rotation, translation, axis, np.eye(3), tool, 2, **fields)


def _rodrigues(axis: np.ndarray, q: np.ndarray) -> np.ndarray:
    """``Rot(axis, q)`` (..., 3, 3) about the unit ``axis`` (3,) by angles ``q`` (...) [rad]."""
    c, s = np.cos(q)[..., None, None], np.sin(q)[..., None, None]
    x, y, z = axis
    K = np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])
    return c * np.eye(3) + s * K + (1.0 - c) * np.outer(axis, axis)


def forward_kinematics_np(model: ChainModel, q) -> ChainData:
    """:class:`ChainData` at joint angles ``q`` (..., n) [rad], with leading batch axes
    (numpy; the compiled :func:`forward_kinematics` does one configuration)."""
    q = np.asarray(q, dtype=float)
    n, batch = model.n, q.shape[:-1]
    R = np.empty((*batch, n + 1, 3, 3))
    p = np.empty((*batch, n + 1, 3))
    w = np.empty((*batch, n, 3))
    R_prev, p_prev = np.broadcast_to(np.eye(3), (*batch, 3, 3)), np.zeros((*batch, 3))
    for k in range(n):
        p[..., k, :] = p_prev + R_prev @ model.translation[k]
        A = R_prev @ model.rotation[k]
        w[..., k, :] = A @ model.axis[k]
        R[..., k, :, :] = A @ _rodrigues(model.axis[k], q[..., k])
        R_prev, p_prev = R[..., k, :, :], p[..., k, :]
    p[..., n, :] = p_prev + R_prev @ model.tool_translation
    R[..., n, :, :] = R_prev @ model.tool_rotation
    return ChainData(R, p, w)


def points_jacobians_np(model: ChainModel, q, links, fracs) -> tuple[np.ndarray, np.ndarray]:
    """Positions (a, 3) [m] and Jacobians (a, dim, n) [m/rad] of the points ``(links[j],
    fracs[j])`` at one configuration ``q`` (n,) [rad] (numpy)."""
    links = np.asarray(links, dtype=np.int64)
    fracs = np.asarray(fracs, dtype=float)
    data = forward_kinematics_np(model, q)
    p = data.position
    x = p[links] + fracs[:, None] * (p[links + 1] - p[links])
    cols = np.cross(data.axis[None, :, :], x[:, None, :] - p[None, :-1, :])  # (a, n, 3)
    cols *= (np.arange(model.n)[None, :] <= links[:, None])[:, :, None]
    return x, np.ascontiguousarray(cols[:, :, : model.dim].transpose(0, 2, 1))


# --- compiled (numba): one configuration, into the caller's arrays, nothing allocated ---


def _forward_kinematics_py(model, q, data):  # pragma: no cover - compiled
    """``data`` (:class:`ChainData`) at joint angles ``q`` (n,) [rad]."""
    R, p, w = data.rotation, data.position, data.axis
    rot, tr, ax = model.rotation, model.translation, model.axis
    trot, ttr = model.tool_rotation, model.tool_translation
    n = q.shape[0]
    for k in range(n + 1):  # rows indexed in place (a view costs two reference counts)
        tail = k == n
        for i in range(3):  # R_k = R_{k-1} rot, p_k = p_{k-1} + R_{k-1} t
            if k == 0:
                p[0, i] = tr[0, i]
                for j in range(3):
                    R[0, i, j] = rot[0, i, j]
                continue
            a0, a1, a2 = R[k - 1, i, 0], R[k - 1, i, 1], R[k - 1, i, 2]
            if tail:
                p[k, i] = p[k - 1, i] + a0 * ttr[0] + a1 * ttr[1] + a2 * ttr[2]
                for j in range(3):
                    R[k, i, j] = a0 * trot[0, j] + a1 * trot[1, j] + a2 * trot[2, j]
            else:
                p[k, i] = p[k - 1, i] + a0 * tr[k, 0] + a1 * tr[k, 1] + a2 * tr[k, 2]
                for j in range(3):
                    R[k, i, j] = a0 * rot[k, 0, j] + a1 * rot[k, 1, j] + a2 * rot[k, 2, j]
        if tail:
            return
        c, s = np.cos(q[k]), np.sin(q[k])
        x, y, z = ax[k, 0], ax[k, 1], ax[k, 2]
        if x == 0.0 and y == 0.0 and z == 1.0:  # about z: R_k = A_k Rz(q)
            for i in range(3):
                a0, a1 = R[k, i, 0], R[k, i, 1]
                w[k, i] = R[k, i, 2]
                R[k, i, 0] = c * a0 + s * a1
                R[k, i, 1] = c * a1 - s * a0
            continue
        v = 1.0 - c  # Rot(axis, q) by Rodrigues' formula
        r00, r01, r02 = c + v * x * x, v * x * y - s * z, v * x * z + s * y
        r10, r11, r12 = v * x * y + s * z, c + v * y * y, v * y * z - s * x
        r20, r21, r22 = v * x * z - s * y, v * y * z + s * x, c + v * z * z
        for i in range(3):
            a0, a1, a2 = R[k, i, 0], R[k, i, 1], R[k, i, 2]
            w[k, i] = a0 * x + a1 * y + a2 * z
            R[k, i, 0] = a0 * r00 + a1 * r10 + a2 * r20
            R[k, i, 1] = a0 * r01 + a1 * r11 + a2 * r21
            R[k, i, 2] = a0 * r02 + a1 * r12 + a2 * r22


def _link_point_py(data, link, frac, x):  # pragma: no cover - compiled
    """``x`` (3,) [m]: the point ``frac`` of the way along link ``link`` (0: its joint, 1: the
    next joint or the end effector), after :func:`forward_kinematics`."""
    p = data.position
    for i in range(3):
        x[i] = p[link, i] + frac * (p[link + 1, i] - p[link, i])


def _point_jacobian_py(data, link, x, J):  # pragma: no cover - compiled
    """``J`` (dim, n) [m/rad]: the Jacobian of the world point ``x`` (3,) rigidly attached to
    link ``link``, after :func:`forward_kinematics` (``dim``: ``J``'s rows, the model's)."""
    p, w = data.position, data.axis
    spatial = J.shape[0] == 3
    for k in range(w.shape[0]):
        if k > link:
            J[0, k] = 0.0
            J[1, k] = 0.0
            if spatial:
                J[2, k] = 0.0
            continue
        dx, dy, dz = x[0] - p[k, 0], x[1] - p[k, 1], x[2] - p[k, 2]
        J[0, k] = w[k, 1] * dz - w[k, 2] * dy
        J[1, k] = w[k, 2] * dx - w[k, 0] * dz
        if spatial:
            J[2, k] = w[k, 0] * dy - w[k, 1] * dx


def _points_jacobians_py(model, q, data, links, fracs, X, J):  # pragma: no cover - compiled
    """Forward kinematics at ``q`` (n,) [rad] into ``data``, then the points ``(links[j],
    fracs[j])`` into ``X`` (a, 3) [m] and their Jacobians into ``J`` (a, dim, n) [m/rad]:
    :func:`link_point` and :func:`point_jacobian` of each, in one loop (a call per point would
    cost more than its arithmetic)."""
    _forward_kinematics_py(model, q, data)
    p, w = data.position, data.axis
    spatial = J.shape[1] == 3
    for j in range(links.shape[0]):
        L, f = links[j], fracs[j]
        for i in range(3):
            X[j, i] = p[L, i] + f * (p[L + 1, i] - p[L, i])
        for k in range(w.shape[0]):
            if k > L:
                J[j, 0, k] = 0.0
                J[j, 1, k] = 0.0
                if spatial:
                    J[j, 2, k] = 0.0
                continue
            dx, dy, dz = X[j, 0] - p[k, 0], X[j, 1] - p[k, 1], X[j, 2] - p[k, 2]
            J[j, 0, k] = w[k, 1] * dz - w[k, 2] * dy
            J[j, 1, k] = w[k, 2] * dx - w[k, 0] * dz
            if spatial:
                J[j, 2, k] = w[k, 0] * dy - w[k, 1] * dx


class CompiledChain(NamedTuple):
    """The compiled kinematics (:func:`compiled_chain`); each writes into its last argument(s)."""

    forward_kinematics: object  # (model, q, data)
    link_point: object  # (data, link, frac, x)
    point_jacobian: object  # (data, link, x, J)
    points_jacobians: object  # (model, q, data, links, fracs, X, J)
    positions: object  # (model, Q, data, P)


@cache
def compiled_chain() -> CompiledChain:
    """The compiled kinematics, compiled (or loaded from numba's cache) on first use."""
    from ..native import compile_with

    fk = compile_with(_forward_kinematics_py, name="chain_forward_kinematics", _nrt=False)
    point = compile_with(_link_point_py, name="chain_link_point")
    jac = compile_with(_point_jacobian_py, name="chain_point_jacobian")
    both = compile_with(
        _points_jacobians_py, {"_forward_kinematics_py": fk}, name="chain_points_jacobians"
    )
    many = compile_with(_positions_py, {"_forward_kinematics_py": fk}, name="chain_positions")
    return CompiledChain(fk, point, jac, both, many)


def _positions_py(model, Q, data, P):  # pragma: no cover - compiled
    """``P`` (T, n+1, 3) [m]: the joint and end-effector positions at each row of ``Q`` (T, n)
    [rad] (a run's whole log at once, for the body's clearance)."""
    for i in range(Q.shape[0]):
        _forward_kinematics_py(model, Q[i], data)
        P[i] = data.position


def positions_many(model: ChainModel, Q: np.ndarray) -> np.ndarray:
    """Joint and end-effector positions (T, n+1, 3) [m] at joint angles ``Q`` (T, n) [rad],
    compiled (:func:`forward_kinematics_np` does the same in numpy)."""
    Q = np.ascontiguousarray(Q, dtype=float)
    P = np.empty((Q.shape[0], model.n + 1, 3))
    compiled_chain().positions(model, Q, chain_data(model), P)
    return P

"""Robots as chains (:class:`~qpbench.robot.chain.ChainModel`): the planar arm, the Franka Emika
Panda and the KUKA LBR iiwa 14 R820 from their makers' published parameters (the source of
every number: docs/robots.md), and any URDF through pinocchio (``pip install
'qpbench[robots]'``), read once into the chain's tables. :func:`make_chain` makes any of them.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..exceptions import InputError, check_known_keys, did_you_mean
from .chain import ChainModel, make_model, planar_chain

#: ``robot.kind``: the robots :func:`make_chain` makes.
CHAIN_KINDS = ("planar", "panda", "iiwa14", "dh", "urdf")


def _rot_x(alpha: float) -> np.ndarray:
    c, s = np.cos(alpha), np.sin(alpha)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """URDF's ``rpy`` [rad] as a rotation: ``Rz(yaw) Ry(pitch) Rx(roll)``."""
    cy, sy, cp, sp = np.cos(yaw), np.sin(yaw), np.cos(pitch), np.sin(pitch)
    rz = np.array([[cy, -sy, 0.0], [sy, cy, 0.0], [0.0, 0.0, 1.0]])
    ry = np.array([[cp, 0.0, sp], [0.0, 1.0, 0.0], [-sp, 0.0, cp]])
    return rz @ ry @ _rot_x(roll)


def modified_dh(a, d, alpha) -> tuple[np.ndarray, np.ndarray]:
    """Placements (rotations (m, 3, 3), translations (m, 3) [m]) of Craig's modified
    Denavit-Hartenberg rows ``a_{i-1}`` [m], ``d_i`` [m], ``alpha_{i-1}`` [rad]: ``RotX(alpha)
    TransX(a) TransZ(d)``, the joint turning about its z axis (``TransZ`` commutes with it)."""
    rot = np.array([_rot_x(al) for al in alpha])
    trans = (
        np.array([[ai, 0.0, 0.0] for ai in a])
        + rot @ np.array([0.0, 0.0, 1.0]) * np.asarray(d, dtype=float)[:, None]
    )
    return rot, trans


#: Franka Emika Panda: modified DH (a [m], d [m], alpha [rad]) of joints 1-7 and the flange.
PANDA_DH = (
    (0.0, 0.0, 0.0, 0.0825, -0.0825, 0.0, 0.088, 0.0),
    (0.333, 0.0, 0.316, 0.0, 0.384, 0.0, 0.0, 0.107),
    (0.0, -np.pi / 2, np.pi / 2, np.pi / 2, -np.pi / 2, np.pi / 2, np.pi / 2, 0.0),
)
#: Panda's joint position limits [rad] and velocity limits [rad/s].
PANDA_LIMITS = dict(
    q_min=(-2.8973, -1.7628, -2.8973, -3.0718, -2.8973, -0.0175, -2.8973),
    q_max=(2.8973, 1.7628, 2.8973, -0.0698, 2.8973, 3.7525, 2.8973),
    v_max=(2.1750, 2.1750, 2.1750, 2.1750, 2.6100, 2.6100, 2.6100),
)
#: KUKA LBR iiwa 14 R820: joints 1-7 and the flange placed as in its URDF, ``xyz`` [m] and
#: ``rpy`` [rad] in the previous frame (joint 1's in the base's), every axis z.
IIWA14_XYZ = (
    (0.0, 0.0, 0.1575), (0.0, 0.0, 0.2025), (0.0, 0.2045, 0.0), (0.0, 0.0, 0.2155),
    (0.0, 0.1845, 0.0), (0.0, 0.0, 0.2155), (0.0, 0.081, 0.0), (0.0, 0.0, 0.045),
)  # fmt: skip
IIWA14_RPY = (
    (0.0, 0.0, 0.0), (np.pi / 2, 0.0, np.pi), (np.pi / 2, 0.0, np.pi), (np.pi / 2, 0.0, 0.0),
    (-np.pi / 2, np.pi, 0.0), (np.pi / 2, 0.0, 0.0), (-np.pi / 2, np.pi, 0.0), (0.0, 0.0, 0.0),
)  # fmt: skip
#: iiwa 14's joint position limits and velocity limits, in degrees and degrees per second.
IIWA14_LIMITS_DEG = dict(
    q_max=(170.0, 120.0, 170.0, 120.0, 170.0, 120.0, 175.0),
    v_max=(85.0, 85.0, 100.0, 75.0, 130.0, 135.0, 135.0),
)


def _from_placements(rot, trans, **fields) -> ChainModel:
    """A spatial chain of z-axis joints from m = n + 1 placements (the last: the tool)."""
    axis = np.tile([0.0, 0.0, 1.0], (len(rot) - 1, 1))
    return make_model(rot[:-1], trans[:-1], axis, rot[-1], trans[-1], 3, **fields)


def panda(**fields) -> ChainModel:
    """The Franka Emika Panda (7 joints, flange 0.107 m past joint 7); ``fields`` override
    the limits or set the links' ``radius`` [m] (:func:`~qpbench.robot.chain.make_model`)."""
    rot, trans = modified_dh(*PANDA_DH)
    return _from_placements(rot, trans, **{**PANDA_LIMITS, **fields})


def iiwa14(**fields) -> ChainModel:
    """The KUKA LBR iiwa 14 R820 (7 joints, flange 0.126 m past joint 6's axis); ``fields`` as
    for :func:`panda`."""
    rot = np.array([rpy_matrix(*r) for r in IIWA14_RPY])
    q_max, v_max = (np.radians(IIWA14_LIMITS_DEG[k]) for k in ("q_max", "v_max"))
    limits = dict(q_min=-q_max, q_max=q_max, v_max=v_max)
    return _from_placements(rot, np.array(IIWA14_XYZ), **{**limits, **fields})


def chain_from_urdf(path, ee_frame: str, **fields) -> ChainModel:
    """The chain of the joints from the root of the URDF at ``path`` to frame ``ee_frame`` (a
    link or joint name), read by pinocchio: each joint's placement in its parent joint's frame
    (fixed joints merged into it), its axis and its limits; the frame's placement in the last
    joint's frame as the tool. Only revolute joints with limits are taken: a prismatic,
    floating, planar or continuous joint on the way is refused. ``fields`` as for
    :func:`panda`."""
    try:
        import pinocchio as pin
    except ImportError:
        msg = "robot.kind = 'urdf' needs pinocchio: pip install 'qpbench[robots]'"
        raise InputError(msg, path=path, key="robot.kind") from None
    if not Path(path).is_file():
        raise InputError("no such URDF file", path=path, key="robot.file")
    try:
        model = pin.buildModelFromUrdf(str(path))
    except (RuntimeError, ValueError) as e:
        raise InputError(f"not a URDF pinocchio reads: {str(e).splitlines()[0]}", path=path) from e
    if not model.existFrame(ee_frame):
        hint = did_you_mean(ee_frame, [f.name for f in model.frames])
        raise InputError(f"no frame {ee_frame!r} in it; {hint}", path=path, key="robot.ee_frame")
    frame = model.frames[model.getFrameId(ee_frame)]
    joints, j = [], frame.parentJoint
    while j > 0:
        joints.append(j)
        j = model.parents[j]
    if not joints:
        raise InputError(f"no joint between the root and {ee_frame!r}", path=path)
    axes, lo, hi, vel = [], [], [], []
    for j in reversed(joints):
        jm, kind = model.joints[j], model.joints[j].shortname()
        unit = {"JointModelRX": (1, 0, 0), "JointModelRY": (0, 1, 0), "JointModelRZ": (0, 0, 1)}
        if kind in unit:
            axes.append(unit[kind])
        elif kind == "JointModelRevoluteUnaligned":
            axes.append(jm.extract().axis)
        else:
            named = (("Unbounded", "continuous (no limits)"), ("RUB", "continuous (no limits)"),
                     ("JointModelP", "prismatic"), ("FreeFlyer", "floating"))  # fmt: skip
            what = next((w for key, w in named if key in kind), kind)
            msg = f"joint {model.names[j]!r} is {what}: a chain takes revolute joints with limits"
            raise InputError(msg, path=path, key="robot.ee_frame")
        lo.append(model.lowerPositionLimit[jm.idx_q])
        hi.append(model.upperPositionLimit[jm.idx_q])
        vel.append(model.velocityLimit[jm.idx_v])
    place = [model.jointPlacements[j] for j in reversed(joints)]
    limits = dict(q_min=lo, q_max=hi, v_max=vel)
    tables = [m.rotation for m in place], [m.translation for m in place], axes
    tool = frame.placement.rotation, frame.placement.translation
    try:
        return make_model(*tables, *tool, 3, **{**limits, **fields})
    except InputError as e:  # name the file
        raise InputError(e.message, path=path, key=e.key) from None


#: The keys of ``[robot]`` that make a kind's chain (the limits aside).
OWN_KEYS = {"planar": ("link_lengths",), "dh": ("a", "d", "alpha"), "urdf": ("file", "ee_frame")}


def make_chain(kind: str, **fields) -> ChainModel:
    """The chain of ``robot.kind`` ``kind``: ``planar`` (``link_lengths`` [m]), ``panda``,
    ``iiwa14``, ``dh`` (Craig's modified Denavit-Hartenberg rows ``a`` [m], ``d`` [m],
    ``alpha`` [rad] of the n joints and the flange, every joint about its z axis), ``urdf``
    (``file``, ``ee_frame``); other ``fields``: limits ``q_min``, ``q_max`` [rad], ``v_max``
    [rad/s] and ``radius`` [m] (:func:`~qpbench.robot.chain.make_model`)."""
    own = OWN_KEYS.get(kind, ())
    check_known_keys(fields, (*own, "q_min", "q_max", "v_max", "radius"), None, "robot")
    if kind == "planar":
        if "link_lengths" not in fields:
            raise InputError("a planar arm needs link_lengths [m]", key="robot.link_lengths")
        return planar_chain(fields.pop("link_lengths"), **fields)
    if kind == "urdf":
        for key in ("file", "ee_frame"):
            if key not in fields:
                raise InputError(
                    "robot.kind = 'urdf' needs a file and an ee_frame", key=f"robot.{key}"
                )
        return chain_from_urdf(fields.pop("file"), fields.pop("ee_frame"), **fields)
    if kind == "dh":
        rows = [np.asarray(fields.pop(k, ()), dtype=float).ravel() for k in ("a", "d", "alpha")]
        if len({r.size for r in rows}) != 1 or rows[0].size < 2:
            sizes = ", ".join(str(r.size) for r in rows)
            msg = f"a, d and alpha need n + 1 values each (n joints, the flange), got {sizes}"
            raise InputError(msg, key="robot.alpha")
        return _from_placements(*modified_dh(*rows), **fields)
    if kind in ("panda", "iiwa14"):
        return panda(**fields) if kind == "panda" else iiwa14(**fields)
    raise InputError(
        f"unknown robot kind {kind!r}; {did_you_mean(kind, CHAIN_KINDS)}"
        f"(one of: {', '.join(CHAIN_KINDS)})",
        key="robot.kind",
    )

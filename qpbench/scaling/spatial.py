"""The spatial sizes of the scaling study (:class:`~.sizes.Size` with a spatial ``robot``): the
Panda, the iiwa 14 and generated chains of n joints (modified Denavit-Hartenberg rows, ``[robot]
kind = "dh"``) in the ``panda_table`` scenario's task, facing ``m`` balls that approach them.
Their tick QP has n variables, 3 equality rows and ``n m`` inequality rows (one per link and
ball). The chain, the start and the balls: docs/scaling.md, "The spatial sizes"."""

from __future__ import annotations

import functools
import math

import numpy as np

from ..exceptions import ParamError
from ..robot.body import body_clearance
from ..robot.chain import ChainModel, points_jacobians_np
from ..robot.kinematics import Arm
from ..robot.obstacles.sphere import SphereObstacle
from ..robot.presets import make_chain
from .sizes import (
    CLEARANCE,
    CLOUD_RADIUS,
    SPEED,
    Size,
    base_tables,
    size_file,
    start_target,
    task_of,
)

#: A generated chain: joint 1's height [m], the sum of the later joints' offsets [m], the flange
#: past the last joint [m] (the Panda's 0.333 and 0.107; its offsets sum to 1.39 m).
BASE_HEIGHT, REACH, TOOL_LENGTH = 0.333, 1.0, 0.107
#: A generated chain's joint limits [rad] (170 deg, the iiwa's) and velocity limits [rad/s].
JOINT_LIMIT, VELOCITY_LIMIT = math.radians(170.0), 2.175
#: The start's distance from the joint limits [rad].
LIMIT_MARGIN = 0.05
#: The balls' radius [m].
BALL_RADIUS = 0.02


def dh_rows(n: int) -> dict:
    """The generated chain of ``n`` joints as ``[robot] kind = "dh"`` rows and limits."""
    alpha = [0.0] + [math.pi / 2 if k % 2 == 0 else -math.pi / 2 for k in range(1, n)] + [0.0]
    d = [BASE_HEIGHT] + [REACH / (n - 1)] * (n - 1) + [TOOL_LENGTH]
    return dict(a=[0.0] * (n + 1), d=d, alpha=alpha, q_min=[-JOINT_LIMIT] * n,
                q_max=[JOINT_LIMIT] * n, v_max=[VELOCITY_LIMIT] * n)  # fmt: skip


def generated_chain(n: int) -> ChainModel:
    """The generated chain of ``n`` joints (docs/scaling.md)."""
    return make_chain("dh", **dh_rows(n))


def chain_of(size: Size) -> ChainModel:
    """The size's chain: a preset's, or :func:`generated_chain`."""
    return generated_chain(size.links) if size.robot == "chain" else make_chain(size.robot)


@functools.cache
def task() -> dict:
    """The scenario tables every spatial size shares: the ``panda_table`` scenario's task."""
    return task_of("panda_table")


def start_angles(chain: ChainModel, target: np.ndarray, guess: np.ndarray) -> np.ndarray:
    """Joint angles [rad] putting the end effector at ``target`` [m] (docs/scaling.md).

    Raises:
        ParamError: no such angles found within the limits.
    """
    q, n = np.array(guess, dtype=float), chain.n
    lo, hi = chain.q_min + LIMIT_MARGIN, chain.q_max - LIMIT_MARGIN
    for _ in range(1000):
        x, J = points_jacobians_np(chain, q, [n - 1], [1.0])
        e, J = target - x[0], J[0]
        if np.linalg.norm(e) < 1e-12:
            return q
        step = J.T @ np.linalg.solve(J @ J.T + 1e-4 * np.eye(3), e)
        null = np.eye(n) - np.linalg.pinv(J) @ J
        q = np.clip(q + step + 0.1 * null @ (guess - q), lo, hi)
    raise ParamError(
        f"no start within the joint limits puts a {n}-joint chain's end effector at "
        f"{target.tolist()} m",
        key="theta0",
    )


def _guess(size: Size) -> np.ndarray:
    """A bent start: the Panda's from ``panda_table``; the others' every other joint bent."""
    if size.robot == "panda":
        return np.array(base_tables("panda_table")["robot"]["theta0"], dtype=float)
    bend = 0.6 if size.robot == "iiwa14" else 0.35
    return np.array([bend if k % 2 else 0.0 for k in range(size.links)])


def place_balls(
    chain: ChainModel, theta0: np.ndarray, m: int, link_radius: float, d_safe: float, seed: int
) -> list[SphereObstacle]:
    """``m`` balls beside the chain at ``theta0`` [rad], their body clearance ``d_safe`` [m] +
    :data:`~.sizes.CLEARANCE` (docs/scaling.md), drawn from ``seed``."""
    rng = np.random.default_rng([int(seed), int(m), chain.n, 15485863])
    p = Arm(chain).joint_positions(theta0[None])[0]
    mid = p[len(p) // 2]
    chord = (p[-1] - p[0]) / np.linalg.norm(p[-1] - p[0])
    u = (mid - p[0]) - ((mid - p[0]) @ chord) * chord
    u = u / np.linalg.norm(u) if np.linalg.norm(u) > 1e-9 else np.array([0.0, 1.0, 0.0])
    spread = CLOUD_RADIUS - BALL_RADIUS
    offsets = rng.normal(size=(m, 3))
    offsets *= (spread * rng.uniform(0.0, 1.0, (m, 1)) ** (1 / 3)) / np.linalg.norm(
        offsets, axis=1, keepdims=True
    )
    if m == 1:
        offsets[:] = 0.0
    want, step = d_safe + CLEARANCE, 0.0

    def balls(step):
        return [
            SphereObstacle(f"ball{i}", mid + step * u + o, BALL_RADIUS, velocity=-SPEED * u)
            for i, o in enumerate(offsets)
        ]

    while np.nanmin(body_clearance(Arm(chain), theta0, 0.0, balls(step), link_radius).d) < want:
        step += 0.001
    return balls(step)


def scenario_file(size: Size, seed: int, duration: float) -> str:
    """The spatial size's scenario file's text (:func:`~.sizes.size_file`); ``duration`` [s]."""
    chain, raw = chain_of(size), task()
    theta0 = start_angles(chain, start_target(raw), _guess(size))
    d_safe, radius = raw["controller"]["d_safe"], raw["key_points"]["link_radius"]
    balls = place_balls(chain, theta0, size.cloud_points, radius, d_safe, seed)
    n, m = size.links, size.cloud_points
    robot = {"kind": size.robot}
    if size.robot == "chain":
        rows = dh_rows(n)
        limits = dict(theta_min="q_min", theta_max="q_max", velocity_max="v_max")
        robot = {"kind": "dh", **{k: rows[k] for k in ("a", "d", "alpha")}}
        robot.update({key: rows[name] for key, name in limits.items()})
    obstacles = [
        {"kind": "sphere", "name": b.name, "center": b.center, "radius": b.radius,
         "velocity": b.velocity}
        for b in balls
    ]  # fmt: skip
    return size_file(
        size,
        raw,
        {**robot, "theta0": theta0},
        obstacles,
        duration,
        f"a {n}-joint {size.robot} chain, {m} balls ({n * m} obstacle rows)",
        f"a {n}-joint chain ({size.robot}) in panda_table's task facing {m} balls that approach it",
    )

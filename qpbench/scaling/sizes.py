"""The sizes of the scaling study and the scenario each one is.

A size is an arm (``n`` links, ``p`` key points per link) facing one point
cloud of ``m`` points. Its tick's QP (paper eq. 11, ``paper`` formulation) has

    variables       n
    equality rows   2                     (the task J v = b0)
    inequality rows a m,  a = n p + n - 1 (one per key point and cloud point)
    bounds          n lower, n upper      (escape-velocity joint limits)

The default grid has two axes, each dimension read with the other held: ``cloud`` (the paper's
4-link layout, ``p = 1``, facing 1 to 1,000 points) and ``arm`` (4 to 64 links, ``p = 2``, facing
16 points). :func:`scenario_toml` writes a size as an ordinary scenario file.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..exceptions import ParamError
from .arms import THETA_LIMIT, VELOCITY_LIMIT, ArmSpec, GeneratedArm, generate_arm
from .obstacles import CloudSpec, place_cloud

if TYPE_CHECKING:
    from ..robot.environment import PointCloudObstacle

#: The task every size shares (the ``wall`` scenario's, the path started mid-stroke so the arm moves at once).
TASK = {
    "centre": (0.4, 0.5),
    "amplitude": (0.1, 0.1),
    "omega": (0.5, 0.5),
    "phase": (-math.pi / 2, -math.pi / 2),
    "normal": (1.0, -1.0),
    "stiffness": 5000.0,
    "damping": 50.0,
    "desired_force": 20.0,
    "kp": 5000.0,
    "kd": 50.0,
    "alpha": 8.0,
    "k": 10.0,
    "d_safe": 0.01,
    "rho": 1.0e4,
    "dt": 0.001,
}


@dataclass(frozen=True)
class Size:
    """``links`` links, ``points_per_link`` key points per link, a cloud of ``cloud_points``
    points; ``axis``: its grid axis (``cloud`` or ``arm``), for the fits."""

    links: int
    points_per_link: int
    cloud_points: int
    axis: str = "arm"

    @property
    def name(self) -> str:
        return f"n{self.links}-p{self.points_per_link}-m{self.cloud_points}"

    @property
    def key_points(self) -> int:
        return self.links * self.points_per_link + self.links - 1


def qp_shape(size: Size) -> dict:
    """``{"n", "m_eq", "m_ineq", "n_box"}`` of the size's tick QP (module docstring)."""
    return {
        "n": size.links,
        "m_eq": 2,
        "m_ineq": size.key_points * size.cloud_points,
        "n_box": 2 * size.links,
    }


#: The default grid (module docstring), smallest first.
DEFAULT_SIZES = tuple(
    [Size(4, 1, m, "cloud") for m in (1, 10, 100, 1000)]
    + [Size(n, 2, 16, "arm") for n in (4, 8, 16, 32, 64)]
)


def parse_sizes(text: str | None) -> list[Size]:
    """Sizes named in ``text``: ``default``/None, or comma-separated ``nN-pP-mM`` names (a name not
    of the default grid is on the ``arm`` axis); :class:`ParamError` for another name."""
    if text is None or text.strip() in ("", "default"):
        return list(DEFAULT_SIZES)
    known = {s.name: s for s in DEFAULT_SIZES}
    out = []
    for part in (p.strip() for p in text.split(",")):
        if not part:
            continue
        if part in known:
            out.append(known[part])
            continue
        try:
            n, p, m = part.split("-")
            if n[0] != "n" or p[0] != "p" or m[0] != "m":
                raise ValueError
            size = Size(int(n[1:]), int(p[1:]), int(m[1:]))
        except (ValueError, IndexError):
            raise ParamError(
                f"'{part}' is not a size name nN-pP-mM (e.g. n16-p2-m16)", key="--sizes"
            ) from None
        if size.links < 2 or size.points_per_link < 1 or not 1 <= size.cloud_points <= 100000:
            raise ParamError(
                f"'{part}': need N >= 2 links, P >= 1 points per link, 1 <= M <= 100000",
                key="--sizes",
            )
        out.append(size)
    if not out:
        raise ParamError("no size given", key="--sizes")
    if len({s.name for s in out}) != len(out):
        raise ParamError(f"a size is listed twice in '{text}'", key="--sizes")
    return out


def start_target() -> np.ndarray:
    """Where the end effector rests in contact at t = 0 in [m]: ``x_d(0) + (Fd / Kp) n``."""
    c, a, ph = np.array(TASK["centre"]), np.array(TASK["amplitude"]), np.array(TASK["phase"])
    normal = np.array(TASK["normal"]) / np.hypot(*TASK["normal"])
    return c + a * np.cos(ph) + TASK["desired_force"] / TASK["kp"] * normal


def generate(
    size: Size, seed: int = 0, cloud: CloudSpec | None = None
) -> tuple[GeneratedArm, PointCloudObstacle]:
    """``(GeneratedArm, PointCloudObstacle)`` of a size, deterministic in ``seed``."""
    gen = generate_arm(ArmSpec(size.links, size.points_per_link, seed), start_target())
    spec = cloud or CloudSpec(size.cloud_points, seed=seed)
    return gen, place_cloud(gen, spec, TASK["d_safe"])


def _vec(values) -> str:
    return "[" + ", ".join(repr(float(v)) for v in values) + "]"


def scenario_toml(size: Size, gen: GeneratedArm, cloud: PointCloudObstacle, duration: float) -> str:
    """The size as a scenario file's text (:mod:`qpbench.sim.scenario` layout)."""
    n = size.links
    t = TASK
    points = ",\n  ".join(_vec(p) for p in cloud.points)
    return f"""# Scaling study size {size.name}: a generated {n}-link arm ({size.points_per_link} key points per link
# and the joints: {size.key_points} key points) facing a cloud of {size.cloud_points} points that approaches it.
# Written by qpbench scaling; every parameter of the simulation is here; units in the comments.

[scenario]
name = "{size.name}"
description = "Scaling study: {n} links, {size.key_points} key points, \
a cloud of {size.cloud_points} points ({size.key_points * size.cloud_points} obstacle rows)."
paper_section = "scaling (beyond the paper)"

[robot]
link_lengths = {_vec(gen.arm.lengths)}  # m, sum 1.0
theta0 = {_vec(gen.theta0)}  # rad, end effector at rest in contact
theta_min = {_vec([-THETA_LIMIT] * n)}  # rad
theta_max = {_vec([THETA_LIMIT] * n)}  # rad
velocity_min = {_vec([-VELOCITY_LIMIT] * n)}  # rad/s
velocity_max = {_vec([VELOCITY_LIMIT] * n)}  # rad/s

[key_points]
points_per_link = {size.points_per_link}
include_joints = true
link_radius = 0.0          # m

[path]
kind = "cosine"
centre = {_vec(t["centre"])}        # m
amplitude = {_vec(t["amplitude"])}  # m
omega = {_vec(t["omega"])}          # rad/s
phase = {_vec(t["phase"])}          # rad

[contact]
point = {_vec(t["centre"])}         # m
normal = {_vec(t["normal"])}
stiffness = {t["stiffness"]!r}      # N/m
damping = {t["damping"]!r}          # N s/m
force_noise_std = 0.0      # N
noise_seed = 0

[controller]
desired_force = {t["desired_force"]!r}  # N
kp = {t["kp"]!r}           # N/m
kd = {t["kd"]!r}           # N s/m
alpha = {t["alpha"]!r}     # 1/s
k = {t["k"]!r}             # 1/s
d_safe = {t["d_safe"]!r}   # m
rho = {t["rho"]!r}

[adaptive]
enabled = false
gain = [500.0, 20.0]
kp_min = 100.0
kd_min = 1.0

[simulation]
dt = {t["dt"]!r}           # s
duration = {float(duration)!r}  # s

[verdict]
settle_time = 2.0
max_tracking_error = 0.001
max_force_error = 2.0
safety_margin = 0.0005

[rnn]
eps = 0.02

[[obstacles]]
kind = "points"
name = "cloud"
velocity = {_vec(cloud.velocity)}  # m/s, towards the arm
points = [
  {points},
]
"""

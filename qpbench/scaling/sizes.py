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

import copy
import functools
import math
import re
import tomllib
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from ..exceptions import ParamError
from ..sweep.toml_text import dumps
from .scene import THETA_LIMIT, VELOCITY_LIMIT, GeneratedArm, generate_arm, place_cloud

if TYPE_CHECKING:
    from ..robot.environment import PointCloudObstacle


@functools.cache
def task() -> dict:
    """The scenario tables every size shares: the ``wall`` scenario's but its ``[scenario]``,
    ``[robot]`` and obstacles, the path started mid-stroke (phase -pi/2) so the arm moves at once."""
    from ..sim.scenario import scenario_path

    raw = tomllib.loads(scenario_path("wall").read_text(encoding="utf-8"))
    del raw["scenario"], raw["robot"], raw["obstacles"]
    raw["path"]["phase"] = [-math.pi / 2, -math.pi / 2]
    return raw


@dataclass(frozen=True)
class Size:
    """``links`` n >= 2 links, ``points_per_link`` p >= 1 key points per link besides the joints,
    a cloud of ``cloud_points`` points (1 to 100,000); ``axis``: its grid axis (``cloud`` or
    ``arm``), for the fits."""

    links: int
    points_per_link: int
    cloud_points: int
    axis: str = "arm"

    def __post_init__(self):
        if self.links < 2 or self.points_per_link < 1 or not 1 <= self.cloud_points <= 100000:
            raise ParamError(
                f"'{self.name}': need N >= 2 links, P >= 1 points per link, 1 <= M <= 100000",
                key="--sizes",
            )

    @property
    def name(self) -> str:
        return f"n{self.links}-p{self.points_per_link}-m{self.cloud_points}"

    @property
    def key_points(self) -> int:
        """``a = n p + (n - 1)``: p points per link and the joints J2..Jn."""
        return self.links * self.points_per_link + self.links - 1


def qp_shape(size: Size) -> dict:
    """``{"n", "m_eq", "m_ineq"}`` of the size's tick QP (module docstring)."""
    return {
        "n": size.links,
        "m_eq": 2,
        "m_ineq": size.key_points * size.cloud_points,
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
    for part in filter(None, (p.strip() for p in text.split(","))):
        match = re.fullmatch(r"n(\d+)-p(\d+)-m(\d+)", part)
        if part not in known and match is None:
            raise ParamError(
                f"'{part}' is not a size name nN-pP-mM (e.g. n16-p2-m16)", key="--sizes"
            )
        out.append(known.get(part) or Size(*map(int, match.groups())))
    if not out:
        raise ParamError("no size given", key="--sizes")
    if len({s.name for s in out}) != len(out):
        raise ParamError(f"a size is listed twice in '{text}'", key="--sizes")
    return out


def start_target() -> np.ndarray:
    """Where the end effector rests in contact at t = 0 in [m]: ``x_d(0) + (Fd / Kp) n``."""
    path, contact, control = task()["path"], task()["contact"], task()["controller"]
    x_d = np.array(path["centre"]) + np.array(path["amplitude"]) * np.cos(path["phase"])
    normal = np.array(contact["normal"]) / np.hypot(*contact["normal"])
    return x_d + control["desired_force"] / control["kp"] * normal


def generate(size: Size, seed: int = 0) -> tuple[GeneratedArm, PointCloudObstacle]:
    """``(GeneratedArm, PointCloudObstacle)`` of a size, deterministic in ``seed``."""
    gen = generate_arm(size.links, size.points_per_link, start_target(), seed)
    return gen, place_cloud(gen, size.cloud_points, task()["controller"]["d_safe"], seed)


def scenario_toml(size: Size, gen: GeneratedArm, cloud: PointCloudObstacle, duration: float) -> str:
    """The size as a scenario file's text (:mod:`qpbench.sim.scenario` layout), ``duration`` [s]."""
    n, a, m = size.links, size.key_points, size.cloud_points
    raw = copy.deepcopy(task())
    raw["scenario"] = {
        "name": size.name,
        "description": f"Scaling study: {n} links, {a} key points, a cloud of {m} points "
        f"({a * m} obstacle rows).",
        "paper_section": "scaling (beyond the paper)",
    }
    raw["robot"] = {
        "link_lengths": gen.arm.lengths,
        "theta0": gen.theta0,
        "theta_min": [-THETA_LIMIT] * n,
        "theta_max": [THETA_LIMIT] * n,
        "velocity_min": [-VELOCITY_LIMIT] * n,
        "velocity_max": [VELOCITY_LIMIT] * n,
    }
    raw["key_points"]["points_per_link"] = size.points_per_link
    raw["simulation"]["duration"] = float(duration)
    points = {"kind": "points", "name": "cloud", "velocity": cloud.velocity, "points": cloud.points}
    raw["obstacles"] = [points]
    header = (
        f"Scaling study size {size.name}: a generated {n}-link arm ({size.points_per_link} key "
        f"points per link and the joints: {a} key points)\nfacing a cloud of {m} points that "
        "approaches it. Written by qpbench scaling; units as in the scenario schema."
    )
    return dumps(raw, header=header)

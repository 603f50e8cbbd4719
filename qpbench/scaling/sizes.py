"""The sizes of the scaling study and the scene and scenario each one is.

A planar size is an arm (``n`` links, ``p`` key points per link) facing one point cloud of ``m``
points. Its tick's QP (paper eq. 11, ``paper`` formulation) has

    variables       n
    equality rows   2                     (the task J v = b0)
    inequality rows a m,  a = n p + n - 1 (one per key point and cloud point)
    bounds          n lower, n upper      (escape-velocity joint limits)

The default grid's axes, each dimension read with the others held: ``cloud`` (the paper's
4-link layout, ``p = 1``, facing 1 to 1,000 points), ``arm`` (4 to 64 links, ``p = 2``, facing
16 points) and ``spatial`` (:mod:`.spatial`). :func:`scenario_toml` writes a size as an
ordinary scenario file.

The scene: a generated arm in contact and a point cloud approaching it. Link lengths sum to
:data:`REACH`: ``l_i = REACH w_i / sum(w)``, ``w_i`` uniform in [0.5, 1.5]. Key points: the
paper's rule generalised (``p`` per link and the joints J2..Jn; ``p = 1``, ``n = 4``: A1..A7).
The start puts the end effector at rest in contact (paper eq. 4: ``x_d(0) + (Fd / Kp) n``), so
the first QPs are feasible: a bent arc of equal relative angles ``c`` (bisection on the reach,
``|c| <= 2 pi / n`` keeps the joints within +-3 rad for n >= 4), turned onto the target by the
first joint.

As in the paper (section 2.2, obstacles as key points ``B_j``; eqs. 8-10) every (key point, cloud
point) pair is one velocity-damper row, every tick: ``a m`` rows, a fixed count, as a persistent
solver needs. The cloud fills a disk of :data:`CLOUD_RADIUS` on the outer side of the arm at its
middle key point, ``d_safe`` + :data:`CLEARANCE` away, and approaches it: its rows start inactive and
become active within the first tenths of a second, so the dumped ticks hold both.
"""

from __future__ import annotations

import copy
import functools
import math
import re
import tomllib
from dataclasses import dataclass

import numpy as np

from ..exceptions import ParamError
from ..robot.kinematics import KeyPoints, PlanarArm, default_key_points
from ..robot.obstacles.points import PointCloudObstacle
from ..sweep.toml_text import dumps

#: Sum of the link lengths of every generated arm in [m] (the paper arm's reach).
REACH = 1.0
#: Joint-angle limits in [rad] (the paper's, for every joint).
THETA_LIMIT = 3.0
#: Joint-velocity limits in [rad/s] (the paper's, for every joint).
VELOCITY_LIMIT = 1.0


@dataclass
class GeneratedArm:
    """An arm (lengths [m]), its key points, a start ``theta0`` [rad] in contact at ``target`` [m]."""

    arm: PlanarArm
    key_points: KeyPoints
    theta0: np.ndarray
    target: np.ndarray

    def key_point_positions(self) -> np.ndarray:
        """Key-point positions in [m] at ``theta0``, shape (a, 2)."""
        return self.arm.points(self.theta0, self.key_points.links, self.key_points.fracs)


def _reach_at(lengths: np.ndarray, c: float) -> float:
    arm = PlanarArm(lengths)
    theta = np.full(lengths.size, c)
    theta[0] = 0.0
    return float(np.hypot(*arm.end_effector(theta)))


def bent_arm_angles(lengths: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Joint angles [rad] of the bent arc reaching ``target`` [m] exactly (module docstring).

    Raises:
        ParamError: ``target`` is out of reach (farther than the arm's length
            or nearer than the tightest arc with ``|c| <= 2 pi / n``).
    """
    n = lengths.size
    dist = float(np.hypot(*target))
    lo, hi = 0.0, 2.0 * math.pi / n * 0.95
    if not _reach_at(lengths, hi) < dist < _reach_at(lengths, lo):
        raise ParamError(
            f"target {target.tolist()} m is out of reach of a bent {n}-link arm", key="target"
        )
    for _ in range(100):  # the reach falls monotonically as the arc bends on [0, 2 pi / n)
        mid = 0.5 * (lo + hi)
        if _reach_at(lengths, mid) > dist:
            lo = mid
        else:
            hi = mid
    theta = np.full(n, 0.5 * (lo + hi))
    theta[0] = 0.0
    ee = PlanarArm(lengths).end_effector(theta)
    theta[0] = math.atan2(target[1], target[0]) - math.atan2(ee[1], ee[0])
    theta[0] = math.remainder(theta[0], 2.0 * math.pi)
    return theta


def generate_arm(
    links: int, points_per_link: int, target: np.ndarray, seed: int = 0
) -> GeneratedArm:
    """The arm of ``links`` links with ``points_per_link`` key points per link besides the joints
    J2..Jn, lengths drawn from ``seed``, its end effector at ``target`` [m] (module docstring)."""
    w = np.random.default_rng([int(seed), int(links), 7919]).uniform(0.5, 1.5, size=int(links))
    lengths = REACH * w / w.sum()
    arm = PlanarArm(lengths)
    theta0 = bent_arm_angles(lengths, target)
    if np.any(np.abs(theta0) > THETA_LIMIT):
        raise ParamError(
            f"start angles {theta0.tolist()} leave the joint limits +-{THETA_LIMIT} rad",
            key="theta0",
        )
    key_points = default_key_points(links, points_per_link, include_joints=True)
    return GeneratedArm(arm, key_points, theta0, arm.end_effector(theta0))


#: Radius of the disk the cloud's points fill [m].
CLOUD_RADIUS = 0.03
#: The cloud's clearance beyond ``d_safe`` at the start [m] and its speed towards the arm [m/s].
CLEARANCE = 0.015
SPEED = 0.1


def cloud_points(m: int, seed: int = 0) -> np.ndarray:
    """``m`` points uniform over a disk of :data:`CLOUD_RADIUS` [m] centred at 0, shape (m, 2);
    one point: the centre."""
    if m == 1:
        return np.zeros((1, 2))
    rng = np.random.default_rng([int(seed), int(m), 104729])
    r = CLOUD_RADIUS * np.sqrt(rng.uniform(0.0, 1.0, m))
    a = rng.uniform(0.0, 2.0 * math.pi, m)
    return np.stack([r * np.cos(a), r * np.sin(a)], axis=1)


def min_key_point_distance(key_xy: np.ndarray, points: np.ndarray) -> float:
    """Smallest distance in [m] between key points (a, 2) and cloud points (m, 2)."""
    from scipy.spatial.distance import cdist

    return float(cdist(key_xy, points).min())


def _clear_offset(
    xy: np.ndarray, anchor: np.ndarray, u: np.ndarray, pts: np.ndarray, want: float
) -> float:
    """Smallest offset along ``u`` (1 mm steps from the one that puts the cloud's point nearest
    the arm ``want`` away from ``anchor``) at which the arm clears the cloud by ``want``."""
    offset = want + float(np.max(-(pts @ u)))
    while min_key_point_distance(xy, anchor + offset * u + pts) < want:
        offset += 0.001
    return offset


def place_cloud(gen: GeneratedArm, points: int, d_safe: float, seed: int = 0) -> PointCloudObstacle:
    """A cloud of ``points`` points (drawn from ``seed``) beside ``gen`` at ``theta0``, every key
    point ``d_safe`` [m] + :data:`CLEARANCE` from it: stepped outwards by 1 mm along the middle key
    point's outer (or inner) normal until the arm clears it, the side needing the smaller step; it
    moves towards the arm at :data:`SPEED`."""
    xy = gen.key_point_positions()
    i = len(gen.key_points) // 2
    phi = float(np.cumsum(gen.theta0)[int(gen.key_points.links[i])])
    u = np.array([-math.sin(phi), math.cos(phi)])  # the normal of key point i's link
    chord = gen.target / np.linalg.norm(gen.target)
    off = xy[i] - (xy[i] @ chord) * chord  # the key point's offset from the chord
    u = u if u @ off >= 0 else -u  # outer: away from the chord base -> end effector
    pts = cloud_points(points, seed)
    want = d_safe + CLEARANCE
    offset, side = min(
        (_clear_offset(xy, xy[i], s * u, pts, want), k) for k, s in enumerate((1.0, -1.0))
    )
    u = u if side == 0 else -u
    return PointCloudObstacle("cloud", xy[i] + offset * u + pts, velocity=-SPEED * u)


@functools.cache
def base_tables(name: str) -> dict:
    """Shipped scenario ``name``'s tables as its file holds them (every size's task)."""
    from ..sim.scenario import scenario_path

    return tomllib.loads(scenario_path(name).read_text(encoding="utf-8"))


def task_of(name: str) -> dict:
    """Shipped scenario ``name``'s tables but its ``[scenario]``, ``[robot]`` and obstacles."""
    raw = copy.deepcopy(base_tables(name))
    del raw["scenario"], raw["robot"], raw["obstacles"]
    return raw


@functools.cache
def task() -> dict:
    """The scenario tables every planar size shares: the ``wall`` scenario's task, the path
    started mid-stroke (phase -pi/2) so the arm moves at once."""
    raw = task_of("wall")
    raw["path"]["phase"] = [-math.pi / 2, -math.pi / 2]
    return raw


#: Robots of the ``spatial`` axis: the two presets and generated chains (:mod:`.spatial`).
SPATIAL_ROBOTS = ("panda", "iiwa14", "chain")


@dataclass(frozen=True)
class Size:
    """``links`` n >= 2 links, ``points_per_link`` p >= 1 key points per link besides the joints,
    a cloud of ``cloud_points`` points (1 to 100,000); ``axis``: its grid axis (``cloud``,
    ``arm`` or ``spatial``), for the fits; ``robot``: ``planar`` (a generated planar arm) or one
    of :data:`SPATIAL_ROBOTS` (n joints, ``cloud_points`` balls, :mod:`.spatial`)."""

    links: int
    points_per_link: int
    cloud_points: int
    axis: str = "arm"
    robot: str = "planar"

    def __post_init__(self):
        if self.links < 2 or self.points_per_link < 1 or not 1 <= self.cloud_points <= 100000:
            raise ParamError(
                f"'{self.name}': need N >= 2 links, P >= 1 points per link, 1 <= M <= 100000",
                key="--sizes",
            )
        if self.robot in ("panda", "iiwa14") and self.links != 7:
            raise ParamError(f"'{self.name}': the {self.robot} has 7 joints", key="--sizes")

    @property
    def spatial(self) -> bool:
        return self.robot != "planar"

    @property
    def name(self) -> str:
        if self.robot == "chain":
            return f"chain{self.links}-m{self.cloud_points}"
        if self.spatial:
            return f"{self.robot}-m{self.cloud_points}"
        return f"n{self.links}-p{self.points_per_link}-m{self.cloud_points}"

    @property
    def key_points(self) -> int:
        """``a = n p + (n - 1)``: p points per link and the joints J2..Jn; spatial: one guarded
        element per link (its point closest to each ball)."""
        if self.spatial:
            return self.links
        return self.links * self.points_per_link + self.links - 1


def qp_shape(size: Size) -> dict:
    """``{"n", "m_eq", "m_ineq"}`` of the size's tick QP (module docstring)."""
    m_eq = 3 if size.spatial else 2
    return {"n": size.links, "m_eq": m_eq, "m_ineq": size.key_points * size.cloud_points}


#: The default grid (module docstring), smallest first.
DEFAULT_SIZES = tuple(
    [Size(4, 1, m, "cloud") for m in (1, 10, 100, 1000)]
    + [Size(n, 2, 16, "arm") for n in (4, 8, 16, 32, 64)]
    + [Size(7, 1, 4, "spatial", robot) for robot in ("panda", "iiwa14")]
    + [Size(n, 1, 4, "spatial", "chain") for n in (14, 28)]
)

_SPATIAL_NAME = re.compile(r"(panda|iiwa14|chain(\d+))-m(\d+)")


def _named(part: str) -> Size | None:
    """The size a name not of the default grid stands for (None: not a size name)."""
    if match := re.fullmatch(r"n(\d+)-p(\d+)-m(\d+)", part):
        return Size(*map(int, match.groups()))
    if match := _SPATIAL_NAME.fullmatch(part):
        robot, links, m = match.groups()
        if robot.startswith("chain"):
            return Size(int(links), 1, int(m), "spatial", "chain")
        return Size(7, 1, int(m), "spatial", robot)
    return None


def parse_sizes(text: str | None) -> list[Size]:
    """Sizes named in ``text``: ``default``/None, or comma-separated names, ``nN-pP-mM`` (planar;
    a name not of the default grid is on the ``arm`` axis), ``panda-mM``, ``iiwa14-mM`` or
    ``chainN-mM`` (spatial); :class:`ParamError` for another name."""
    if text is None or text.strip() in ("", "default"):
        return list(DEFAULT_SIZES)
    known = {s.name: s for s in DEFAULT_SIZES}
    out = []
    for part in filter(None, (p.strip() for p in text.split(","))):
        size = known.get(part) or _named(part)
        if size is None:
            raise ParamError(
                f"'{part}' is not a size name nN-pP-mM, panda-mM, iiwa14-mM or chainN-mM "
                "(e.g. n16-p2-m16, chain14-m4)",
                key="--sizes",
            )
        out.append(size)
    if not out:
        raise ParamError("no size given", key="--sizes")
    if len({s.name for s in out}) != len(out):
        raise ParamError(f"a size is listed twice in '{text}'", key="--sizes")
    return out


def start_target(tables: dict | None = None) -> np.ndarray:
    """Where the end effector rests in contact at t = 0 in [m]: ``x_d(0) + (Fd / Kp) n``, in the
    task ``tables`` (default: :func:`task`)."""
    tables = tables or task()
    path, contact, control = tables["path"], tables["contact"], tables["controller"]
    x_d = np.array(path["centre"]) + np.array(path["amplitude"]) * np.cos(path["phase"])
    normal = np.array(contact["normal"]) / np.linalg.norm(contact["normal"])
    return x_d + control["desired_force"] / control["kp"] * normal


def generate(size: Size, seed: int = 0) -> tuple[GeneratedArm, PointCloudObstacle]:
    """``(GeneratedArm, PointCloudObstacle)`` of a size, deterministic in ``seed``."""
    gen = generate_arm(size.links, size.points_per_link, start_target(), seed)
    return gen, place_cloud(gen, size.cloud_points, task()["controller"]["d_safe"], seed)


def size_file(
    size: Size, tables: dict, robot: dict, obstacles: list, duration: float, what: str, header: str
) -> str:
    """The text of the size's scenario file (:mod:`qpbench.sim.scenario` layout): the task
    ``tables`` with the size's ``[scenario]`` (``what``: its description), ``[robot]`` (``robot``)
    and ``obstacles``, runs of ``duration`` [s]; ``header``: the size in words, its first lines."""
    raw = copy.deepcopy(tables)
    raw["scenario"] = {
        "name": size.name,
        "description": f"Scaling study: {what}.",
        "paper_section": "scaling (beyond the paper)",
    }
    raw["robot"] = robot
    raw["simulation"]["duration"] = float(duration)
    raw["obstacles"] = obstacles
    written = "Written by qpbench scaling; units as in the scenario schema."
    return dumps(raw, header=f"Scaling study size {size.name}: {header}.\n{written}")


def scenario_toml(size: Size, gen: GeneratedArm, cloud: PointCloudObstacle, duration: float) -> str:
    """The planar size's scenario file's text (:func:`size_file`)."""
    n, a, m = size.links, size.key_points, size.cloud_points
    robot = {
        "link_lengths": gen.arm.lengths,
        "theta0": gen.theta0,
        "theta_min": [-THETA_LIMIT] * n,
        "theta_max": [THETA_LIMIT] * n,
        "velocity_min": [-VELOCITY_LIMIT] * n,
        "velocity_max": [VELOCITY_LIMIT] * n,
    }
    tables = copy.deepcopy(task())
    tables["key_points"]["points_per_link"] = size.points_per_link
    points = {"kind": "points", "name": "cloud", "velocity": cloud.velocity, "points": cloud.points}
    return size_file(
        size,
        tables,
        robot,
        [points],
        duration,
        f"{n} links, {a} key points, a cloud of {m} points ({a * m} obstacle rows)",
        f"a generated {n}-link arm ({size.points_per_link} key points per link and the joints: "
        f"{a} key points)\nfacing a cloud of {m} points that approaches it",
    )

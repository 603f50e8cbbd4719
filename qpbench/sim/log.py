"""The closed loop's tick log: its columns, by name, in one place (what each holds:
docs/methodology.md, "The tick log")."""

from __future__ import annotations

import re

import numpy as np
import pandas as pd

from ..statuses import TICK_STATUSES

T = "t"
EE_X, EE_Y, EE_Z = "ee_x", "ee_y", "ee_z"
XD_X, XD_Y, XD_Z = "xd_x", "xd_y", "xd_z"
TRACKING_ERROR = "tracking_error"
FORCE = "force"
FORCE_ERROR = "force_error"
D_MIN = "d_min"
V_SQ = "v_sq"
TASK_RESIDUAL = "task_residual"
STATUS = "status"
FALLBACK = "fallback"
ZERO_VELOCITY = "zero_velocity"
SOLVE_TIME = "solve_time_s"
SOLVER_TIME = "solver_time_s"
BUILD_TIME = "build_time_s"
FALLBACK_BUILD_TIME = "fallback_build_time_s"
FALLBACK_SOLVE_TIME = "fallback_solve_time_s"
TICK_TIME = "tick_time_s"
#: Columns that depend on the machine's timing, not on the trajectory.
TIME_COLUMNS = (
    SOLVE_TIME,
    SOLVER_TIME,
    BUILD_TIME,
    FALLBACK_BUILD_TIME,
    FALLBACK_SOLVE_TIME,
    TICK_TIME,
)
Y_0, Y_1, Y_2 = "y_0", "y_1", "y_2"
Z_MAX = "z_max"
KP_HAT, KD_HAT = "kp_hat", "kd_hat"
D_BODY_MIN, D_BODY_LINK, D_BODY_OBSTACLE = "d_body_min", "d_body_link", "d_body_obstacle"

#: Columns after the distances, in the order the tick kernel writes them
#: (``status`` is inserted before ``fallback`` when the log becomes a frame).
_TAIL = (
    D_MIN,
    V_SQ,
    TASK_RESIDUAL,
    FALLBACK,
    ZERO_VELOCITY,
    SOLVE_TIME,
    Y_0,
    Y_1,
    Z_MAX,
    KP_HAT,
    KD_HAT,
    *TIME_COLUMNS[1:],  # written by the engines, not by the tick kernel
)
_MIDDLE = (EE_X, EE_Y, XD_X, XD_Y, TRACKING_ERROR, FORCE, FORCE_ERROR)


def theta_columns(n: int) -> list[str]:
    """``theta_0 .. theta_{n-1}``: joint angles [rad]."""
    return [f"theta_{i}" for i in range(n)]


def velocity_columns(n: int) -> list[str]:
    """``v_0 .. v_{n-1}``: commanded joint velocities [rad/s]."""
    return [f"v_{i}" for i in range(n)]


def distance_column(key_point: str, obstacle: str) -> str:
    """``d_<key point>_<obstacle>``: the key point's distance to the obstacle [m]."""
    return f"d_{key_point}_{obstacle}"


def joint_count(frame: pd.DataFrame) -> int:
    """Joints of the arm a tick log is of (its ``v_i`` columns)."""
    return sum(1 for c in frame.columns if re.fullmatch(r"v_\d+", str(c)))


def distance_columns(frame: pd.DataFrame) -> list[str]:
    """The ``d_<A>_<obstacle>`` columns of a tick log, in its order."""
    body = (D_MIN, D_BODY_MIN, D_BODY_LINK, D_BODY_OBSTACLE)
    return [c for c in frame.columns if str(c).startswith("d_") and c not in body]


def float_columns(n: int, obstacle_columns: list[tuple[str, str]], dim: int = 2) -> list[str]:
    """The float block the tick kernel fills, in order (every column but ``status``), for ``n``
    joints, the ``(key point, obstacle)`` of each distance column and a task of ``dim`` axes
    (3: ``ee_z``, ``xd_z``, ``y_2`` too)."""
    middle, tail = list(_MIDDLE), list(_TAIL)
    if dim == 3:
        middle[:4] = [EE_X, EE_Y, EE_Z, XD_X, XD_Y, XD_Z]
        tail.insert(tail.index(Y_1) + 1, Y_2)
    distances = [distance_column(a, o) for a, o in obstacle_columns]
    return [T, *theta_columns(n), *velocity_columns(n), *middle, *distances, *tail]


def to_frame(data: np.ndarray, columns: list[str], status_codes: np.ndarray) -> pd.DataFrame:
    """The first ``len(status_codes)`` rows of ``data`` as a frame, ``status`` a categorical of
    :data:`~qpbench.statuses.TICK_STATUSES` from its codes (indices into it)."""
    done = len(status_codes)
    frame = pd.DataFrame(data[:done], columns=columns)
    for flag in (FALLBACK, ZERO_VELOCITY):
        frame[flag] = frame[flag].astype(bool)
    codes = np.asarray(status_codes, dtype=np.int8)
    status = pd.Categorical.from_codes(codes, categories=list(TICK_STATUSES))
    frame.insert(columns.index(FALLBACK), STATUS, status)
    return frame


#: A tick status's code in a log (:func:`to_frame`); another status counts as ``error``.
STATUS_CODES = {s: i for i, s in enumerate(TICK_STATUSES)}


def add_body_columns(frame: pd.DataFrame, body, obstacle_names: list[str]) -> None:
    """Insert the ticks' :class:`qpbench.robot.body.BodyClearance` after ``d_min``."""
    at = list(frame.columns).index(D_MIN) + 1
    names = np.array(list(obstacle_names) + [""], dtype=object)
    frame.insert(at, D_BODY_MIN, body.d_min)
    frame.insert(at + 1, D_BODY_LINK, body.link.astype(np.int64))
    obstacle = pd.Categorical(names[body.obstacle], categories=list(dict.fromkeys(names)))
    frame.insert(at + 2, D_BODY_OBSTACLE, obstacle)

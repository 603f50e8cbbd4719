"""Pictures of the arm in its workspace, as the paper's figures show it first.

:func:`draw_snapshot` draws a closed-loop run on one figure: the arm at several
instants (stick figures, fading from pale at the start to solid at the end),
its key points, the obstacles at the last drawn instant (lines, segments,
disks, point clouds; moving ones also as a faint trace of where they started),
the contact surface, the desired and the actual end-effector paths, and the
closest approach of a key point to an obstacle, marked and labelled.

:func:`animate` renders the same scene frame by frame to a GIF (Pillow, which
matplotlib requires) or an MP4 (when ``ffmpeg`` is on the PATH).

Both read only the tick log of :func:`qpbench.sim.loop.simulate` (columns
``t``, ``theta_i``, ``ee_x``, ``ee_y``, ``xd_x``, ``xd_y``, ``d_<A>_<obstacle>``)
and the scenario; lengths are in metres, drawn with equal axes.
"""

from __future__ import annotations

import math
import shutil
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from . import style

if TYPE_CHECKING:
    import pandas as pd

    from ..sim.scenario import Scenario

__all__ = ["animate", "closest_approach", "draw_snapshot"]

#: Colour of the arm (links and joints), of the key points, of obstacles and of the surface.
ARM, KEY, OBSTACLE, SURFACE = "#1f3b73", "#d9480f", "#5c5f66", "#2b8a3e"
#: Colour of the actual end-effector path when no backend is named.
PATH = "#e8590c"


def _thetas(log, n: int) -> np.ndarray:
    return log[[f"theta_{i}" for i in range(n)]].to_numpy(dtype=float)


def closest_approach(log: pd.DataFrame, scenario: Scenario) -> dict | None:
    """Where and when a key point came closest to an obstacle.

    Returns ``{"t", "k", "key_point", "obstacle", "distance"}`` (distance in
    [m] from the link's surface, ``k`` the tick index), or ``None`` when the
    scenario has no obstacle.
    """
    from ..sim.log import distance_columns

    cols = distance_columns(log)
    if not cols:
        return None
    D = log[cols].to_numpy(dtype=float)
    if not np.isfinite(D).any():
        return None
    flat = int(np.nanargmin(D))
    k, c = divmod(flat, D.shape[1])
    _, key, obstacle = cols[c].split("_", 2)
    return {
        "t": float(log["t"].iloc[k]),
        "k": int(k),
        "key_point": key,
        "obstacle": obstacle,
        "distance": float(D[k, c]),
    }


def _instants(t: np.ndarray, count: int) -> np.ndarray:
    """Ticks nearest to ``count`` times evenly spaced over ``t`` (a decimated log's ticks are not evenly spaced)."""
    if len(t) < 2:
        return np.zeros(len(t), dtype=int)
    count = max(2, min(int(count), len(t)))
    wanted = np.linspace(t[0], t[-1], count)
    k = np.clip(np.searchsorted(t, wanted), 1, len(t) - 1)
    k -= (wanted - t[k - 1]) < (t[k] - wanted)
    return np.unique(k)


def _view(scenario, log, arm) -> tuple[tuple[float, float], tuple[float, float]]:
    """Axis limits holding the arm's reach around the base and the paths, with a margin [m]."""
    reach = float(np.sum(arm.lengths))
    xs = np.r_[log["ee_x"].to_numpy(float), log["xd_x"].to_numpy(float), 0.0]
    ys = np.r_[log["ee_y"].to_numpy(float), log["xd_y"].to_numpy(float), 0.0]
    xs, ys = xs[np.isfinite(xs)], ys[np.isfinite(ys)]
    lo = np.array([min(xs.min(), -0.25 * reach), min(ys.min(), -0.6 * reach)])
    hi = np.array([max(xs.max(), 0.6 * reach), max(ys.max(), 0.6 * reach)])
    pad = 0.08 * float(np.max(hi - lo))
    return (lo[0] - pad, hi[0] + pad), (lo[1] - pad, hi[1] + pad)


def _draw_line(ax, point, normal, xlim, ylim, **line) -> None:
    """The line through ``point`` perpendicular to ``normal``, clipped to the view; hatched on the far side."""
    tangent = np.array([-normal[1], normal[0]])
    span = 4.0 * max(xlim[1] - xlim[0], ylim[1] - ylim[0])
    a, b = point - span * tangent, point + span * tangent
    ax.plot([a[0], b[0]], [a[1], b[1]], **line)
    # the solid side (opposite the normal), lightly filled
    depth = 0.04 * span
    poly = np.array([a, b, b - depth * normal, a - depth * normal])
    ax.fill(poly[:, 0], poly[:, 1], color=line.get("color", OBSTACLE), alpha=0.12, lw=0)


def _draw_obstacles(ax, obstacles, t: float, xlim, ylim, faint: bool = False) -> None:
    from matplotlib.patches import Circle

    alpha = 0.25 if faint else 1.0
    for ob in obstacles:
        shift = ob.velocity * t
        kind = type(ob).__name__
        label = None if faint else ob.name
        if kind == "LineObstacle":
            if faint and not np.any(ob.velocity):
                continue
            _draw_line(
                ax,
                ob.point + shift,
                ob.normal,
                xlim,
                ylim,
                color=OBSTACLE,
                lw=2,
                alpha=alpha,
                label=label,
            )
        elif kind == "SegmentObstacle":
            a, b = ob.a + shift, ob.b + shift
            ax.plot(
                [a[0], b[0]],
                [a[1], b[1]],
                color=OBSTACLE,
                lw=3,
                alpha=alpha,
                solid_capstyle="round",
                label=label,
            )
        elif kind == "DiskObstacle":
            c = ob.center + shift
            ax.add_patch(
                Circle(
                    c,
                    ob.radius,
                    facecolor=OBSTACLE,
                    edgecolor=OBSTACLE,
                    alpha=0.35 * alpha,
                    label=label,
                )
            )
        elif kind == "PointCloudObstacle":
            pts = ob.points + shift
            ax.scatter(pts[:, 0], pts[:, 1], s=6, color=OBSTACLE, alpha=alpha, label=label)


def _workspace_axes(ax, xlim, ylim) -> None:
    """Equal-aspect axes in metres over the view, with a light grid."""
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(alpha=0.25)


def _frame_parts(scenario):
    arm = scenario.make_arm()
    keys = scenario.make_key_points()
    surface = scenario.make_surface()
    obstacles = scenario.make_obstacles()
    return arm, keys, surface, obstacles


def _draw_poses(ax, arm, keys, theta: np.ndarray, idx: np.ndarray) -> None:
    """The arm and its key points at ticks ``idx``, paler the earlier; the last pose's key points named."""
    for j, k in enumerate(idx):
        shade = 0.18 + 0.82 * (j / max(len(idx) - 1, 1))
        p = arm.joint_positions(theta[k])
        last = j == len(idx) - 1
        ax.plot(
            p[:, 0],
            p[:, 1],
            "-o",
            color=ARM,
            alpha=shade,
            lw=2.6 if last else 1.6,
            ms=4 if last else 2.5,
            label="arm (pale: earlier)" if last else None,
            zorder=3,
        )
        kp = arm.points(theta[k], keys.links, keys.fracs)
        ax.scatter(
            kp[:, 0],
            kp[:, 1],
            s=16 if last else 8,
            color=KEY,
            alpha=shade,
            zorder=4,
            label="key points" if last else None,
        )
        if last:
            for name, q in zip(keys.names, kp):
                ax.annotate(
                    name, q, textcoords="offset points", xytext=(4, 4), fontsize=7, color=KEY
                )


def _draw_paths(ax, log: pd.DataFrame, colour: str = PATH) -> None:
    """The desired and actual end-effector paths [m] (the actual in ``colour``), and the arm's base."""
    ax.plot(
        log["xd_x"],
        log["xd_y"],
        "--",
        color="0.45",
        lw=1.2,
        label="desired end-effector path",
        zorder=2,
    )
    ax.plot(
        log["ee_x"],
        log["ee_y"],
        "-",
        color=colour,
        lw=1.2,
        alpha=0.9,
        label="actual end-effector path",
        zorder=2,
    )
    ax.scatter([0.0], [0.0], marker="s", s=40, color="black", zorder=5, label="base")


def _mark_closest_approach(ax, log: pd.DataFrame, scenario: Scenario, arm, keys, theta) -> None:
    """Ring the key point at its closest approach to an obstacle, red when closer than d_safe."""
    close = closest_approach(log, scenario)
    if close is None or close["key_point"] not in keys.names:
        return
    a = list(keys.names).index(close["key_point"])
    q = arm.points(theta[close["k"]], keys.links[a : a + 1], keys.fracs[a : a + 1])[0]
    d_safe = scenario.data["controller"]["d_safe"]
    bad = close["distance"] < d_safe - 5e-4
    ax.scatter(
        [q[0]],
        [q[1]],
        s=140,
        facecolors="none",
        edgecolors="red" if bad else "black",
        lw=1.8,
        zorder=6,
        label="closest approach",
    )
    ax.annotate(
        f"{close['key_point']}: {close['distance'] * 1e3:.1f} mm from {close['obstacle']}\n"
        f"at t = {close['t']:.2f} s (d_safe {d_safe * 1e3:.0f} mm)",
        q,
        textcoords="offset points",
        xytext=(10, -28),
        fontsize=8,
        color="red" if bad else "black",
    )


def draw_snapshot(
    scenario: Scenario,
    log: pd.DataFrame,
    path: str | Path,
    *,
    instants: int = 8,
    title: str | None = None,
    backend: str | None = None,
) -> Path:
    """Draw the run ``log`` of ``scenario`` as stick figures at ``instants`` times; save to ``path`` (PNG, SVG, PDF).

    Args:
        scenario: The :class:`~qpbench.sim.scenario.Scenario` the log was simulated from.
        log: The tick log (:attr:`qpbench.sim.loop.SimResult.log`).
        path: Output file; its suffix picks the format.
        instants: Number of arm poses drawn, evenly spaced in time (first and last included).
        title: Figure title (default: scenario name and duration).
        backend: The backend of the run: its actual end-effector path in the backend's colour
            (:func:`qpbench.report.style.look`); ``None``: orange.

    Returns:
        ``path``.
    """
    plt = style.pyplot()
    path = Path(path)
    arm, keys, surface, obstacles = _frame_parts(scenario)
    theta = _thetas(log, arm.n)
    t = log["t"].to_numpy(float)
    ticks = len(log)
    xlim, ylim = _view(scenario, log, arm)

    fig, ax = plt.subplots(figsize=(7.5, 6.2), dpi=110)
    _draw_line(
        ax,
        surface.point,
        -surface.normal,
        xlim,
        ylim,
        color=SURFACE,
        lw=2.5,
        label="contact surface",
    )
    moving = any(np.any(ob.velocity) for ob in obstacles)
    if moving:
        _draw_obstacles(ax, obstacles, 0.0, xlim, ylim, faint=True)
    _draw_obstacles(ax, obstacles, float(t[-1]), xlim, ylim)

    _draw_poses(ax, arm, keys, theta, _instants(t, instants))
    _draw_paths(ax, log, PATH if backend is None else style.look(backend).colour)

    _mark_closest_approach(ax, log, scenario, arm, keys, theta)

    _workspace_axes(ax, xlim, ylim)
    ax.set_title(
        title or f"{scenario.name}: the arm over {t[-1] + (t[1] - t[0] if ticks > 1 else 0):.1f} s"
    )
    ax.legend(loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=8, frameon=False)
    fig.tight_layout()
    return style.save(fig, path, dpi=110)


def _frame_ticks(t: np.ndarray, dt: float, fps: float, speed: float) -> list[int]:
    """Ticks shown as frames: every ``speed / (fps * dt)``-th, ``dt`` [s] from ``t`` when it can."""
    dt = float(t[1] - t[0]) if len(t) > 1 else dt
    step = max(1, int(round(speed / (fps * dt))))
    return list(range(0, len(t), step))


def _animation_background(ax, surface, log: pd.DataFrame, obstacles, xlim, ylim) -> bool:
    """Axes, surface, desired path and (if none moves) the obstacles; True when none moves."""
    _workspace_axes(ax, xlim, ylim)
    _draw_line(ax, surface.point, -surface.normal, xlim, ylim, color=SURFACE, lw=2.5)
    ax.plot(log["xd_x"], log["xd_y"], "--", color="0.6", lw=1.0)
    static = not any(np.any(ob.velocity) for ob in obstacles)
    if static:
        _draw_obstacles(ax, obstacles, 0.0, xlim, ylim)
    return static


def _animation_artists(ax) -> tuple:
    """The artists each frame updates: links, key points, end-effector trace, time label."""
    (link_line,) = ax.plot([], [], "-o", color=ARM, lw=2.4, ms=4, zorder=3)
    keys_plot = ax.scatter([], [], s=14, color=KEY, zorder=4)
    (trace,) = ax.plot([], [], "-", color=PATH, lw=1.0, zorder=2)
    label = ax.text(
        0.02, 0.97, "", transform=ax.transAxes, va="top", fontsize=8, family="monospace"
    )
    return link_line, keys_plot, trace, label


def animate(
    scenario: Scenario,
    log: pd.DataFrame,
    path: str | Path,
    *,
    fps: int = 20,
    speed: float = 1.0,
    progress: bool = False,
    title: str | None = None,
    dpi: int = 70,
) -> Path:
    """Render the run as an animation: GIF (Pillow) or MP4 (needs ``ffmpeg`` on the PATH).

    Args:
        scenario: The scenario the log was simulated from.
        log: The tick log.
        path: ``.gif`` or ``.mp4``.
        fps: Frames per second of the file.
        speed: Simulated seconds per second of animation (2.0: twice as fast as real time).
        progress: Show a progress bar (stderr).
        title: Title prefix (default: the scenario's name).
        dpi: Resolution; the default keeps a 20 s GIF at about 1-2 MB.

    Returns:
        ``path``.

    Raises:
        ParamError: an unknown suffix, ``.mp4`` without ffmpeg, or a non-positive ``fps``/``speed``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib import animation

    path = Path(path)
    _check_animation(path, fps, speed)

    arm, keys, surface, obstacles = _frame_parts(scenario)
    theta = _thetas(log, arm.n)
    t = log["t"].to_numpy(float)
    frames = _frame_ticks(t, scenario.dt, fps, speed)
    xlim, ylim = _view(scenario, log, arm)
    d_safe = scenario.data["controller"]["d_safe"]
    from ..sim.log import distance_columns

    dcols = distance_columns(log)

    fig, ax = plt.subplots(figsize=(6, 5), dpi=dpi)
    static = _animation_background(ax, surface, log, obstacles, xlim, ylim)
    link_line, keys_plot, trace, label = _animation_artists(ax)
    moving_artists: list = []
    head = title or scenario.name

    def draw(k):
        for art in moving_artists:
            art.remove()
        moving_artists.clear()
        if not static:
            before = set(ax.lines) | set(ax.collections) | set(ax.patches)
            _draw_obstacles(ax, obstacles, float(t[k]), xlim, ylim)
            moving_artists.extend((set(ax.lines) | set(ax.collections) | set(ax.patches)) - before)
        p = arm.joint_positions(theta[k])
        link_line.set_data(p[:, 0], p[:, 1])
        keys_plot.set_offsets(arm.points(theta[k], keys.links, keys.fracs))
        trace.set_data(log["ee_x"].to_numpy()[: k + 1], log["ee_y"].to_numpy()[: k + 1])
        dmin = np.nanmin(log[dcols].to_numpy()[k]) if dcols else float("nan")
        near = dcols and dmin < d_safe - 5e-4
        label.set_text(
            f"{head}  t = {t[k]:5.2f} s" + (f"   d_min = {dmin * 1e3:6.1f} mm" if dcols else "")
        )
        label.set_color("red" if near else "black")
        return [link_line, keys_plot, trace, label, *moving_artists]

    anim = animation.FuncAnimation(fig, draw, frames=frames, blit=False)
    _save_animation(anim, fig, path, fps, len(frames), progress)
    return path


def _check_animation(path: Path, fps: float, speed: float) -> None:
    """Reject an animation :func:`animate` cannot write (a :class:`ParamError` naming the value)."""
    from ..exceptions import ParamError

    suffix = path.suffix.lower()
    if suffix not in (".gif", ".mp4"):
        raise ParamError(
            f"an animation is a .gif or an .mp4 file, got '{path.name}'", key="animate"
        )
    if suffix == ".mp4" and shutil.which("ffmpeg") is None:
        raise ParamError("writing .mp4 needs ffmpeg on the PATH; use a .gif", key="animate")
    if not (fps > 0 and speed > 0 and math.isfinite(fps) and math.isfinite(speed)):
        raise ParamError(
            f"fps and speed must be positive, got fps={fps}, speed={speed}", key="animate"
        )


def _save_animation(anim, fig, path: Path, fps: float, n_frames: int, progress: bool) -> None:
    """Write ``anim`` to ``path`` atomically (temporary file, then rename) and close ``fig``."""
    import matplotlib.pyplot as plt
    from matplotlib import animation

    suffix = path.suffix.lower()
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=n_frames, unit="frame", desc=f"animate {path.name}", leave=False)
    callback = None if bar is None else (lambda i, n: bar.update(1))  # matplotlib's (frame, total)

    writer = (
        animation.PillowWriter(fps=fps) if suffix == ".gif" else animation.FFMpegWriter(fps=fps)
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp{suffix}")
    try:
        anim.save(tmp, writer=writer, progress_callback=callback)
        from ..atomic import rename

        rename(tmp, path)
    finally:
        if bar is not None:
            bar.close()
        plt.close(fig)
        if tmp.exists():
            tmp.unlink()

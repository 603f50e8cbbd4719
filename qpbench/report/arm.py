"""Pictures of the arm in its workspace: a still (:func:`draw_snapshot`) and an animation
(:func:`animate`, GIF or MP4) of a run: the arm, its key points, the obstacles, the surface, the
end-effector paths in the backend's look, red closer than ``d_safe``; lengths [m]."""

from __future__ import annotations

import math
import shutil
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..robot.obstacles import OBSTACLE_COLOR, draw_line
from ..sim import log as tick_log
from ..sim.verdict import DEFAULT_SAFETY_MARGIN
from . import style

if TYPE_CHECKING:
    import pandas as pd

    from ..sim.scenario import Scenario


#: Colour of the arm (links and joints), of the key points' edges, of obstacles and of the
#: surface: neutral, so that the backend's look is the only colour that names a backend.
ARM, KEY, OBSTACLE, SURFACE = "#343a40", "#212529", OBSTACLE_COLOR, "#2b8a3e"
#: Look of the actual end-effector path when no backend is named.
PATH = style.Look("#495057", "o", "-")
#: The report's two pictures of the arm per scenario, left to right: role -> column header.
ROLES = {"exact": "fastest exact backend", "network": "network"}
#: Width of the workspace (its height follows the view's proportions) and height of the
#: distance panel below it [in].
WORKSPACE_IN, DISTANCE_IN = 5.0, 1.6


def backend_look(backend: str | None) -> style.Look:
    """The backend's look (:func:`qpbench.report.style.look`), or :data:`PATH` when none is named."""
    return PATH if backend is None else style.look(backend)


def closest_approach(log: pd.DataFrame) -> dict | None:
    """Where and when a key point came closest to an obstacle: ``{"t", "k" (tick index),
    "key_point", "obstacle", "distance" [m]}``; ``None`` without obstacles."""
    cols = tick_log.distance_columns(log)
    if not cols:
        return None
    D = log[cols].to_numpy(dtype=float)
    if not np.isfinite(D).any():
        return None
    k, c = divmod(int(np.nanargmin(D)), D.shape[1])
    _, key, obstacle = cols[c].split("_", 2)
    return {
        "t": float(log["t"].iloc[k]),
        "k": int(k),
        "key_point": key,
        "obstacle": obstacle,
        "distance": float(D[k, c]),
    }


def _instants(t: np.ndarray, count: int) -> np.ndarray:
    """Ticks nearest to ``count`` times evenly spaced over ``t`` (a decimated log's are not)."""
    if len(t) < 2:
        return np.zeros(len(t), dtype=int)
    count = max(2, min(int(count), len(t)))
    wanted = np.linspace(t[0], t[-1], count)
    k = np.clip(np.searchsorted(t, wanted), 1, len(t) - 1)
    k -= (wanted - t[k - 1]) < (t[k] - wanted)
    return np.unique(k)


def view(scenario, log, arm) -> tuple[tuple[float, float], tuple[float, float]]:
    """Axis limits [m] around the arm's joints (400 ticks at most), the base, both end-effector
    paths, the lines' and the surface's nearest points and the shapes within twice the reach."""
    reach = float(np.sum(arm.lengths))
    theta = log[tick_log.theta_columns(arm.n)].to_numpy(float)
    every = max(1, len(theta) // 400)
    parts = [np.zeros((1, 2))]
    parts += [arm.joint_positions(q) for q in theta[::every] if np.isfinite(q).all()]
    parts += [log[["ee_x", "ee_y"]].to_numpy(float), log[["xd_x", "xd_y"]].to_numpy(float)]
    surface = scenario.make_surface()
    parts.append(_foot(surface.point, surface.normal)[None, :])
    for ob in scenario.make_obstacles():
        near = ob.view_points()
        parts.append(near[np.linalg.norm(near, axis=1) <= 2.0 * reach])
    pts = np.concatenate([p.reshape(-1, 2) for p in parts])
    pts = pts[np.isfinite(pts).all(axis=1)]
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = 0.12 * max(float(np.max(hi - lo)), 0.5 * reach)
    return (lo[0] - pad, hi[0] + pad), (lo[1] - pad, hi[1] + pad)


def _foot(point, normal) -> np.ndarray:
    """The point of the line through ``point`` perpendicular to ``normal`` nearest the origin."""
    point, normal = np.asarray(point, float), np.asarray(normal, float)
    normal = normal / np.linalg.norm(normal)
    return normal * float(normal @ point)


def draw_obstacles(ax, obstacles, t: float, xlim, ylim, faint: bool = False) -> None:
    """Each obstacle as at ``t`` [s], drawn by its kind (a static line is not drawn again
    ``faint``)."""
    for ob in obstacles:
        ob.draw(ax, t, limits=(xlim, ylim), faint=faint, color=OBSTACLE)


def workspace_axes(ax, xlim, ylim) -> None:
    """Equal-aspect axes in metres over the view, with a light grid."""
    ax.set_xlim(*xlim)
    ax.set_ylim(*ylim)
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.grid(alpha=0.25)


#: Keyword arguments of an earlier pose's links and key points, and of the last pose's.
POSE = (dict(lw=1.6, ms=2.5), dict(lw=2.6, ms=4, label="arm (pale: earlier poses)"))
DOTS = (dict(s=10, lw=0.6), dict(s=26, lw=1.0, label="key points (last pose named)"))


def _draw_poses(ax, arm, keys, theta: np.ndarray, idx: np.ndarray) -> None:
    """The arm and its key points at ticks ``idx``, paler the earlier; the last one's named (on
    a white halo: links behind them do not hide them)."""
    from matplotlib import patheffects

    for j, k in enumerate(idx):
        shade = 0.18 + 0.82 * (j / max(len(idx) - 1, 1))
        last = j == len(idx) - 1
        p = arm.joint_positions(theta[k])
        ax.plot(p[:, 0], p[:, 1], "-o", color=ARM, alpha=shade, zorder=3, **POSE[last])
        kp = arm.points(theta[k], keys.links, keys.fracs)
        dots = dict(facecolors="white", edgecolors=KEY, alpha=shade, zorder=4)
        ax.scatter(kp[:, 0], kp[:, 1], **dots, **DOTS[last])
    halo = [patheffects.withStroke(linewidth=2.5, foreground="white")]
    name = dict(textcoords="offset points", xytext=(5, 4), fontsize=7.5, color=KEY, zorder=7)
    for text, q in zip(keys.names, kp):
        ax.annotate(text, q, path_effects=halo, **name)


def _draw_paths(ax, log: pd.DataFrame, backend: str | None = None) -> None:
    """The desired and actual end-effector paths [m] (the actual in the run's look), the base."""
    desired = dict(color="0.35", lw=1.3, label="desired end-effector path", zorder=2)
    ax.plot(log["xd_x"], log["xd_y"], ":", **desired)
    label = f"{backend}: actual end-effector path" if backend else "actual end-effector path"
    # no markers along it (they would read as key points); the legend shows one
    ax.plot(log["ee_x"], log["ee_y"], **backend_look(backend).line(lw=1.6, label=label, zorder=5))
    ax.scatter([0.0], [0.0], marker="s", s=40, color="black", zorder=5, label="base")


def _mark_closest_approach(ax, log: pd.DataFrame, scenario: Scenario, arm, keys, theta) -> None:
    """Ring the key point at its closest approach to an obstacle, red when closer than d_safe."""
    close = closest_approach(log)
    if close is None or close["key_point"] not in keys.names:
        return
    a = list(keys.names).index(close["key_point"])
    q = arm.points(theta[close["k"]], keys.links[a : a + 1], keys.fracs[a : a + 1])[0]
    d_safe = scenario.spec.controller.d_safe
    bad = close["distance"] < d_safe - DEFAULT_SAFETY_MARGIN
    label = (
        f"closest approach: {close['key_point']} {close['distance'] * 1e3:.1f} mm "
        f"from {close['obstacle']}\nat t = {close['t']:.2f} s (d_safe {d_safe * 1e3:g} mm)"
    )
    ring = dict(s=170, facecolors="none", edgecolors="red" if bad else "black", lw=1.8)
    ax.scatter([q[0]], [q[1]], zorder=6, label=label, **ring)


def check_drawable(scenario: Scenario, key: str) -> None:
    """A :class:`~qpbench.exceptions.ParamError` naming ``key`` when ``scenario``'s arm is not
    planar: the pictures here are of the plane."""
    from ..exceptions import ParamError

    if scenario.make_arm().dim != 2:
        raise ParamError(
            f"draws a planar arm; {scenario.name}'s robot is spatial ({scenario.spec.robot.kind})",
            key=key,
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
    """Draw the tick log of a run of ``scenario`` at ``instants`` poses evenly spaced in time
    into ``path`` (PNG, SVG or PDF by its suffix); return it. ``backend``: the run's, whose look
    its path and distance line take (``None``: grey)."""
    from .loop_figure import has_distance

    check_drawable(scenario, "scenario")
    arm, keys = scenario.make_arm(), scenario.make_key_points()
    surface, obstacles = scenario.make_surface(), scenario.make_obstacles()
    theta = log[tick_log.theta_columns(arm.n)].to_numpy(float)
    t = log["t"].to_numpy(float)
    xlim, ylim = view(scenario, log, arm)
    has_d = has_distance(log)

    # the workspace's height follows its view's proportions (equal axes), within limits
    high = float(np.clip(WORKSPACE_IN * np.ptp(ylim) / np.ptp(xlim), 2.4, 1.3 * WORKSPACE_IN))
    size = (WORKSPACE_IN + 3.2, high + 0.8 + (DISTANCE_IN + 0.6 if has_d else 0.0))
    ratios = [high, DISTANCE_IN] if has_d else None
    fig, axes = style.subplots(2 if has_d else 1, 1, *size, height_ratios=ratios)
    ax = axes[0, 0]
    surface_line = dict(color=SURFACE, lw=2.5, label="contact surface")
    draw_line(ax, surface.point, -surface.normal, xlim, ylim, **surface_line)
    if any(np.any(ob.velocity) for ob in obstacles):  # moving: also faint where they started
        draw_obstacles(ax, obstacles, 0.0, xlim, ylim, faint=True)
    draw_obstacles(ax, obstacles, float(t[-1]), xlim, ylim)

    _draw_poses(ax, arm, keys, theta, _instants(t, instants))
    _draw_paths(ax, log, backend)

    _mark_closest_approach(ax, log, scenario, arm, keys, theta)

    workspace_axes(ax, xlim, ylim)
    span = t[-1] + (t[1] - t[0] if len(t) > 1 else 0)
    ax.set_title(title or f"{scenario.name}: the arm over {span:.1f} s")
    if has_d:
        _distance_panel(axes[1, 0], log, backend, scenario.spec.controller.d_safe)
    style.legend_beside(ax, *style.entries(axes[:, 0]))
    return style.save(fig, path, dpi=110)


def _distance_panel(ax, log: pd.DataFrame, backend: str | None, d_safe: float) -> None:
    """The closest key point's distance [mm] against t in the run's look (the body's dashed),
    its closest approach ringed, on the report's distance axis (:mod:`.loop_figure`)."""
    from .loop_figure import distance_axis

    look = backend_look(backend)
    name = f"{backend}: " if backend else ""
    t = log[tick_log.T].to_numpy(float)
    d = log[tick_log.D_MIN].to_numpy(float) * 1e3
    ax.plot(t, d, **look.line(t, lw=1.2, label=f"{name}closest key point [mm]", zorder=3))
    if tick_log.D_BODY_MIN in log.columns:
        body = log[tick_log.D_BODY_MIN].to_numpy(float) * 1e3
        if np.isfinite(body).any():
            label = f"{name}closest point of the body [mm]"
            ax.plot(t, body, color=look.colour, ls=(0, (2, 2)), lw=0.9, label=label, zorder=2)
    k = int(np.nanargmin(d))
    bad = d[k] < (d_safe - DEFAULT_SAFETY_MARGIN) * 1e3
    ring = dict(s=110, facecolors="none", edgecolors="red" if bad else "black", lw=1.6)
    ax.scatter([t[k]], [d[k]], **ring)
    distance_axis(ax, d_safe, float(np.nanmin(d)))
    ax.set_xlabel("t [s]")
    ax.set_ylabel("distance to an\nobstacle [mm]", fontsize=9)
    ax.grid(True, which="major", alpha=0.3)


def _animation_background(ax, surface, log: pd.DataFrame, obstacles, xlim, ylim) -> bool:
    """Axes, surface, desired path and (if none moves) the obstacles; True when none moves."""
    workspace_axes(ax, xlim, ylim)
    draw_line(ax, surface.point, -surface.normal, xlim, ylim, color=SURFACE, lw=2.5)
    ax.plot(log["xd_x"], log["xd_y"], "--", color="0.6", lw=1.0)
    static = not any(np.any(ob.velocity) for ob in obstacles)
    if static:
        draw_obstacles(ax, obstacles, 0.0, xlim, ylim)
    return static


def _animation_artists(ax, backend: str | None = None) -> tuple:
    """The artists each frame updates: links, key points, end-effector trace, time stamp (title)."""
    (link_line,) = ax.plot([], [], "-o", color=ARM, lw=2.4, ms=4, zorder=3)
    keys_plot = ax.scatter([], [], s=18, facecolors="white", edgecolors=KEY, lw=0.9, zorder=4)
    look = backend_look(backend)
    (trace,) = ax.plot([], [], color=look.colour, ls=look.linestyle, lw=1.4, zorder=5)
    label = ax.set_title("", fontsize=8, family="monospace", loc="left")
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
    backend: str | None = None,
) -> Path:
    """Render the tick log of a run of ``scenario`` frame by frame to ``path`` (``.gif``, or
    ``.mp4`` with ffmpeg), the time stamp red while a key point is closer than ``d_safe``; return
    it. ``speed``: simulated seconds per second of animation; ``backend``: whose look the
    end-effector trace takes (``None``: dark grey).

    Raises:
        ParamError: an unknown suffix, ``.mp4`` without ffmpeg, or a non-positive ``fps``/``speed``.
    """
    from matplotlib import animation

    path = Path(path)
    check_animation(path, fps, speed)

    check_drawable(scenario, "scenario")
    arm, keys = scenario.make_arm(), scenario.make_key_points()
    surface, obstacles = scenario.make_surface(), scenario.make_obstacles()
    theta = log[tick_log.theta_columns(arm.n)].to_numpy(float)
    t = log["t"].to_numpy(float)
    dt = float(t[1] - t[0]) if len(t) > 1 else scenario.dt  # every speed / (fps dt)-th tick
    frames = list(range(0, len(t), max(1, int(round(speed / (fps * dt))))))
    xlim, ylim = view(scenario, log, arm)
    d_safe = scenario.spec.controller.d_safe
    dcols = tick_log.distance_columns(log)

    # equal axes: the frame's height follows the view's proportions
    high = float(np.clip(5.4 * np.ptp(ylim) / np.ptp(xlim) + 0.9, 2.6, 6.0))
    fig, ax = style.pyplot().subplots(figsize=(6, high), dpi=70, layout="constrained")
    static = _animation_background(ax, surface, log, obstacles, xlim, ylim)
    link_line, keys_plot, trace, label = _animation_artists(ax, backend)
    moving_artists: list = []
    head = title or scenario.name

    def draw(k):
        for art in moving_artists:
            art.remove()
        moving_artists.clear()
        if not static:
            before = set(ax.lines) | set(ax.collections) | set(ax.patches)
            draw_obstacles(ax, obstacles, float(t[k]), xlim, ylim)
            moving_artists.extend((set(ax.lines) | set(ax.collections) | set(ax.patches)) - before)
        p = arm.joint_positions(theta[k])
        link_line.set_data(p[:, 0], p[:, 1])
        keys_plot.set_offsets(arm.points(theta[k], keys.links, keys.fracs))
        trace.set_data(log["ee_x"].to_numpy()[: k + 1], log["ee_y"].to_numpy()[: k + 1])
        dmin = np.nanmin(log[dcols].to_numpy()[k]) if dcols else float("nan")
        near = dcols and dmin < d_safe - DEFAULT_SAFETY_MARGIN
        label.set_text(
            f"{head}  t = {t[k]:5.2f} s" + (f"   d_min = {dmin * 1e3:6.1f} mm" if dcols else "")
        )
        label.set_color("red" if near else "black")
        return [link_line, keys_plot, trace, label, *moving_artists]

    anim = animation.FuncAnimation(fig, draw, frames=frames, blit=False)
    _save_animation(anim, fig, path, fps, len(frames), progress)
    return path


def check_animation(path: Path, fps: float, speed: float) -> None:
    """Reject an animation :func:`animate` cannot write (a :class:`ParamError` naming the value)."""
    from ..exceptions import ParamError

    suffix = path.suffix.lower()
    key = "animate"
    if suffix not in (".gif", ".mp4"):
        raise ParamError(f"an animation is a .gif or an .mp4 file, got '{path.name}'", key=key)
    if suffix == ".mp4" and shutil.which("ffmpeg") is None:
        raise ParamError("writing .mp4 needs ffmpeg on the PATH; use a .gif", key=key)
    if not (fps > 0 and speed > 0 and math.isfinite(fps) and math.isfinite(speed)):
        raise ParamError(f"fps and speed must be positive, got fps={fps}, speed={speed}", key=key)


def _save_animation(anim, fig, path: Path, fps: float, n_frames: int, progress: bool) -> None:
    """Write ``anim`` to ``path`` atomically (temporary file, then rename) and close ``fig``."""
    from matplotlib import animation
    from tqdm import tqdm

    from ..atomic import record, rename

    suffix = path.suffix.lower()
    writer = (animation.PillowWriter if suffix == ".gif" else animation.FFMpegWriter)(fps=fps)
    desc = f"animate {path.name}"
    bar = tqdm(total=n_frames, unit="frame", desc=desc, leave=False, disable=not progress)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp{suffix}")
    try:  # matplotlib's progress callback gets (frame, total)
        anim.save(tmp, writer=writer, progress_callback=lambda i, n: bar.update(1))
        rename(tmp, path)
        record(path)  # listed with the command's other outputs
    finally:
        bar.close()
        style.pyplot().close(fig)
        tmp.unlink(missing_ok=True)

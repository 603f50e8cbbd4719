"""The arm's run as an animation (GIF, or MP4 with ``ffmpeg``): the scene of :mod:`.arm` frame
by frame, with a time stamp outside the workspace, red while a key point is closer than
``d_safe``."""

from __future__ import annotations

import math
import shutil
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..sim.verdict import DEFAULT_SAFETY_MARGIN
from . import arm as scene
from . import style

if TYPE_CHECKING:
    import pandas as pd

    from ..sim.scenario import Scenario


def _animation_background(ax, surface, log: pd.DataFrame, obstacles, xlim, ylim) -> bool:
    """Axes, surface, desired path and (if none moves) the obstacles; True when none moves."""
    scene.workspace_axes(ax, xlim, ylim)
    scene.draw_line(ax, surface.point, -surface.normal, xlim, ylim, color=scene.SURFACE, lw=2.5)
    ax.plot(log["xd_x"], log["xd_y"], "--", color="0.6", lw=1.0)
    static = not any(np.any(ob.velocity) for ob in obstacles)
    if static:
        scene.draw_obstacles(ax, obstacles, 0.0, xlim, ylim)
    return static


def _animation_artists(ax, backend: str | None = None) -> tuple:
    """The artists each frame updates: links, key points, end-effector trace (in ``backend``'s
    look), and the time stamp (the axes' title: outside the workspace, never over the arm)."""
    (link_line,) = ax.plot([], [], "-o", color=scene.ARM, lw=2.4, ms=4, zorder=3)
    keys_plot = ax.scatter([], [], s=18, facecolors="white", edgecolors=scene.KEY, lw=0.9, zorder=4)
    look = scene.backend_look(backend)
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
    """Render the tick log of a run of ``scenario`` to ``path`` (``.gif`` or ``.mp4``); return it.

    ``speed``: simulated seconds per second of animation; ``backend``: the run's backend, whose
    look its end-effector trace takes (``None``: dark grey).

    Raises:
        ParamError: an unknown suffix, ``.mp4`` without ffmpeg, or a non-positive ``fps``/``speed``.
    """
    from matplotlib import animation

    from ..sim.log import distance_columns

    path = Path(path)
    check_animation(path, fps, speed)

    arm, keys, surface, obstacles = scene.frame_parts(scenario)
    theta = scene.thetas(log, arm.n)
    t = log["t"].to_numpy(float)
    dt = float(t[1] - t[0]) if len(t) > 1 else scenario.dt  # every speed / (fps dt)-th tick
    frames = list(range(0, len(t), max(1, int(round(speed / (fps * dt))))))
    xlim, ylim = scene.view(scenario, log, arm)
    d_safe = scenario.data["controller"]["d_safe"]
    dcols = distance_columns(log)

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
            scene.draw_obstacles(ax, obstacles, float(t[k]), xlim, ylim)
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
    from matplotlib import animation
    from tqdm import tqdm

    from ..atomic import record, rename

    suffix = path.suffix.lower()
    writer = (
        animation.PillowWriter(fps=fps) if suffix == ".gif" else animation.FFMpegWriter(fps=fps)
    )
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

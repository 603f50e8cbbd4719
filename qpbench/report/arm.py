"""Pictures of the arm in its workspace: a still (:func:`draw_snapshot`) and an animation
(:func:`animate`, GIF or MP4) of a run: the arm, its key points, the obstacles, the surface, the
end-effector paths in the backend's look, red closer than ``d_safe``; lengths [m]. A planar arm
is drawn in its plane, a spatial one in two orthographic views side by side (:func:`views`)."""

from __future__ import annotations

import math
import shutil
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..robot.obstacles import OBSTACLE_COLOR, draw_trace, outline, project, trace
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


def views(scenario: Scenario) -> tuple[tuple[str, str], ...]:
    """The orthographic views a picture of ``scenario``'s arm shows, left to right, each the
    plane of two axes (horizontal, vertical): a planar arm's plane, ``("x", "y")``; for a
    spatial arm two views chosen by the contact normal's largest axis ``n``: seen along ``n``,
    the surface face on (the path traced on it, the obstacles beside it; the other two axes in
    order), and seen across it, the surface edge on as a line (the pressing, the heights of the
    arm and the obstacles over the surface; ``n`` and z, or x and z when ``n`` is z, so z is up)."""
    if scenario.make_arm().dim == 2:
        return (("x", "y"),)
    n = "xyz"[int(np.argmax(np.abs(scenario.make_surface().normal)))]
    face = tuple(a for a in "xyz" if a != n)
    return face, ("x" if n == "z" else n, "z")


def _log_points(log: pd.DataFrame, prefix: str) -> np.ndarray:
    """The positions (T, dim) [m] of the log's ``<prefix>_x``, ``_y`` (and ``_z``) columns."""
    return log[[c for c in (f"{prefix}_{a}" for a in "xyz") if c in log.columns]].to_numpy(float)


def _instants(t: np.ndarray, count: int) -> np.ndarray:
    """Ticks nearest to ``count`` times evenly spaced over ``t`` (a decimated log's are not)."""
    if len(t) < 2:
        return np.zeros(len(t), dtype=int)
    count = max(2, min(int(count), len(t)))
    wanted = np.linspace(t[0], t[-1], count)
    k = np.clip(np.searchsorted(t, wanted), 1, len(t) - 1)
    k -= (wanted - t[k - 1]) < (t[k] - wanted)
    return np.unique(k)


def view(scenario, log, arm, plane=("x", "y")) -> tuple[tuple[float, float], tuple[float, float]]:
    """Axis limits [m] of the view ``plane`` around the arm's joints (400 ticks at most), the
    base, both end-effector paths, the lines' and the surface's nearest points and the shapes
    within twice the reach."""
    reach = float(np.sum(arm.lengths))
    theta = log[tick_log.theta_columns(arm.n)].to_numpy(float)
    every = max(1, len(theta) // 400)
    parts = [np.zeros((1, 2))]
    parts += [
        project(arm.joint_positions(q), plane) for q in theta[::every] if np.isfinite(q).all()
    ]
    parts += [project(_log_points(log, p), plane) for p in ("ee", "xd")]
    surface = scenario.make_surface()
    seen = trace(surface.point, surface.normal, plane)  # its point nearest the origin
    parts.append(np.empty((0, 2)) if seen is None else seen[0])
    for ob in scenario.make_obstacles():
        near = ob.view_points(plane)
        parts.append(near[np.linalg.norm(near, axis=1) <= 2.0 * reach])
    pts = np.concatenate([p.reshape(-1, 2) for p in parts])
    pts = pts[np.isfinite(pts).all(axis=1)]
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = 0.12 * max(float(np.max(hi - lo)), 0.5 * reach)
    return (lo[0] - pad, hi[0] + pad), (lo[1] - pad, hi[1] + pad)


def limits(scenario, log, arm) -> tuple[tuple, dict[str, tuple[float, float]], float]:
    """The :func:`views`, axis name -> limits [m] (each view's :func:`view`, an axis two views
    share spanning both: the views line up along it) and the largest height / width of a view."""
    planes, out = views(scenario), {}
    for plane in planes:
        for axis, (lo, hi) in zip(plane, view(scenario, log, arm, plane)):
            was = out.get(axis, (lo, hi))
            out[axis] = (min(lo, was[0]), max(hi, was[1]))
    return planes, out, max(np.ptp(out[v]) / np.ptp(out[h]) for h, v in planes)


def draw_obstacles(ax, obstacles, t: float, xlim, ylim, faint: bool = False, plane=("x", "y")):
    """Each obstacle as at ``t`` [s] on the view ``plane``, drawn by its kind (a static plane is
    not drawn again ``faint``)."""
    for ob in obstacles:
        ob.draw(ax, t, plane=plane, limits=(xlim, ylim), faint=faint, color=OBSTACLE)


def workspace_axes(ax, xlim, ylim, plane=("x", "y")) -> None:
    """Equal-aspect axes in metres over the view ``plane``, with a light grid."""
    ax.set(xlim=xlim, ylim=ylim, aspect="equal", xlabel=f"{plane[0]} [m]", ylabel=f"{plane[1]} [m]")
    ax.grid(alpha=0.25)


def caption(plane) -> str:
    """A view's name and the way it looks (``("x", "z")``: "x-z view, seen along +y")."""
    h, v = (np.eye(3)["xyz".index(a)] for a in plane)
    sight = -np.cross(h, v)  # horizontal right, vertical up: the eye looks along -(h x v)
    i = int(np.argmax(np.abs(sight)))
    return f"{plane[0]}-{plane[1]} view, seen along {'-' if sight[i] < 0 else '+'}{'xyz'[i]}"


def _capsules(ax, p: np.ndarray, radius: float, label: str | None = None) -> list:
    """The links between joints ``p`` (n+1, 2) [m] as the shadows of capsules of ``radius``
    [m], one patch filling their union evenly (none when ``radius`` is 0); the patches."""
    from matplotlib.patches import PathPatch
    from matplotlib.path import Path as Outline

    if radius <= 0.0:
        return []
    hulls = [outline(p[i : i + 2], radius) for i in range(len(p) - 1)]
    shadow = Outline.make_compound_path(*(Outline([*h, h[0]], closed=True) for h in hulls))
    label = label and f"{label}: links as capsules of {radius * 1e3:g} mm"
    return [ax.add_patch(PathPatch(shadow, color=ARM, alpha=0.16, lw=0, zorder=2, label=label))]


#: Keyword arguments of an earlier pose's links and key points, and of the last pose's.
POSE = (dict(lw=1.6, ms=2.5), dict(lw=2.6, ms=4, label="arm (pale: earlier poses)"))
DOTS = (dict(s=10, lw=0.6), dict(s=26, lw=1.0, label="key points (last pose named)"))


def _draw_poses(ax, arm, keys, theta: np.ndarray, idx: np.ndarray, plane=("x", "y")) -> None:
    """The arm and its key points at ticks ``idx`` on the view ``plane``, paler the earlier,
    the last one's links as capsules of the key points' radius; the last one's named (on a
    white halo: links behind them do not hide them)."""
    from matplotlib import patheffects

    for j, k in enumerate(idx):
        shade = 0.18 + 0.82 * (j / max(len(idx) - 1, 1))
        last = j == len(idx) - 1
        p = project(arm.joint_positions(theta[k]), plane)
        if last:
            _capsules(ax, p, keys.radius, label="arm")
        ax.plot(p[:, 0], p[:, 1], "-o", color=ARM, alpha=shade, zorder=3, **POSE[last])
        kp = project(arm.points(theta[k], keys.links, keys.fracs), plane)
        dots = dict(facecolors="white", edgecolors=KEY, alpha=shade, zorder=4)
        ax.scatter(kp[:, 0], kp[:, 1], **dots, **DOTS[last])
    halo = [patheffects.withStroke(linewidth=2.5, foreground="white")]
    name = dict(textcoords="offset points", xytext=(5, 4), fontsize=7.5, color=KEY, zorder=7)
    for text, q in zip(keys.names, kp):
        ax.annotate(text, q, path_effects=halo, **name)


def _draw_paths(ax, log: pd.DataFrame, backend: str | None = None, plane=("x", "y")) -> None:
    """The desired and actual end-effector paths [m] on the view ``plane`` (the actual in the
    run's look), the base."""
    desired = dict(color="0.35", lw=1.3, label="desired end-effector path", zorder=2)
    xd, ee = (project(_log_points(log, p), plane) for p in ("xd", "ee"))
    ax.plot(xd[:, 0], xd[:, 1], ":", **desired)
    label = f"{backend}: actual end-effector path" if backend else "actual end-effector path"
    # no markers along it (they would read as key points); the legend shows one
    ax.plot(ee[:, 0], ee[:, 1], **backend_look(backend).line(lw=1.6, label=label, zorder=5))
    ax.scatter([0.0], [0.0], marker="s", s=40, color="black", zorder=5, label="base")


def _mark_closest_approach(ax, log, scenario: Scenario, arm, keys, theta, plane=("x", "y")):
    """Ring the key point at its closest approach to an obstacle (:func:`closest_approach`; a
    ``closest`` key point: its link's point nearest the obstacle), red when closer than d_safe."""
    close = closest_approach(log)
    if close is None or close["key_point"] not in keys.names:
        return
    a, k = list(keys.names).index(close["key_point"]), close["k"]
    links, fracs = keys.links[a : a + 1], keys.fracs[a : a + 1]
    obstacle = [ob for ob in scenario.make_obstacles() if ob.name == close["obstacle"]]
    if keys.kind != "closest" or not obstacle:
        point = arm.points(theta[k], links, fracs)[0]
    else:
        p = arm.joint_positions(theta[k])
        A, _, dist, _ = obstacle[0].closest_on_segments(p[links], p[links + 1], close["t"])
        point = A[0, int(np.argmin(dist[0]))]
    q = project(point, plane)
    d_safe = scenario.spec.controller.d_safe
    bad = close["distance"] < d_safe - DEFAULT_SAFETY_MARGIN
    label = (
        f"closest approach: {close['key_point']} {close['distance'] * 1e3:.1f} mm "
        f"from {close['obstacle']}\nat t = {close['t']:.2f} s (d_safe {d_safe * 1e3:g} mm)"
    )
    ring = dict(s=170, facecolors="none", edgecolors="red" if bad else "black", lw=1.8)
    ax.scatter([q[0]], [q[1]], zorder=6, label=label, **ring)


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
    into ``path`` (PNG, SVG or PDF by its suffix), in each of its :func:`views` side by side;
    return it. ``backend``: the run's, whose look its path and distance line take (``None``:
    grey)."""
    from .loop_figure import has_distance

    arm, keys = scenario.make_arm(), scenario.make_key_points()
    surface, obstacles = scenario.make_surface(), scenario.make_obstacles()
    theta = log[tick_log.theta_columns(arm.n)].to_numpy(float)
    t = log["t"].to_numpy(float)
    planes, lims, ratio = limits(scenario, log, arm)
    has_d = has_distance(log)

    # the workspace's height follows its views' proportions (equal axes), within limits
    high = float(np.clip(WORKSPACE_IN * ratio, 2.4, 1.3 * WORKSPACE_IN))
    size = (WORKSPACE_IN * len(planes) + 3.2, high + 0.8 + (DISTANCE_IN + 0.6 if has_d else 0.0))
    fig = style.pyplot().figure(figsize=size, layout="constrained")
    ratios = [high, DISTANCE_IN] if has_d else None
    grid = fig.add_gridspec(2 if has_d else 1, len(planes), height_ratios=ratios)
    axes = [fig.add_subplot(grid[0, j]) for j in range(len(planes))]
    surface_line = dict(color=SURFACE, lw=2.5, label="contact surface")
    moving = any(np.any(ob.velocity) for ob in obstacles)  # also faint where they started
    for ax, plane in zip(axes, planes):
        xlim, ylim = lims[plane[0]], lims[plane[1]]
        draw_trace(ax, surface.point, -surface.normal, plane, (xlim, ylim), **surface_line)
        if moving:
            draw_obstacles(ax, obstacles, 0.0, xlim, ylim, faint=True, plane=plane)
        draw_obstacles(ax, obstacles, float(t[-1]), xlim, ylim, plane=plane)
        _draw_poses(ax, arm, keys, theta, _instants(t, instants), plane)
        _draw_paths(ax, log, backend, plane)
        _mark_closest_approach(ax, log, scenario, arm, keys, theta, plane)
        workspace_axes(ax, xlim, ylim, plane)
        if len(planes) > 1:
            ax.set_title(caption(plane), fontsize=9)
    span = t[-1] + (t[1] - t[0] if len(t) > 1 else 0)
    heading = title or f"{scenario.name}: the arm over {span:.1f} s"
    if len(planes) > 1:
        fig.suptitle(heading)
    else:
        axes[0].set_title(heading)
    if has_d:
        axes.append(fig.add_subplot(grid[1, :]))
        _distance_panel(axes[-1], log, backend, scenario.spec.controller.d_safe)
    entries = dict(zip(*style.entries(axes)[::-1]))  # by label: a view's repeats dropped
    style.legend_beside(axes[len(planes) - 1], list(entries.values()), list(entries))
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
    ``.mp4`` with ffmpeg), in each of its :func:`views` side by side, the time stamp red while
    a key point is closer than ``d_safe``; return it. ``speed``: simulated seconds per second
    of animation; ``backend``: whose look the end-effector trace takes (``None``: dark grey).

    Raises:
        ParamError: an unknown suffix, ``.mp4`` without ffmpeg, or a non-positive ``fps``/``speed``.
    """
    from matplotlib import animation

    path = Path(path)
    check_animation(path, fps, speed)

    arm, keys = scenario.make_arm(), scenario.make_key_points()
    obstacles = scenario.make_obstacles()
    theta = log[tick_log.theta_columns(arm.n)].to_numpy(float)
    t = log["t"].to_numpy(float)
    ee = _log_points(log, "ee")
    dt = float(t[1] - t[0]) if len(t) > 1 else scenario.dt  # every speed / (fps dt)-th tick
    frames = list(range(0, len(t), max(1, int(round(speed / (fps * dt))))))
    planes, lims, ratio = limits(scenario, log, arm)
    d_safe = scenario.spec.controller.d_safe
    dcols = tick_log.distance_columns(log)

    # equal axes: the frame's height follows the views' proportions
    high = float(np.clip(5.4 * ratio + 0.9, 2.6, 6.0))
    fig, grid = style.subplots(1, len(planes), 6 * len(planes), high, dpi=70)
    axes = list(grid[0])
    static = not any(np.any(ob.velocity) for ob in obstacles)
    updated = _animation_views(axes, planes, lims, scenario, log, static, backend_look(backend))
    label = axes[0].set_title("", fontsize=8, family="monospace", loc="left")
    moving_artists: list = []
    head = title or scenario.name

    def shown(ax) -> set:
        return set(ax.lines) | set(ax.collections) | set(ax.patches)

    def draw(k):
        for art in moving_artists:
            art.remove()
        moving_artists.clear()
        for ax, plane, (link_line, keys_plot, trace_line) in zip(axes, planes, updated):
            p = project(arm.joint_positions(theta[k]), plane)
            moving_artists.extend(_capsules(ax, p, keys.radius))
            if not static:
                before = shown(ax)
                draw_obstacles(ax, obstacles, float(t[k]), *(lims[a] for a in plane), plane=plane)
                moving_artists.extend(shown(ax) - before)
            link_line.set_data(p[:, 0], p[:, 1])
            keys_plot.set_offsets(project(arm.points(theta[k], keys.links, keys.fracs), plane))
            e = project(ee[: k + 1], plane)
            trace_line.set_data(e[:, 0], e[:, 1])
        dmin = np.nanmin(log[dcols].to_numpy()[k]) if dcols else float("nan")
        near = dcols and dmin < d_safe - DEFAULT_SAFETY_MARGIN
        label.set_text(
            f"{head}  t = {t[k]:5.2f} s" + (f"   d_min = {dmin * 1e3:6.1f} mm" if dcols else "")
        )
        label.set_color("red" if near else "black")
        return [*(a for arts in updated for a in arts), label, *moving_artists]

    anim = animation.FuncAnimation(fig, draw, frames=frames, blit=False)
    _save_animation(anim, fig, path, fps, len(frames), progress)
    return path


def _animation_views(axes, planes, lims, scenario: Scenario, log, static: bool, look) -> list:
    """Draw each view's still parts (axes, surface, desired path, the obstacles if none moves)
    and return, per view, the artists a frame updates: links, key points, trace."""
    surface, obstacles = scenario.make_surface(), scenario.make_obstacles()
    updated = []
    for ax, plane in zip(axes, planes):
        xlim, ylim = lims[plane[0]], lims[plane[1]]
        workspace_axes(ax, xlim, ylim, plane)
        draw_trace(ax, surface.point, -surface.normal, plane, (xlim, ylim), color=SURFACE, lw=2.5)
        xd = project(_log_points(log, "xd"), plane)
        ax.plot(xd[:, 0], xd[:, 1], "--", color="0.6", lw=1.0)
        if static:
            draw_obstacles(ax, obstacles, 0.0, xlim, ylim, plane=plane)
        if len(planes) > 1:
            ax.set_title(caption(plane), fontsize=8, loc="right")
        (link_line,) = ax.plot([], [], "-o", color=ARM, lw=2.4, ms=4, zorder=3)
        keys_plot = ax.scatter([], [], s=18, facecolors="white", edgecolors=KEY, lw=0.9, zorder=4)
        (trace_line,) = ax.plot([], [], color=look.colour, ls=look.linestyle, lw=1.4, zorder=5)
        updated.append((link_line, keys_plot, trace_line))
    return updated


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

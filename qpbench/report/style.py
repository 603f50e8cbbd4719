"""One look per backend (:func:`look`), the same in every figure; panels of at most
:data:`MAX_SERIES` highlighted backends (:func:`groups`, :func:`panels`), the others grey behind;
the one place figures are saved (:func:`save`)."""

from __future__ import annotations

import logging
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Iterable, Iterator

log = logging.getLogger("qpbench.report")

#: Highest PNG a figure may be [px]; :func:`save` lowers the resolution of a taller one.
MAX_HEIGHT_PX = 2000
#: Most backends highlighted in one panel.
MAX_SERIES = 8
#: Colour of the backends a panel does not highlight (context).
GREY = "#c8c8c8"
#: Markers, in the order a group's backends take them.
MARKERS = ("o", "s", "^", "v", "D", "P", "X", "*")


@dataclass(frozen=True)
class Look:
    """How one backend is drawn: ``colour`` (hex), ``marker`` (matplotlib), ``linestyle``."""

    colour: str
    marker: str
    linestyle: str

    def line(self, x=None, **extra) -> dict:
        """Keyword arguments of ``Axes.plot`` (``extra`` added or overriding); markers at
        :func:`marks` of ``x``, shifted by marker (coinciding lines each show theirs); without
        ``x`` none on the line (its legend entry still shows one)."""
        kw = {"color": self.colour, "ls": self.linestyle, "marker": self.marker, "ms": 4.5}
        phase = (MARKERS.index(self.marker) + 0.5) / len(MARKERS)
        kw["markevery"] = [] if x is None else marks(x, phase)
        kw["markerfacecolor"] = "white" if self.linestyle != "-" else self.colour
        return kw | extra


#: Markers along a line (:meth:`Look.line`).
MARKS = 10


def marks(x, phase: float = 0.5) -> list[int]:
    """Indices of the points of ``x`` nearest to :data:`MARKS` values, the ``k``-th at
    ``(k + phase) / MARKS`` of the way from the smallest to the largest."""
    import numpy as np

    x = np.asarray(x, dtype=float)
    ok = np.flatnonzero(np.isfinite(x))
    if ok.size == 0:
        return []
    lo, hi = x[ok].min(), x[ok].max()
    wanted = lo + (hi - lo) * (np.arange(MARKS) + phase) / MARKS
    idx = ok[np.argmin(np.abs(x[ok][None, :] - wanted[:, None]), axis=1)]
    return sorted({int(i) for i in idx})


def _table() -> dict[str, Look]:
    own = {  # own-API QP solvers: solid lines
        "daqp": "#1f77b4",
        "daqp-stateless": "#8c564b",
        "qpoases": "#ff7f0e",
        "osqp": "#2ca02c",
        "proxqp": "#d62728",
        "clarabel": "#9467bd",
        "piqp": "#e377c2",
        "cvxpy": "#808000",
    }
    other = {  # the network and the pseudo-inverse: dash-dot
        "rnn-tuned": "#000000",
        "rnn": "#f0a30a",
        "rnn-converged": "#17becf",
        "pinv": "#a0522d",
    }
    routes = {  # qpsolvers routes: dashed, hollow markers
        "qpsolvers:daqp": "#003f5c",
        "qpsolvers:quadprog": "#00a087",
        "qpsolvers:osqp": "#005a32",
        "qpsolvers:clarabel": "#5e3c99",
        "qpsolvers:proxqp": "#8b0000",
        "qpsolvers:piqp": "#c51b7d",
        "qpsolvers:highs": "#b8860b",
        "qpsolvers:scs": "#6b8e23",
        "qpsolvers:qpalm": "#4682b4",
        "qpsolvers:ecos": "#dc143c",
        "qpsolvers:cvxopt": "#d2691e",
        "qpsolvers:gurobi": "#2f4f4f",
        "qpsolvers:mosek": "#9932cc",
        "qpsolvers:qpoases": "#ff4500",
        "qpsolvers:hpipm": "#20b2aa",
        "qpsolvers:sip": "#556b2f",
    }
    out = {}
    for colours, ls in ((own, "-"), (other, "-."), (routes, "--")):
        for i, (name, colour) in enumerate(colours.items()):
            out[name] = Look(colour, MARKERS[i % len(MARKERS)], ls)
    return out


#: The look of every backend this package knows (colours distinct from one another and from
#: :data:`GREY`).
LOOKS: dict[str, Look] = _table()
#: Colours of backends :data:`LOOKS` does not name, picked by a stable hash of the name.
SPARE = (
    "#e6194b",
    "#3cb44b",
    "#4363d8",
    "#f58231",
    "#911eb4",
    "#f032e6",
    "#469990",
    "#9a6324",
    "#800000",
    "#000075",
    "#808080",
    "#6a5acd",
)


def look(backend: str) -> Look:
    """The look of ``backend``: :data:`LOOKS`, else a stable pick from :data:`SPARE` by name."""
    name = str(backend)
    if name in LOOKS:
        return LOOKS[name]
    h = zlib.crc32(name.encode())
    return Look(SPARE[h % len(SPARE)], MARKERS[(h // len(SPARE)) % len(MARKERS)], ":")


def _kind(backend: str) -> int:
    """0: own-API QP solvers, 1: the network and the pseudo-inverse, 2: qpsolvers routes, 3: others."""
    name = str(backend)
    if name.startswith("qpsolvers:"):
        return 2
    if name.startswith("rnn") or name == "pinv":
        return 1
    return 0 if name in LOOKS else 3


_KIND_TITLES = (
    "QP solvers (own API)",
    "network and pseudo-inverse",
    "qpsolvers routes",
    "other backends",
)


def _order(backend: str) -> tuple:
    names = list(LOOKS)
    return (names.index(backend), "") if backend in LOOKS else (len(names), str(backend))


def groups(backends: Iterable[str], max_series: int = MAX_SERIES) -> list[tuple[str, list[str]]]:
    """``backends`` split into panels of at most ``max_series``: ``[(title, names), ...]``; a
    kind (:data:`_KIND_TITLES`) shares a panel, cut into equal parts when too many. All in one
    panel: one group titled ``""``."""
    names = sorted(dict.fromkeys(str(b) for b in backends), key=_order)
    if len(names) <= max_series:
        return [("", names)] if names else []
    out = []
    for kind, title in enumerate(_KIND_TITLES):
        members = [b for b in names if _kind(b) == kind]
        parts = -(-len(members) // max_series)
        for p in range(parts):
            out.append((f"{title} ({p + 1}/{parts})" if parts > 1 else title, members[p::parts]))
    return out


def highlighted(everyone: Iterable[str], group: Iterable[str]) -> Iterator[tuple[str, bool]]:
    """``(backend, highlighted)`` for every backend: the grey rest first (drawn below), then ``group``."""
    group = list(group)
    yield from ((b, False) for b in everyone if b not in group)
    yield from ((b, True) for b in group)


def series(backend: str, lit: bool, x, lw: float, grey_lw: float) -> dict:
    """Keyword arguments of ``Axes.plot`` of one backend's series over ``x``: in its look and
    named in the legend when ``lit``, else grey behind the others."""
    if lit:
        return look(backend).line(x, lw=lw, label=backend, zorder=3)
    return dict(color=GREY, lw=grey_lw, zorder=1)


def subplots(rows: int, cols: int, width: float, height: float, **kw):
    """``(fig, axes)``: a ``rows`` by ``cols`` grid (always 2-d), ``width`` by ``height`` [in],
    constrained layout."""
    kw |= dict(squeeze=False, layout="constrained")
    return pyplot().subplots(rows, cols, figsize=(width, height), **kw)


def panels(backends, rows: int, width: float, height: float, pad=(0.8, 1.6), **kw):
    """``(fig, axes, groups)``: ``rows`` rows of panels, a column per group of backends
    (:func:`groups`), each ``width`` by ``height`` [in] plus ``pad`` (width, height) [in]."""
    cols = groups(backends)
    size = (width * len(cols) + pad[0], height * rows + pad[1])
    return (*subplots(rows, len(cols), *size, **kw), cols)


def entries(axes, skip=()) -> tuple[list, list]:
    """The legend handles and labels of every axes of ``axes`` in turn, but those labelled as
    one of ``skip``."""
    pairs = [
        (h, t) for ax in axes for h, t in zip(*ax.get_legend_handles_labels()) if t not in skip
    ]
    return [h for h, _ in pairs], [t for _, t in pairs]


def legend_above(ax, handles=None, labels=None, ncol: int = 2, title: str = "", **kw):
    """A legend above ``ax``, outside the data (``handles``/``labels``: the axes' own by default),
    under a small ``title`` (none when empty)."""
    where = dict(loc="lower left", bbox_to_anchor=(0.0, 1.02, 1.0, 0.2), mode="expand", ncol=ncol)
    where |= dict(title=title or None, title_fontsize=8)
    return legend_beside(ax, handles, labels, **({"fontsize": 7.5} | where | kw))


def legend_beside(ax, handles=None, labels=None, **kw):
    """A legend to the right of ``ax``, outside the data, frameless; ``None`` without entries."""
    if handles is None:
        handles, labels = ax.get_legend_handles_labels()
    if not handles:
        return None
    where = dict(loc="upper left", bbox_to_anchor=(1.02, 1.0), fontsize=8)
    return ax.legend(handles, labels, frameon=False, borderaxespad=0.0, **(where | kw))


def pyplot():
    """``matplotlib.pyplot`` on the Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg", force=True)
    import matplotlib.pyplot as plt

    return plt


def save(fig, path: str | Path, dpi: float = 110) -> Path:
    """Write ``fig`` to ``path`` atomically (format from the suffix) and close it; a PNG taller
    than :data:`MAX_HEIGHT_PX` again at the resolution that fits. A constrained layout with
    equal axes is written in its tight box (its legend was placed before the aspect shrank them)."""
    from matplotlib.layout_engine import ConstrainedLayoutEngine
    from PIL import Image

    from ..atomic import atomic_path

    path = Path(path)
    fmt = path.suffix.lstrip(".").lower() or "png"
    laid_out = isinstance(fig.get_layout_engine(), ConstrainedLayoutEngine)
    free_aspect = all(ax.get_aspect() == "auto" for ax in fig.axes)
    bbox = None if laid_out and free_aspect else "tight"
    try:
        with atomic_path(path) as tmp:  # never a half-written figure under the final name
            fig.savefig(tmp, format=fmt, dpi=dpi, bbox_inches=bbox)
            height = 0
            if fmt == "png":
                with Image.open(tmp) as img:
                    height = img.size[1]
            if height > MAX_HEIGHT_PX:
                fitted = dpi * (MAX_HEIGHT_PX - 1) / height
                msg = "%s: figure %d px tall at %g dpi, over %d px; written at %.0f dpi"
                log.warning(msg, path, height, dpi, MAX_HEIGHT_PX, fitted)
                fig.savefig(tmp, format=fmt, dpi=fitted, bbox_inches=bbox)
    finally:
        pyplot().close(fig)
    return path

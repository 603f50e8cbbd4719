"""Outputs written atomically (a temporary name in the folder renamed into place: a killed
run never leaves a truncated file), checked before a run, and listed when a command ends
(files of worker processes are recorded by the process that receives their rows)."""

from __future__ import annotations

import contextlib
import os
import secrets
import shutil
from pathlib import Path
from typing import TYPE_CHECKING

from .exceptions import OutputExistsError, ParamError

if TYPE_CHECKING:
    from collections.abc import Callable, Iterator


#: Files written since :func:`recording` started, in the order first written (``None``: not recording).
_written: dict[Path, None] | None = None


@contextlib.contextmanager
def recording() -> Iterator[Callable[[], list[Path]]]:
    """Record the outputs written inside the ``with`` block; yields a function that lists
    those that exist (absolute paths, in the order first written)."""
    global _written
    _written = mine = {}
    try:
        yield lambda: [p for p in mine if p.is_file()]
    finally:
        _written = None


def record(path: str | Path) -> None:
    """Note ``path`` as an output of this command (nothing happens when not recording)."""
    if _written is not None:
        _written[Path(os.path.abspath(path))] = None


def rename(src: str | Path, dst: str | Path) -> None:
    """:func:`os.replace` ``src`` by ``dst``; recorded files under ``src`` are now under ``dst``."""
    os.replace(src, dst)
    if _written:
        src, dst = Path(os.path.abspath(src)), Path(os.path.abspath(dst))
        moved = [dst / p.relative_to(src) if p == src or src in p.parents else p for p in _written]
        _written.clear()
        _written.update(dict.fromkeys(moved))


def listing(paths: list[Path], cwd: str | Path | None = None, most: int = 3) -> str:
    """``wrote: a.csv, out/report.md, out/logs/ (20 files)``: paths relative to ``cwd`` where
    they are under it; a folder holding more than ``most`` of them is named once with its count."""
    cwd = Path(os.path.abspath(cwd or os.getcwd()))

    def shown(p: Path) -> str:
        return str(p.relative_to(cwd)) if cwd in p.parents else str(p)

    by_folder: dict[Path, list[Path]] = {}
    for p in paths:
        by_folder.setdefault(p.parent, []).append(p)
    parts: list[str] = []
    for folder, files in by_folder.items():
        if len(files) > most:
            parts.append(f"{shown(folder / 'x')[:-1]} ({len(files)} files)")
        else:
            parts += [shown(p) for p in files]
    return "wrote: " + ", ".join(parts)


@contextlib.contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside ``path``, renamed to ``path`` on success (removed,
    ``path`` untouched, on an exception)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{secrets.token_hex(8)}.tmp")  # made by the writer
    try:
        yield tmp
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
        record(path)
    finally:
        tmp.unlink(missing_ok=True)


def write_text(path: str | Path, text: str) -> None:
    """Write ``text`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def write_bytes(path: str | Path, data: bytes) -> None:
    """Write ``data`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def check_folder(path: str | Path, key: str = "out") -> None:
    """An output folder may exist or not, but its parent must (:func:`check_output`)."""
    check_output(path, force=True, kind="dir", key=key)


def check_output(
    path: str | Path,
    force: bool = False,
    resume: bool | None = None,
    kind: str = "file",
    make_parent: bool = False,
    key: str = "out",
) -> None:
    """Check an output before anything is written: a ``kind`` (``file``, ``dir``) or nothing, its
    parent present unless ``make_parent`` (else :class:`ParamError`), existing only with
    ``force`` or ``resume`` (``None``: no ``--resume``; else :class:`OutputExistsError`)."""
    path = Path(path)
    if kind == "file" and path.is_dir():
        raise ParamError(f"{path}: is a folder; expected a file name", key=key)
    parent = path.parent
    for folder in [path, parent] if kind == "dir" else [parent]:
        if folder.exists() and not folder.is_dir():
            raise ParamError(f"{folder}: is a file; expected a folder", key=key)
    if not parent.exists() and not make_parent:
        raise ParamError(f"{path}: parent folder {parent} does not exist; create it first", key=key)
    if path.exists() and not (force or resume):
        or_resume = "" if resume is None else " or --resume to continue"
        raise OutputExistsError(f"{path}: exists; pass --force to overwrite{or_resume}")


def promote(staging: Path, out: Path, names) -> None:
    """Replace the outputs ``names`` in ``out`` by those in ``staging``, one rename each, and
    remove ``staging``: a reader sees the previous outputs or the new ones."""
    for name in names:
        src = staging / name
        dst = out / name
        if not src.exists():
            continue
        old = out / f".old-{name}"
        shutil.rmtree(old, ignore_errors=True)
        if src.is_dir() and dst.exists():
            os.replace(dst, old)
        rename(src, dst)
        shutil.rmtree(old, ignore_errors=True)
    shutil.rmtree(staging, ignore_errors=True)

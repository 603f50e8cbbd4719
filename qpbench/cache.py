"""Where qpbench keeps what it compiles (numba's kernels, native shims): one rule
(:func:`cache_root`), so a worker, a second run and a test find what the first compile left.
"""

from __future__ import annotations

import os
from pathlib import Path

#: The installed package's folder.
PACKAGE_DIR = Path(__file__).resolve().parent


def writable(folder: Path) -> bool:
    """``folder`` exists (made if missing), may be written and has a write bit (none at all:
    a shared data folder, even for root, who may write anywhere)."""
    try:
        folder.mkdir(parents=True, exist_ok=True)
        return os.access(folder, os.W_OK) and bool(folder.stat().st_mode & 0o222)
    except OSError:
        return False


def user_cache_dir() -> Path:
    """``$XDG_CACHE_HOME/qpbench``, default ``~/.cache/qpbench``."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "qpbench"


def cache_root() -> Path:
    """The folder compiled artefacts go to: ``$NUMBA_CACHE_DIR``; else the package folder's
    ``__cache__`` when writable; else :func:`user_cache_dir`."""
    env, local = os.environ.get("NUMBA_CACHE_DIR"), PACKAGE_DIR / "__cache__"
    return Path(env) if env else local if writable(local) else user_cache_dir()


def configure_numba_cache() -> None:
    """Set ``NUMBA_CACHE_DIR`` (inherited by workers) to :func:`user_cache_dir` / ``numba`` when
    unset and the package folder is not writable (numba's default: beside the sources)."""
    if not os.environ.get("NUMBA_CACHE_DIR") and not writable(PACKAGE_DIR / "__pycache__"):
        folder = user_cache_dir() / "numba"
        folder.mkdir(parents=True, exist_ok=True)
        os.environ["NUMBA_CACHE_DIR"] = str(folder)

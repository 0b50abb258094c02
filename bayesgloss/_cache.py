"""Tables that are the same on every run, kept in the user's cache folder.

A table that costs seconds to compute and depends only on its arguments
(e.g. :func:`bayesgloss.pooling._beta_bin_masses`) is computed once per
machine and read back by every later process. The folder is
``$BAYESGLOSS_CACHE_DIR``, else ``$XDG_CACHE_HOME/bayesgloss``, else
``~/.cache/bayesgloss``; ``BAYESGLOSS_CACHE_DIR=""`` turns the cache off.
A file is named by its table, its arguments and a version, written to a
temporary name and renamed (two processes may write it at once), and read
back only if its shape and type are the ones expected; a folder that cannot
be written, or a file that cannot be read, costs only the computation.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path

import numpy as np

__all__ = ["cache_dir", "cached_array"]


def cache_dir() -> Path | None:
    """The cache folder (module docstring), or None when it is turned off."""
    env = os.environ.get("BAYESGLOSS_CACHE_DIR")
    if env is not None:
        return Path(env) if env else None
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "bayesgloss"


def cached_array(
    name: str, shape: tuple[int, ...], dtype, compute: Callable[[], np.ndarray]
) -> np.ndarray:
    """The array ``compute()`` returns, read from ``<cache>/<name>.npy`` when
    a file of that ``shape`` and ``dtype`` is there, else computed and written
    there (best effort: failures to read or write are not errors)."""
    folder = cache_dir()
    path = None if folder is None else folder / f"{name}.npy"
    if path is not None and path.is_file():
        try:
            out = np.load(path, allow_pickle=False)
            if out.shape == tuple(shape) and out.dtype == np.dtype(dtype):
                return out
        except (OSError, ValueError):
            pass
    out = np.asarray(compute())
    if path is not None:
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            with tempfile.NamedTemporaryFile(dir=path.parent, suffix=".npy", delete=False) as f:
                np.save(f, out, allow_pickle=False)
            os.replace(f.name, path)
        except OSError:
            pass
    return out

"""Fan-out and resumable runs: local processes by default, a Dask cluster on request.

Work is cut into units (one bundle's estimate, one study replicate...). Each
unit is a pure function of its arguments (seeds included), so the numbers do
not depend on where or in which order units run. A unit's result is written
into its own folder through a temporary folder renamed into place when
complete, so a run killed at any moment leaves only finished units behind,
and a rerun skips them: nothing finished is recomputed, nothing is lost.

Executors (:func:`executor`): ``jobs`` local processes
(:func:`bayesgloss.pool.process_pool`), or, given a scheduler
address, a Dask distributed cluster through ``Client.get_executor()``
(the ``cluster`` extra: ``pip install bayesgloss[cluster]``). Units defined
in a script rather than in the package (the studies) run through
:func:`script_unit`, which workers can unpickle without the script on their
import path.
"""

from __future__ import annotations

import contextlib
import hashlib
import importlib.util
import json
import os
import shutil
import sys
import tempfile
from collections.abc import Callable, Iterable
from concurrent.futures import as_completed
from pathlib import Path

from .pool import process_pool

__all__ = ["executor", "unit_key", "run_units", "script_unit"]


@contextlib.contextmanager
def executor(jobs: int = 2, scheduler: str | None = None):
    """A concurrent.futures executor: local processes, or a Dask cluster.

    Parameters
    ----------
    jobs : int
        Local worker processes (ignored with ``scheduler``).
    scheduler : str, optional
        Address of a Dask distributed scheduler (``tcp://host:8786``), or a
        ``distributed.LocalCluster``/``Client`` object.
    """
    if scheduler is None:
        with process_pool(jobs) as pool:
            yield pool
        return
    try:
        from distributed import Client
    except ImportError as err:  # pragma: no cover - depends on the install
        raise RuntimeError(
            "a Dask scheduler was given but dask.distributed is not installed: "
            "pip install 'bayesgloss[cluster]'"
        ) from err
    own = not isinstance(scheduler, Client)
    client = Client(scheduler) if own else scheduler
    try:
        yield client.get_executor()
    finally:
        if own:
            client.close()


def unit_key(name: str, options: dict) -> str:
    """A unit's folder name: its name and a hash of its options."""
    digest = hashlib.sha256(json.dumps(options, sort_keys=True, default=str).encode())
    return f"{name}-{digest.hexdigest()[:10]}"


def _write_atomically(folder: Path, files: dict[str, bytes]) -> None:
    """Write files into ``folder`` so that it exists only when complete."""
    folder.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{folder.name}.", dir=folder.parent))
    try:
        for name, data in files.items():
            (tmp / name).write_bytes(data)
        os.replace(tmp, folder)  # atomic on one file system; fails if folder exists
    except OSError:
        shutil.rmtree(tmp, ignore_errors=True)
        if not folder.exists():
            raise


def run_units(
    func: Callable[..., dict[str, bytes]],
    units: Iterable[tuple[str, dict]],
    out_dir,
    *,
    jobs: int = 2,
    scheduler=None,
    progress: Callable[[int, int], None] | None = None,
) -> list[Path]:
    """Run ``func(**options)`` for every unit not yet finished under ``out_dir``.

    Parameters
    ----------
    func : callable
        Module-level function (picklable) returning ``{file name: bytes}``.
    units : iterable of (name, options)
    out_dir : path
    jobs, scheduler
        See :func:`executor`.
    progress : callable, optional
        Called with (units finished, units in all).

    Returns
    -------
    list of Path
        Each unit's folder, in the order given.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    units = list(units)
    folders = [out / unit_key(name, opts) for name, opts in units]
    todo = [(f, opts) for f, (_, opts) in zip(folders, units, strict=True) if not f.exists()]
    done = len(units) - len(todo)
    if progress:
        progress(done, len(units))
    if todo:
        with executor(jobs, scheduler) as ex:
            futs = {ex.submit(func, **opts): folder for folder, opts in todo}
            for fut in as_completed(futs):
                _write_atomically(futs[fut], fut.result())
                done += 1
                if progress:
                    progress(done, len(units))
    return folders


def script_unit(script: str, function: str, /, **options) -> dict[str, bytes]:
    """Call ``function(**options)`` of the Python file ``script``, on any worker.

    A function defined in a script (``python studies/study_noise.py``) is
    pickled by reference to a module that a Dask worker, or a process
    started by ``spawn``, cannot import. Pass
    ``functools.partial(script_unit, script, function)`` to
    :func:`run_units` instead: this function is importable everywhere the
    package is, and it imports the script by its path (once per process),
    with the script's folder on ``sys.path`` as when the script is run, so
    its sibling modules import too. Workers must see the script's path
    (the same machine, or a shared file system).

    Parameters
    ----------
    script : str
        Path of the Python file.
    function : str
        Name of a function of the file returning ``{file name: bytes}``.
    **options
        The unit's options, passed on.
    """
    path = Path(script).resolve()
    module = sys.modules.get(path.stem)
    if module is None or Path(getattr(module, "__file__", "") or "").resolve() != path:
        if str(path.parent) not in sys.path:
            sys.path.insert(0, str(path.parent))
        spec = importlib.util.spec_from_file_location(path.stem, path)
        if spec is None or spec.loader is None:
            raise ValueError(f"cannot import a Python module from {script!r}")
        module = importlib.util.module_from_spec(spec)
        sys.modules[path.stem] = module
        try:
            spec.loader.exec_module(module)
        except BaseException:
            del sys.modules[path.stem]
            raise
    return getattr(module, function)(**options)

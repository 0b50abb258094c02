"""Which bayesgloss a study runs: the tree on ``PYTHONPATH``, or the study stops.

A candidate is scored or probed from a worktree of its branch with
``PYTHONPATH=<worktree>`` (studies/README.md, "How a change joins it").
Whether ``PYTHONPATH`` wins depends on how bayesgloss was installed: on
stop 75's machine an editable install made with pip's default mode
imported the installed tree (main) before ``PYTHONPATH``'s, so a
candidate's run would have scored the default under the candidate's name.
An install in setuptools' compat mode (``pip install -e . --config-settings
editable_mode=compat``, a path entry after ``PYTHONPATH``'s) does not. Nor
does ``python -c`` from a checkout, whose current folder comes first.

:func:`check` makes the mismatch an error before anything is fitted.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["check", "imported_tree", "wanted_tree"]


def imported_tree() -> Path:
    """The folder holding the ``bayesgloss`` package this process imports."""
    import bayesgloss

    return Path(bayesgloss.__file__).resolve().parent.parent


def wanted_tree(pythonpath: str | None) -> Path | None:
    """The first entry of ``pythonpath`` that holds a ``bayesgloss``
    package (a folder ``bayesgloss`` with an ``__init__.py``), resolved;
    None where no entry does (or ``pythonpath`` is empty or None)."""
    for entry in (pythonpath or "").split(os.pathsep):
        if entry and (Path(entry) / "bayesgloss" / "__init__.py").is_file():
            return Path(entry).resolve()
    return None


def check(study: str, pythonpath: str | None = None) -> Path:
    """The tree of the imported bayesgloss, after checking it is the one
    ``PYTHONPATH`` names (``pythonpath``; default the environment's).

    Parameters
    ----------
    study : str
        The study's name, for the error.
    pythonpath : str, optional
        ``os.pathsep``-separated entries; default ``$PYTHONPATH``.

    Raises
    ------
    SystemExit
        Where an entry of ``PYTHONPATH`` holds a bayesgloss package and the
        imported one is another: one line naming both trees and the fix.
    """
    if pythonpath is None:
        pythonpath = os.environ.get("PYTHONPATH")
    wanted, got = wanted_tree(pythonpath), imported_tree()
    if wanted is not None and wanted != got:
        raise SystemExit(
            f"{study}: PYTHONPATH names the bayesgloss of {wanted}, but this process "
            f"imports the one of {got}: the current folder (python -c from a "
            "checkout) or an editable install is ahead of PYTHONPATH; run the study "
            "as a script from the worktree, and install with `pip install -e . "
            "--config-settings editable_mode=compat`"
        )
    return got

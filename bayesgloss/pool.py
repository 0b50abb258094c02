"""Local worker processes that end with the process that started them.

A leaf module: it imports nothing of bayesgloss, so that the samplers
(:func:`bayesgloss.sampling.sample_posterior` takes any pool with a ``map``
method, as emcee's ``EnsembleSampler`` does) and the fan-out of
:mod:`bayesgloss.runner` can both use it without importing each other.
"""

from __future__ import annotations

import os
import sys
from concurrent.futures import ProcessPoolExecutor

__all__ = ["process_pool", "shares"]


def process_pool(jobs: int) -> ProcessPoolExecutor:
    """``jobs`` local worker processes that end when the process that started
    them dies: on Linux each worker asks the kernel for SIGTERM on its
    parent's death (``prctl(PR_SET_PDEATHSIG)``), so a run killed with
    ``kill -9`` leaves no workers computing on (Ctrl-C already reaches the
    whole process group).

    Parameters
    ----------
    jobs : int
        Worker processes (at least 1).
    """
    return ProcessPoolExecutor(
        max_workers=max(1, jobs), initializer=_end_with_parent, initargs=(os.getpid(),)
    )


def _end_with_parent(parent: int) -> None:
    """Worker initializer of :func:`process_pool`."""
    if not sys.platform.startswith("linux"):
        return
    import ctypes
    import signal

    pr_set_pdeathsig = 1
    ctypes.CDLL(None, use_errno=True).prctl(pr_set_pdeathsig, int(signal.SIGTERM))
    if os.getppid() != parent:  # the parent died before the request took effect
        os._exit(1)


def shares(jobs: int, tasks: int) -> tuple[int, int]:
    """How ``jobs`` processes are split over ``tasks`` fits: (processes
    running fits at once, processes each fit gets for its own groups of
    ensembles). One fit to each process while there are more fits than
    processes; a single fit takes them all."""
    return min(jobs, tasks), max(1, jobs // max(tasks, 1))

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

__all__ = ["process_pool", "one_blas_thread", "shares"]


def process_pool(jobs: int) -> ProcessPoolExecutor:
    """``jobs`` local worker processes that end when the process that started
    them dies: on Linux each worker asks the kernel for SIGTERM on its
    parent's death (``prctl(PR_SET_PDEATHSIG)``), so a run killed with
    ``kill -9`` leaves no workers computing on (Ctrl-C already reaches the
    whole process group). Each worker runs its linear algebra on one thread
    (:func:`one_blas_thread`).

    Parameters
    ----------
    jobs : int
        Worker processes (at least 1).
    """
    return ProcessPoolExecutor(
        max_workers=max(1, jobs), initializer=_end_with_parent, initargs=(os.getpid(),)
    )


def one_blas_thread() -> None:
    """Limit this process's BLAS (numpy's OpenBLAS) to one thread.

    The workers of :func:`process_pool` already share the machine's cores
    among themselves: OpenBLAS's own threads, one per core in every process,
    wait for work by spinning, and with two processes on two cores (a
    validation run's two arms, ``--jobs 2``'s two chains) the spinning took
    two thirds of the CPU as system time (``vmstat``, stop 58), where one
    thread a process left it at none. The model's matrix products are small
    (a few facets or quadrature cells by a few frames): a second thread never
    paid for itself.
    """
    import numpy  # noqa: F401 (loads OpenBLAS, so that a spawned worker's is limited too)
    from threadpoolctl import threadpool_limits

    threadpool_limits(limits=1, user_api="blas")


def _end_with_parent(parent: int) -> None:
    """Worker initializer of :func:`process_pool`: one BLAS thread
    (:func:`one_blas_thread`), and the end with the parent."""
    one_blas_thread()
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

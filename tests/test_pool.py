"""Tests of bayesgloss.pool: the workers' BLAS threads."""

import os

import numpy  # noqa: F401 (OpenBLAS loaded, so that threadpoolctl sees it)
from threadpoolctl import threadpool_info

from bayesgloss.pool import process_pool, shares


def _blas_threads() -> list[int]:
    return [pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas"]


def test_workers_run_blas_on_one_thread():
    # numpy's OpenBLAS starts one thread per core; the workers share the
    # cores already, so each gets one (two side by side spun away two thirds
    # of the CPU as system time). The parent keeps its own setting: a
    # pool that limited every process would fail the second assertion on a
    # machine of two or more cores, one that limited none the first
    with process_pool(2) as pool:
        inside = list(pool.map(_blas_threads_of, range(2)))
    assert inside and all(threads and set(threads) == {1} for threads in inside), inside
    told = ("OPENBLAS_NUM_THREADS", "GOTO_NUM_THREADS", "OMP_NUM_THREADS")  # OpenBLAS reads these
    if (os.cpu_count() or 1) > 1 and not any(name in os.environ for name in told):
        assert max(_blas_threads()) > 1


def _blas_threads_of(_):
    return _blas_threads()


def test_shares_split_jobs_over_fits():
    assert shares(2, 4) == (2, 1)
    assert shares(2, 1) == (1, 2)
    assert shares(1, 3) == (1, 1)

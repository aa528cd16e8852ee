"""One BLAS thread while the library computes, unless the user chose a number.

Our matrices are small: JᵀJ of a few dozen parameters, a multiple-shooting normal matrix of a few hundred.
Threaded BLAS gains little on them and, on a machine whose cores are busy (a test suite, a second fit,
``--workers``), its threads wait for each other: one 774 x 774 Cholesky factorisation took 0.4-1.1 s with
OpenBLAS's default threads and 0.010 s with one thread, on 2 cores with one of them busy. The command line
sets the environment variables before numpy loads (:mod:`flowchart2sdnn.cli`); a notebook has numpy loaded
already, so the library limits the threads at run time with threadpoolctl, around each public computation
only (the user's own numpy work keeps its threads).
"""

from __future__ import annotations

import contextlib
import functools
import os

__all__ = ["THREAD_VARIABLES", "one_blas_thread", "blas_threads"]

#: the variables by which a user chooses BLAS's threads; any of them set: the library leaves threads alone
THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def blas_threads():
    """A context in which BLAS runs on one thread (nothing when the user set a thread variable, or without
    threadpoolctl)."""
    if any(os.environ.get(v) for v in THREAD_VARIABLES):
        return contextlib.nullcontext()
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:  # an install without the dependency: threads as they are
        return contextlib.nullcontext()
    return threadpool_limits(limits=1, user_api="blas")


def one_blas_thread(function):
    """`function` run with :func:`blas_threads`."""

    @functools.wraps(function)
    def limited(*args, **kwargs):
        with blas_threads():
            return function(*args, **kwargs)

    return limited

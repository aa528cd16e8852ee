"""Where work runs: in this process, in local worker processes, or on a Dask cluster.

Layer: bottom. This module imports nothing of ours but :mod:`flowchart2sdnn.errors`; the work units it runs
(fitting one start, identifying one log file) live with the code they belong to and reach it as plain
picklable callables.

Every executor has the same small interface (:class:`Executor`): ``map`` (results in input order, as
:func:`~flowchart2sdnn.fit.multistart.run_multistart` consumes them), ``submit`` and ``as_completed`` (for
work whose results may arrive in any order, as in ``sdnn batch``), and ``close``. Choose one with
:func:`make_executor`:

* ``workers=None`` (or 1) and no scheduler: :class:`SerialExecutor`, everything in this process;
* ``workers=N``: :class:`ProcessExecutor`, N local processes started with the "forkserver" method (or
  "spawn" where there is no forkserver): numba-compiled code and threads do not survive a plain fork
  reliably, and a forkserver that has already imported the package starts workers in milliseconds;
* ``scheduler=ADDRESS``: :class:`DaskExecutor` on a running Dask scheduler (``tcp://host:8786``), or
  ``"local"`` for a :class:`distributed.LocalCluster` of ``workers`` processes on this machine. Dask is an
  optional extra (``pip install flowchart2sdnn[dask]``) and must be installed on the workers too.

Workers ignore SIGINT: Ctrl-C interrupts the parent, which stops collecting results and shuts the
workers down (:meth:`Executor.close` with ``cancel=True``).
"""

from __future__ import annotations

import concurrent.futures as cf
import dataclasses
import multiprocessing
import os
import signal
from collections.abc import Callable, Iterable, Iterator
from typing import Any

import numpy as np

from .errors import SdnnError

__all__ = [
    "Executor",
    "SerialExecutor",
    "ProcessExecutor",
    "DaskExecutor",
    "make_executor",
    "start_method",
    "DASK_HINT",
]

DASK_HINT = "pip install flowchart2sdnn[dask]"
#: Modules the forkserver imports once, so that every worker starts with the package and its kernels loaded
#: (names only: this module imports none of them).
PRELOAD = ("flowchart2sdnn.api",)


# ------------------------------------------------------------------------------------------------ results
def _freeze(obj: Any) -> Any:
    """Make the array fields of a frozen dataclass read-only again (pickling drops the flag)."""
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        for f in dataclasses.fields(obj):
            value = getattr(obj, f.name, None)
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
    return obj


class _DoneFuture(cf.Future):
    """A future that is already finished (what SerialExecutor.submit returns)."""

    def __init__(self, fn: Callable, args: tuple):
        super().__init__()
        try:
            self.set_result(fn(*args))
        except KeyboardInterrupt:
            raise
        except BaseException as exc:  # noqa: BLE001 - delivered through .result() like a real future
            self.set_exception(exc)


# ------------------------------------------------------------------------------------------------ executors
class Executor:
    """Common interface of the executors (use :func:`make_executor`).

    Attributes
    ----------
    kind : str
        "serial", "processes" or "dask".
    workers : int
        Number of workers (1 for serial; for Dask the number connected when the client started).
    """

    kind = "serial"
    workers = 1

    def map(self, fn: Callable, items: Iterable) -> Iterator:
        """``fn(item)`` for every item, yielded in input order."""
        raise NotImplementedError

    def submit(self, fn: Callable, *args) -> Any:
        """Start ``fn(*args)``; returns a future with ``.result()``, ``.exception()`` and ``.cancel()``."""
        raise NotImplementedError

    def as_completed(self, futures: Iterable) -> Iterator:
        """The futures as they finish."""
        raise NotImplementedError

    def result(self, future) -> Any:
        """The value of a finished future (array fields of dataclass results made read-only)."""
        return _freeze(future.result())

    def close(self, cancel: bool = False) -> None:
        """Release the workers; ``cancel=True`` drops queued work and stops running work if possible."""

    def describe(self) -> str:
        return "serial (this process)"

    def __enter__(self) -> Executor:
        return self

    def __exit__(self, exc_type, exc, tb) -> None:
        self.close(cancel=exc_type is not None)


class SerialExecutor(Executor):
    """Runs everything in the calling process, in order."""

    def map(self, fn: Callable, items: Iterable) -> Iterator:
        return map(fn, items)

    def submit(self, fn: Callable, *args) -> cf.Future:
        return _DoneFuture(fn, args)

    def as_completed(self, futures: Iterable) -> Iterator:
        return iter(list(futures))


def _worker_init(extra: Callable[[], None] | None) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if extra is not None:
        extra()


def start_method() -> str:
    """"forkserver" where the platform has it (Linux, macOS), else "spawn"; never a plain fork."""
    return "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"


class ProcessExecutor(Executor):
    """``workers`` local processes (:class:`concurrent.futures.ProcessPoolExecutor`, forkserver or spawn).

    Parameters
    ----------
    workers : int
        Number of processes (>= 1).
    method : str, optional
        Start method, default :func:`start_method`.
    initializer : callable, optional
        Run once in each worker when it starts (module-level, picklable), e.g. to limit BLAS threads.
    """

    kind = "processes"

    def __init__(self, workers: int, method: str | None = None, initializer: Callable[[], None] | None = None):
        if not isinstance(workers, int) or workers < 1:
            raise ValueError(f"`workers` must be an int >= 1, got {workers!r}")
        self.workers = workers
        self.method = method or start_method()
        ctx = multiprocessing.get_context(self.method)
        if self.method == "forkserver":
            # the server imports the package once; every worker forks from it with numba and the kernels loaded
            ctx.set_forkserver_preload(list(PRELOAD))
        self._pool = cf.ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_worker_init,
                                            initargs=(initializer,))

    def map(self, fn: Callable, items: Iterable) -> Iterator:
        futures = [self._pool.submit(fn, item) for item in items]
        try:
            for f in futures:
                yield self.result(f)
        finally:
            for f in futures:
                f.cancel()

    def submit(self, fn: Callable, *args) -> cf.Future:
        return self._pool.submit(fn, *args)

    def as_completed(self, futures: Iterable) -> Iterator:
        return cf.as_completed(list(futures))

    def close(self, cancel: bool = False) -> None:
        processes = list((getattr(self._pool, "_processes", None) or {}).values())
        self._pool.shutdown(wait=not cancel, cancel_futures=cancel)
        if cancel:
            # running fits cannot be cancelled through the pool: stop our own worker processes
            for p in processes:
                if p.is_alive():
                    p.terminate()
            for p in processes:
                p.join(timeout=5)

    def describe(self) -> str:
        return f"{self.workers} local worker process(es) ({self.method})"


def _import_distributed():
    try:
        import distributed
    except ImportError:
        raise SdnnError.at("EXE001", f"--scheduler needs Dask distributed, which is not installed: {DASK_HINT}",
                           hint=DASK_HINT) from None
    return distributed


class DaskExecutor(Executor):
    """Work on a Dask cluster.

    Parameters
    ----------
    scheduler : str, optional
        The scheduler's address (``tcp://host:8786``), or "local" for a LocalCluster of ``workers`` single-threaded
        processes on this machine.
    workers : int, optional
        Size of the local cluster (default: the number of CPUs).
    client : distributed.Client, optional
        Use this client instead (it is not closed by :meth:`close`).
    """

    kind = "dask"

    def __init__(self, scheduler: str | None = None, workers: int | None = None, client=None):
        distributed = _import_distributed()
        self._distributed = distributed
        self._own_client = client is None
        self._cluster = None
        if client is None:
            if not scheduler:
                raise ValueError("give a scheduler address or a client")
            try:
                if scheduler == "local":
                    n = workers or os.cpu_count() or 1
                    self._cluster = distributed.LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                                             dashboard_address=None)
                    client = distributed.Client(self._cluster)
                else:
                    client = distributed.Client(scheduler, timeout="20s")
            except (OSError, TimeoutError) as exc:
                raise SdnnError.at("EXE002", f"cannot reach the Dask scheduler at {scheduler}: {exc}",
                                   hint="start one with 'dask scheduler' and workers with 'dask worker ADDRESS'"
                                   ) from None
        self.client = client
        self.address = getattr(getattr(client, "scheduler", None), "address", None) or scheduler
        self.workers = max(1, len(client.scheduler_info().get("workers", {})))

    def map(self, fn: Callable, items: Iterable) -> Iterator:
        futures = self.client.map(fn, list(items), pure=False)
        try:
            for f in futures:
                yield self.result(f)
        finally:
            self.client.cancel(futures)

    def submit(self, fn: Callable, *args):
        return self.client.submit(fn, *args, pure=False)

    def as_completed(self, futures: Iterable) -> Iterator:
        return iter(self._distributed.as_completed(list(futures)))

    def close(self, cancel: bool = False) -> None:
        if self._own_client:
            self.client.close()
            if self._cluster is not None:
                self._cluster.close()

    def describe(self) -> str:
        return f"Dask scheduler {self.address} ({self.workers} worker(s))"


def make_executor(workers: int | None = None, scheduler: str | None = None) -> Executor:
    """The executor for ``--workers N`` / ``--scheduler ADDRESS`` (serial when neither is given).

    Parameters
    ----------
    workers : int, optional
        Local worker processes; with ``scheduler="local"`` the size of the local Dask cluster.
    scheduler : str, optional
        A Dask scheduler address, or "local".

    Raises
    ------
    SdnnError
        EXE001 when a scheduler is asked for and Dask is not installed, EXE002 when it cannot be reached.
    """
    if workers is not None and workers < 1:
        raise ValueError(f"`workers` must be >= 1, got {workers}")
    if scheduler:
        return DaskExecutor(scheduler, workers=workers)
    if workers is None or workers == 1:
        return SerialExecutor()
    return ProcessExecutor(workers)

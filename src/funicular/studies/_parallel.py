"""Run a study's independent tasks: in this process, in processes on this machine, or on a Dask cluster.

A task is a picklable top-level function applied to one small argument; :meth:`Pool.run` returns
the results in the order of the tasks, whatever order they finish in, so a study that combines
them in that order gets the same answer however they ran.

A worker process that dies (killed, out of memory) loses only the task it was running. On this
machine every worker process is a pool of its own (a ``ProcessPoolExecutor`` with one process:
when its process dies the pool breaks, and only the task it was running is in it), so the task
is known; it is tried once more in a fresh process and, if that dies too, its result is
:class:`Lost`. On a Dask cluster the scheduler reschedules the task of a dead worker itself (up to
its ``distributed.scheduler.allowed-failures`` setting) and then reports ``KilledWorker``: the
result is :class:`Lost` as well.
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import pickle
import signal
from collections import deque
from collections.abc import Callable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from typing import Any, TypeVar

from funicular._extras import InstallHint
from funicular.errors import ParameterError, shown

T = TypeVar("T")
R = TypeVar("R")

CONNECT_TIMEOUT = 10.0  # seconds to wait for a Dask scheduler to answer
ATTEMPTS = 2  # a task whose local worker process dies is tried once more
CLUSTER_EXTRA = InstallHint("cluster")


@dataclass(frozen=True)
class Lost:
    """The result of a task whose worker died on every attempt: what happened, as a sentence."""

    message: str


WORKER_DIED = Lost("its worker process died, and so did the one it was retried in")


def available_cpus() -> int:
    """The CPUs this process may run on (its affinity mask where the system has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # macOS and Windows have no affinity masks
        return os.cpu_count() or 1


def _ignore(index: int, result: object) -> None:
    """The default ``on_done``."""


class Pool:
    """Where tasks run: ``processes`` local processes (1: this process), or the Dask ``client``'s cluster.

    Make one with :func:`open_pool` and close it (``with``) when done; ``Pool()`` runs everything
    in this process.
    """

    def __init__(self, processes: int = 1, client: Any = None) -> None:
        self.processes = processes
        self.client = client

    def __enter__(self) -> Pool:
        return self

    def __exit__(self, *exc_info: object) -> None:
        if self.client is not None:
            self.client.close()

    def runs_here(self, tasks: int) -> bool:
        """Whether ``tasks`` tasks would run in this process (one process, or a single local task)."""
        return self.client is None and (self.processes == 1 or tasks <= 1)

    def run(
        self,
        function: Callable[[T], R],
        tasks: Sequence[T],
        on_done: Callable[[int, R | Lost], None] = _ignore,
    ) -> list[R | Lost]:
        """``[function(task) for task in tasks]``, each result a :class:`Lost` if its worker died;
        ``on_done(index, result)`` as each task finishes."""
        if self.client is not None:
            return _run_on_cluster(self.client, function, tasks, on_done)
        if self.runs_here(len(tasks)):
            results: list[R | Lost] = []
            for index, task in enumerate(tasks):
                results.append(function(task))
                on_done(index, results[-1])
            return results
        return _run_in_processes(function, tasks, self.processes, on_done)


def open_pool(workers: int | None = None, scheduler: str | None = None) -> Pool:
    """A :class:`Pool` of ``workers`` local processes (default: one per available CPU), or of the Dask
    cluster whose scheduler is at ``scheduler`` (connected here, so that a wrong address fails
    before any work). A ParameterError, naming ``workers`` or ``scheduler``, for a bad setting."""
    if scheduler is None:
        processes = available_cpus() if workers is None else workers
        if processes < 1:
            raise ParameterError(
                f"workers {processes} is too few; give 1 or more processes (1: solve in this process).", key="workers"
            )
        return Pool(processes=processes)
    if workers is not None:
        raise ParameterError(
            f"workers {workers}: with a scheduler the cluster's workers do the solves; give one of the two.",
            key="workers",
        )
    return Pool(client=_connect(scheduler))


def _connect(scheduler: str) -> Any:
    try:
        from distributed import Client
    except ImportError:
        raise ParameterError(
            f"scheduler {scheduler}: a Dask cluster needs dask.distributed, which is not installed; {CLUSTER_EXTRA}.",
            key="scheduler",
        ) from None
    try:
        return Client(scheduler, timeout=CONNECT_TIMEOUT)  # type: ignore[no-untyped-call]
    except ValueError:
        raise ParameterError(
            f"scheduler {shown(scheduler)} is not an address; give one like tcp://10.0.0.5:8786.", key="scheduler"
        ) from None
    except OSError:  # (a timeout is one)
        raise ParameterError(
            f"scheduler {scheduler}: no Dask scheduler answered within {CONNECT_TIMEOUT:g} s; check the address, "
            "that `dask scheduler` runs there and that its port is open.",
            key="scheduler",
        ) from None


def _ignore_interrupts() -> None:
    """Ctrl-C reaches the workers too; the funicular process handles it (it ends them), so they
    need not print tracebacks of their own."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def _run_in_processes(
    function: Callable[[T], R], tasks: Sequence[T], processes: int, on_done: Callable[[int, R | Lost], None]
) -> list[R | Lost]:
    context = multiprocessing.get_context("spawn")  # a fork of a process with threads can deadlock
    results: dict[int, R | Lost] = {}
    queue = deque(range(len(tasks)))
    deaths = [0] * len(tasks)
    running: dict[Future[R], tuple[int, ProcessPoolExecutor]] = {}
    idle: list[ProcessPoolExecutor] = []
    finished = False
    try:
        while queue or running:
            while queue and len(running) < processes:
                index = queue.popleft()
                pool = idle.pop() if idle else ProcessPoolExecutor(1, context, _ignore_interrupts)
                running[pool.submit(function, tasks[index])] = (index, pool)
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            for future in done:
                index, pool = running.pop(future)
                try:
                    result: R | Lost = future.result()
                except BrokenProcessPool:  # this pool's one process died: only this task was in it
                    pool.shutdown()
                    deaths[index] += 1
                    if deaths[index] < ATTEMPTS:
                        queue.appendleft(index)
                        continue
                    result = WORKER_DIED
                else:
                    idle.append(pool)
                results[index] = result
                on_done(index, result)
        finished = True
    finally:
        for pool in [*idle, *(pool for _, pool in running.values())]:
            if not finished:  # interrupted, or a task raised: the other results will not be used
                for process in list((pool._processes or {}).values()):
                    process.terminate()
            pool.shutdown(cancel_futures=True)
    return [results[index] for index in range(len(tasks))]


def _call_pickled(function: Callable[[T], R], task: bytes) -> bytes:
    """``function`` applied to a pickled task, its result pickled.

    Dask's own transfer of numpy arrays can leave them unaligned in memory, which the solver core
    rejects; arrays unpickled from bytes are fresh copies (the same values, bit for bit).
    """
    return pickle.dumps(function(pickle.loads(task)))


def _run_on_cluster(
    client: Any, function: Callable[[T], R], tasks: Sequence[T], on_done: Callable[[int, R | Lost], None]
) -> list[R | Lost]:
    from distributed import as_completed
    from distributed.scheduler import KilledWorker

    futures = [client.submit(_call_pickled, function, pickle.dumps(task), pure=False) for task in tasks]
    position = {future.key: index for index, future in enumerate(futures)}
    results: dict[int, R | Lost] = {}
    try:
        for future in as_completed(futures):  # type: ignore[no-untyped-call]
            index = position[future.key]
            try:
                result: R | Lost = pickle.loads(future.result())
            except KilledWorker:
                result = Lost("the Dask workers running it died, as many times as the scheduler allows")
            results[index] = result
            on_done(index, result)
    finally:
        client.cancel(futures)  # interrupted: leave nothing running on the cluster
    return [results[index] for index in range(len(tasks))]


# --------------------------------------------------------------------------- command line
def add_parallel_arguments(parser: argparse.ArgumentParser) -> None:
    """``--workers K`` and ``--scheduler ADDRESS``, for the studies that solve in parallel."""
    parser.add_argument(
        "--workers",
        type=int,
        metavar="K",
        help="solve in K processes on this machine (default: one per available CPU; 1: in this process)",
    )
    parser.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="solve on the Dask cluster whose scheduler is at ADDRESS, e.g. tcp://10.0.0.5:8786 "
        f"(needs dask.distributed: {CLUSTER_EXTRA})",
    )


def pool_for(args: argparse.Namespace) -> Pool:
    """:func:`open_pool` from ``--workers`` and ``--scheduler``, its errors naming the options."""
    try:
        return open_pool(args.workers, args.scheduler)
    except ParameterError as error:
        raise error.renamed(f"--{error.key}") from None

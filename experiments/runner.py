"""Where an experiment's runs run: the local worker pool, or a Dask distributed cluster.

Every experiment script hands its runs to `run`: one job in, one result out, each run a
task of its own that carries what it needs (its layout or scenario, its seed, its agent).
By default the tasks go to the local pool (`experiments/workers.py`: `--jobs` spawned
processes). With `--cluster ADDRESS` they go to the scheduler of an existing Dask
distributed cluster (`pip install -e '.[cluster]'`), one future per run:

* A worker that dies (killed, out of memory, its machine gone) has its tasks rescheduled
  on the others by the scheduler; a task whose workers died more than the scheduler's
  `distributed.scheduler.allowed-failures` times (3 by default) fails the sweep with
  `KilledWorker`. A task that raises is not retried: a run is deterministic, so it would
  raise again.
* Results are identical to a local run because a run depends on nothing but its job and the
  code: each result comes back with the fingerprint of the code and the numeric libraries
  of the process that ran it (`fingerprint`), and a result from a worker whose fingerprint
  is not this checkout's stops the sweep.
* The tasks write nothing on a worker's disk: what a run makes (a picture) comes back with
  its result.

Stopping the script releases its futures, and the scheduler drops the runs not yet started.
"""

from __future__ import annotations

import argparse
import hashlib
import importlib
import os
import platform
import sys
import uuid
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import as_completed
from dataclasses import dataclass
from functools import cache
from importlib import metadata
from pathlib import Path
from typing import Any, Generic, TypeVar

from experiments.workers import pool

ROOT = Path(__file__).resolve().parent.parent
# What a run's result depends on: the project's code, the committed scenarios, and the
# libraries that compute (a different numpy or numba may round differently).
CODE = ("protocol", "world_server", "agent_runtime", "teacher", "conag", "experiments")
DATA = ("scenarios",)
LIBRARIES = ("numpy", "numba", "pymunk", "msgpack")
CONNECT_TIMEOUT = "20s"

J = TypeVar("J")
R = TypeVar("R")
T = TypeVar("T")


class ClusterError(RuntimeError):
    """The cluster cannot be used: Dask distributed missing, no scheduler, other code on a worker."""


@dataclass(frozen=True)
class Where:
    """Where the runs go: `workers` local processes, or the Dask scheduler at `cluster`."""

    workers: int = 1
    cluster: str | None = None

    def describe(self, seen: int = 0) -> str:
        """For a results page: "2 worker processes", or "a Dask cluster (tcp://..., 3 workers)"."""
        if self.cluster is None:
            return f"{self.workers} worker processes"
        return f"a Dask cluster ({self.cluster}, {seen} workers)" if seen else f"a Dask cluster ({self.cluster})"


@dataclass(frozen=True)
class Done(Generic[J, R]):
    """One finished run: its job, what it returned, and the worker that ran it."""

    job: J
    result: R
    worker: str


def add_cluster_argument(ap: argparse.ArgumentParser) -> None:
    """`--cluster ADDRESS`, the same in every experiment script."""
    ap.add_argument("--cluster", metavar="ADDRESS", default=None,
                    help="run on the Dask distributed scheduler at ADDRESS (e.g. tcp://10.0.0.5:8786) instead "
                         "of local worker processes (--jobs is then ignored); needs `pip install -e '.[cluster]'`")


def where_of(args: argparse.Namespace, workers: int) -> Where:
    """The `Where` of a script's parsed --cluster and its local worker count."""
    return Where(workers=workers, cluster=getattr(args, "cluster", None))


def run(fn: Callable[[J], R], jobs: Sequence[J], where: Where, *,
        seen: Callable[[int], None] | None = None) -> Iterator[Done[J, R]]:
    """`fn(job)` for every job, where `where` says, yielded as each finishes (in no set order).

    `fn` and the jobs' classes must be importable by name (a module-level function, or a
    `functools.partial` of one), not from `__main__`: Dask pickles those by value, and a
    script's results would come back as copies of its classes. A script calls its `main`
    through `by_name`. `seen`, if given, is told the cluster's worker count once connected."""
    if where.cluster is None:
        yield from _local(fn, jobs, where.workers)
    else:
        yield from _cluster(fn, jobs, where.cluster, seen)


def _local(fn: Callable[[J], R], jobs: Sequence[J], workers: int) -> Iterator[Done[J, R]]:
    with pool(workers) as executor:
        futures = {executor.submit(task, fn, job): job for job in jobs}
        for future in as_completed(futures):
            result, worker, _ = future.result()
            yield Done(futures[future], result, worker)


def by_name(main: Callable[[], T]) -> Callable[[], T]:
    """A script's `main` taken from its module imported by name (`experiments.NAME`) when it
    runs as `__main__` (`python3 -m experiments.NAME`): then the functions and classes its
    runs use are that module's, importable by name on a cluster's workers."""
    spec = getattr(sys.modules["__main__"], "__spec__", None)
    if main.__module__ != "__main__" or spec is None:
        return main
    return getattr(importlib.import_module(spec.name), main.__name__)


def connect(address: str) -> Any:
    """A Dask client of the scheduler at `address`; ClusterError if that cannot be."""
    try:
        from distributed import Client
    except ImportError:
        raise ClusterError("--cluster needs Dask distributed, which is not installed: "
                           "pip install -e '.[cluster]' (or pip install distributed)") from None
    try:
        return Client(address, timeout=CONNECT_TIMEOUT, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        raise ClusterError(f"no Dask scheduler reachable at {address}: {exc}") from None


def _cluster(fn: Callable[[J], R], jobs: Sequence[J], address: str,
             seen: Callable[[int], None] | None) -> Iterator[Done[J, R]]:
    mine = fingerprint()
    client = connect(address)
    from distributed import as_completed as dask_completed

    futures: dict[Any, J] = {}
    try:
        if seen is not None:
            seen(len(client.nthreads()))
        name = getattr(fn, "__name__", None) or getattr(getattr(fn, "func", None), "__name__", "run")
        sweep = uuid.uuid4().hex[:8]
        # pure=False and a key per run: two equal jobs are two runs, as in the local pool.
        futures = {client.submit(task, fn, job, key=f"{name}-{sweep}-{k}", pure=False): job
                   for k, job in enumerate(jobs)}
        for future in dask_completed(futures, loop=client.loop):
            result, worker, theirs = future.result()
            if theirs != mine:
                raise ClusterError(f"the worker {worker} runs other code or libraries than this checkout "
                                   f"({theirs[:12]} there, {mine[:12]} here): its results would not be "
                                   f"a local run's. Start (or restart) the workers from a checkout of the same commit.")
            yield Done(futures[future], result, worker)
    finally:
        client.cancel(list(futures))
        client.close()


def task(fn: Callable[[J], R], job: J) -> tuple[R, str, str]:
    """In a worker: one run, the worker that ran it and that worker's `fingerprint`."""
    return fn(job), _worker_name(), fingerprint()


def _worker_name() -> str:
    if "distributed" in sys.modules:
        from distributed import get_worker
        try:
            return str(get_worker().address)
        except ValueError:   # not in a Dask worker
            pass
    return f"pid {os.getpid()}"


@cache
def fingerprint(root: Path = ROOT) -> str:
    """sha256 of the code and data a run depends on (CODE's .py files, DATA's .toml files,
    by path under `root`) and of the Python and LIBRARIES versions. Once per process."""
    h = hashlib.sha256()
    files = sorted(p for d in CODE for p in (root / d).rglob("*.py"))
    files += sorted(p for d in DATA for p in (root / d).rglob("*.toml"))
    for path in files:
        h.update(path.relative_to(root).as_posix().encode() + b"\0" + path.read_bytes() + b"\0")
    h.update(f"python {platform.python_version()}".encode())
    for lib in LIBRARIES:
        try:
            h.update(f" {lib} {metadata.version(lib)}".encode())
        except metadata.PackageNotFoundError:
            h.update(f" {lib} -".encode())
    return h.hexdigest()

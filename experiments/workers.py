"""The worker pool the experiment scripts run their jobs on.

Spawned processes (nothing crosses a fork), each watching its parent: a script stopped by
SIGTERM or SIGKILL exits without shutting its pool down, and ProcessPoolExecutor workers
do not notice. They went on with the queued runs for half an hour, two of them loading
both cores of the machine (`experiments.generalisation`, stopped with `pkill`). A worker
whose parent is gone now exits within `POLL` seconds. Ctrl-C reaches the workers anyway:
the terminal signals the whole process group.
"""

from __future__ import annotations

import os
import threading
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context

POLL = 1.0  # seconds between a worker's looks at its parent


def pool(workers: int) -> ProcessPoolExecutor:
    """`workers` spawned processes that exit when this process is gone."""
    return ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn"),
                               initializer=watch_parent, initargs=(os.getpid(),))


def watch_parent(parent: int, poll: float = POLL) -> threading.Thread:
    """In a worker: a daemon thread that ends this process once `parent` is no longer its
    parent (it died; the orphan was handed to init or a subreaper)."""
    def watch() -> None:
        while os.getppid() == parent:
            time.sleep(poll)
        os._exit(1)

    thread = threading.Thread(target=watch, name="watch-parent", daemon=True)
    thread.start()
    return thread

"""The experiment scripts' worker pool: a script killed outright leaves no worker running
its queued jobs on (before, orphans loaded both cores for half an hour)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

from tests.conftest import ROOT, wait_until

SCRIPT = """
import os, sys, time
from experiments.workers import pool
if __name__ == "__main__":
    executor = pool(1)
    print(executor.submit(os.getpid).result(), flush=True)
    executor.submit(time.sleep, 120)
    time.sleep(120)
"""


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # A zombie (its reaper has not got to it yet) runs nothing.
    with open(f"/proc/{pid}/stat") as f:
        return f.read().rsplit(")", 1)[1].split()[0] != "Z"


def test_a_worker_exits_once_the_script_that_started_it_is_killed():
    script = subprocess.Popen([sys.executable, "-c", SCRIPT], cwd=ROOT, stdout=subprocess.PIPE, text=True)
    try:
        assert script.stdout is not None
        worker = int(script.stdout.readline())
        time.sleep(0.5)  # the worker is in its two-minute job now
        assert _alive(worker)
        script.send_signal(signal.SIGKILL)
        script.wait(10)
        assert wait_until(lambda: not _alive(worker), timeout=10), "the worker outlived its script"
    finally:
        script.kill()
        script.wait(10)

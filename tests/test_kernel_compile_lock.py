"""The test workers' compile lock: two processes that want the same uncompiled kernel at
once compile it once between them; the other loads it from numba's cache."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
import time

import pytest

from tests.conftest import ROOT

KERNEL = '''
from numba import njit


@njit(cache=True)
def total(n):
    s = 0
    for i in range(n):
        s += i * i
    return s
'''

WORKER = '''
import json, sys, time
from pathlib import Path
sys.path.insert(0, sys.argv[1])
from tests import kernel_compile_lock
kernel_compile_lock.install(Path(sys.argv[2]))
import kernel_under_test as k
while time.time() < float(sys.argv[3]):  # both start compiling at the same moment
    time.sleep(0.001)
assert k.total(10) == 285
print(json.dumps({"misses": sum(k.total.stats.cache_misses.values()),
                  "hits": sum(k.total.stats.cache_hits.values())}))
'''


@pytest.mark.slow
def test_two_processes_compile_a_kernel_once_between_them(tmp_path):
    (tmp_path / "kernel_under_test.py").write_text(textwrap.dedent(KERNEL))
    locks = tmp_path / "locks"
    locks.mkdir()
    start = str(time.time() + 4)  # after both have imported numba
    procs = [subprocess.Popen([sys.executable, "-c", WORKER, str(tmp_path), str(locks), start],
                              cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
             for _ in range(2)]
    results = []
    for p in procs:
        out, err = p.communicate(timeout=120)
        assert p.returncode == 0, err
        results.append(json.loads(out))
    assert sorted(r["misses"] for r in results) == [0, 1]
    assert sorted(r["hits"] for r in results) == [0, 1]

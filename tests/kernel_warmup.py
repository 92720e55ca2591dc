"""Compile the kernels the fast tier uses, in the background, while the test workers start.

`python -m tests.kernel_warmup builds` runs a small build in process (the world's and the
agent's kernels, as every build uses them); `checks` runs the layout checks (the
buildability search and the exact plan of `experiments.optimal_plan`). The test controller
starts both at once (tests/conftest.py): on a fresh clone the kernels then compile on both
cores while the workers import and collect, each kernel under its file lock
(tests/kernel_compile_lock.py), so a worker that wants one either loads it from numba's
cache or waits for the compile under way, never compiling it a second time. Warm, each part
loads its kernels from the cache in about a second. Nothing here is a test: a part that
fails leaves its kernels to whichever test wants them first.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from tests import kernel_compile_lock

ROOT = Path(__file__).resolve().parent.parent


def builds() -> None:
    """The world's and an agent's kernels: the fork server's own warm-up build."""
    from conag.forkserver import preload
    preload(warm=True)


def checks() -> None:
    """The buildability search's and the exact planner's kernels."""
    from experiments.optimal_plan import optimal_plan
    from world_server.buildability import check_buildable
    from world_server.scenario import load_scenario
    check_buildable(load_scenario(ROOT / "scenarios" / "fig17.toml"))
    bricks, sites, obstacles = (np.zeros((3, 8), bool) for _ in range(3))
    bricks[0, 3], sites[0, 6] = True, True
    optimal_plan(bricks, sites, obstacles, [(0, 0)])


PARTS = {"builds": builds, "checks": checks}

def main(argv: list[str]) -> int:
    kernel_compile_lock.install(kernel_compile_lock.lock_dir_for(ROOT))
    for part in argv:
        PARTS[part]()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))

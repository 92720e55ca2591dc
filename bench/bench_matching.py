"""calculateMatching benchmark (paper §6.1, Fig. 16; issue 4 target: <= 10 ms at 101 x 101, 10 sites).

    python3 -m bench.bench_matching            # the table of docs/results/benchmarks.md
    python3 -m bench.bench_matching --quick    # a smoke run, not a measurement

Maps like an agent's: a square map with scattered food and water discs (5% of the cells,
obstacles), a 6 x 6 block of free bricks in the north-west quarter and the unfilled drop
sites as walls of 10 sites (rows of a blueprint) in the south-east half, so paths are long
and cross other sites. For each size and site count, `calculate_matching` (compiled) is
timed on maps drawn from seeds 0..K-1, `--repeats` calls per map after one warm-up call;
the figure is the median (and 90th percentile) over all calls. The whole-grid numpy
version of the same algorithm (`calculate_matching_grid`, the tests' reference) is timed
once per map for comparison, and the two results are checked equal.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time

import numpy as np

from agent_runtime.matching import calculate_matching, calculate_matching_grid

CASES = ((101, 10), (101, 50), (41, 10))
TARGET_MS = {(101, 10): 10.0}


def agent_like_map(n: int, sites: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(bricks, sites, obstacles) as described in the module docstring."""
    obstacles = rng.random((n, n)) < 0.05
    bricks = np.zeros((n, n), bool)
    r0, c0 = n // 8, n // 8
    bricks[r0:r0 + 6, c0:c0 + 6] = True
    site = np.zeros((n, n), bool)
    walls = -(-sites // 10)
    rows = np.linspace(n // 2, n - 4, walls).astype(int)
    for k, r in enumerate(rows):
        width = min(10, sites - 10 * k)
        c = int(rng.integers(n // 2, n - width - 2))
        site[r, c:c + width] = True
    obstacles &= ~bricks & ~site
    return bricks, site, obstacles


def measure(n: int, sites: int, maps: int, repeats: int) -> dict:
    fast, grid = [], []
    for seed in range(maps):
        case = agent_like_map(n, sites, np.random.default_rng(seed))
        result = calculate_matching(*case)  # warm-up (and the compile on a first run)
        for _ in range(repeats):
            t = time.perf_counter()
            calculate_matching(*case)
            fast.append(time.perf_counter() - t)
        t = time.perf_counter()
        ref = calculate_matching_grid(*case)
        grid.append(time.perf_counter() - t)
        if not (np.array_equal(ref.match, result.match) and set(ref.pairs) == set(result.pairs)):
            raise AssertionError(f"compiled and whole-grid matching differ on seed {seed}")
    fast_ms = sorted(1e3 * t for t in fast)
    return dict(median=statistics.median(fast_ms), p90=fast_ms[int(0.9 * (len(fast_ms) - 1))],
                grid=statistics.median(1e3 * t for t in grid), matched=len(result.pairs))


def main(argv: list[str] | None = None) -> str:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a few calls: a smoke run, not a measurement")
    ap.add_argument("--maps", type=int, default=5, help="maps (seeds) per case")
    ap.add_argument("--repeats", type=int, default=40, help="timed calls per map")
    args = ap.parse_args(argv)
    maps, repeats = (1, 3) if args.quick else (args.maps, args.repeats)
    lines = ["| map | unfilled sites | calculate_matching median ms (p90) | whole-grid numpy ms | target ms | met |",
             "|---|---:|---:|---:|---:|:---:|"]
    for n, sites in CASES:
        r = measure(n, sites, maps, repeats)
        target = TARGET_MS.get((n, sites))
        met = "" if target is None else ("yes" if r["median"] <= target else "NO")
        lines.append(f"| {n} x {n} | {sites} | {r['median']:.2f} ({r['p90']:.2f}) | {r['grid']:.0f} | "
                     f"{'' if target is None else target} | {met} |")
        print(f"{n} x {n}, {sites} sites: {r['median']:.2f} ms", file=sys.stderr, flush=True)
    table = "\n".join(lines)
    print(table)
    return table


if __name__ == "__main__":
    main()

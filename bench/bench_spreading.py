"""Navigation-map benchmark: the compiled distance field against scipy's Dijkstra.

    python3 -m bench.bench_spreading             # the table of docs/results/benchmarks.md (~10 s)
    python3 -m bench.bench_spreading --quick     # a smoke run, well under a second of timing

Maps (fixed seeds): "open" is 5% random obstacle cells plus two walls with gaps and three
random goals; "maze" is a perfect maze (recursive backtracker, one-cell corridors) with
one goal in a corner, so paths wind through most of the map. Each cell of the table is
the median of many single calls. scipy is timed two ways: `scipy.sparse.csgraph.dijkstra`
alone on a prebuilt graph (`indices=goals, min_only=True`), and with the sparse graph
built from the grid first (vectorised numpy, same no-corner-cutting rule), which is the
realistic cost for a map that changes every tick. Both fields are checked equal.
"""

from __future__ import annotations

import argparse
import math
import statistics
import time

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from agent_runtime.spreading import MOVES, distance_field

SIZES = (41, 101)


def open_map(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    obstacles = rng.random((n, n)) < 0.05
    obstacles[n // 3, : 2 * n // 3] = True  # a wall from the left edge
    obstacles[n // 4 :, 2 * n // 3] = True  # a wall up from the bottom edge
    obstacles[n // 3, n // 6] = False  # with a gap
    goals = np.zeros((n, n), bool)
    free = np.flatnonzero(~obstacles)
    goals.flat[rng.choice(free, 3, replace=False)] = True
    return goals, obstacles


def maze_map(n: int, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Walls everywhere, then carve corridors between odd cells by a randomised DFS."""
    obstacles = np.ones((n, n), bool)
    stack = [(1, 1)]
    obstacles[1, 1] = False
    while stack:
        r, c = stack[-1]
        options = [(r + dr, c + dc, dr, dc) for dr, dc in ((-2, 0), (2, 0), (0, -2), (0, 2))
                   if 0 < r + dr < n - 1 and 0 < c + dc < n - 1 and obstacles[r + dr, c + dc]]
        if not options:
            stack.pop()
            continue
        rr, cc, dr, dc = options[rng.integers(len(options))]
        obstacles[r + dr // 2, c + dc // 2] = False
        obstacles[rr, cc] = False
        stack.append((rr, cc))
    goals = np.zeros((n, n), bool)
    goals[1, 1] = True
    return goals, obstacles


def _slices(d: int, n: int) -> tuple[slice, slice]:
    """Cells i with i + d inside [0, n), and their neighbours i + d."""
    return slice(max(0, -d), n - max(0, d)), slice(max(0, d), n - max(0, -d))


def scipy_graph(obstacles: np.ndarray) -> csr_matrix:
    """The grid as a sparse graph: free cells, 8 moves, diagonals only past free flanks."""
    n, m = obstacles.shape
    free = ~obstacles
    ids = np.arange(n * m).reshape(n, m)
    rows, cols, weights = [], [], []
    for dr, dc in MOVES:
        (ra, rb), (ca, cb) = _slices(dr, n), _slices(dc, m)
        ok = free[ra, ca] & free[rb, cb]
        if dr and dc:
            ok &= free[rb, ca] & free[ra, cb]
        rows.append(ids[ra, ca][ok])
        cols.append(ids[rb, cb][ok])
        weights.append(np.full(int(ok.sum()), math.hypot(dr, dc)))
    return csr_matrix((np.concatenate(weights), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(n * m, n * m))


def scipy_field(goals: np.ndarray, obstacles: np.ndarray, graph: csr_matrix | None = None) -> np.ndarray:
    graph = scipy_graph(obstacles) if graph is None else graph
    sources = np.flatnonzero(goals & ~obstacles)
    return dijkstra(graph, directed=True, indices=sources, min_only=True).reshape(goals.shape)


def median_us(fn, repeats: int) -> float:
    fn()  # warm-up (and numba compile on the first map)
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter_ns()
        fn()
        times.append(time.perf_counter_ns() - t0)
    return statistics.median(times) / 1e3


def measure(kind: str, n: int, repeats: int) -> tuple[float, float, float]:
    goals, obstacles = (open_map if kind == "open" else maze_map)(n, np.random.default_rng(n))
    graph = scipy_graph(obstacles)
    ours, ref = distance_field(goals, obstacles), scipy_field(goals, obstacles, graph)
    assert np.array_equal(np.isinf(ours), np.isinf(ref)), "inf patterns differ"
    assert np.allclose(ours[np.isfinite(ours)], ref[np.isfinite(ref)], rtol=0, atol=1e-9)
    fast = median_us(lambda: distance_field(goals, obstacles), repeats * 10)
    solve = median_us(lambda: scipy_field(goals, obstacles, graph), repeats)
    built = median_us(lambda: scipy_field(goals, obstacles), repeats)
    return fast, built, solve


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a few repeats: a smoke run, not a measurement")
    parser.add_argument("--repeats", type=int, default=300, help="scipy calls per cell (the kernel gets 10x)")
    args = parser.parse_args(argv)
    repeats = 5 if args.quick else args.repeats
    print("| map | size | distance_field (us) | scipy incl. graph build (us) | scipy solve only (us) "
          "| speed-up vs incl. build | speed-up vs solve only |")
    print("|---|---:|---:|---:|---:|---:|---:|")
    for kind in ("open", "maze"):
        for n in SIZES:
            fast, built, solve = measure(kind, n, repeats)
            print(f"| {kind} | {n} x {n} | {fast:.1f} | {built:.1f} | {solve:.1f} "
                  f"| {built / fast:.1f}x | {solve / fast:.1f}x |", flush=True)


if __name__ == "__main__":
    main()

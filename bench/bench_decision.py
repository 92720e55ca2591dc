"""Agent decision step benchmark: one `Brain.step(frame)` against scipy's Dijkstra.

    python3 -m bench.bench_decision              # the table of docs/results/benchmarks.md
    python3 -m bench.bench_decision --quick      # a smoke run, not a measurement

For each map size, scenarios/fig6.toml runs in-process (`conag.sim.start`, one agent,
`AgentConfig(map_size=...)`) for a warm-up of 300 ticks, so the ESMs hold a realistic
picture (blueprint, the food-and-water wall, bricks). Then the sim keeps running, and on
every tick until the structure is complete (about 540 ticks; then a new
episode with the next seed starts and warms up again, so an idle agent is never timed)
the agent's whole decision step, `brain.step(frame)` (ESM move + sense,
motivations, the configuration and brick navigation maps, the state nodes, action
selection), is timed on that tick's frame, and so is `brain.plan()` alone (the two
navigation maps); the world step is not timed. The goal and obstacle masks of both maps
(the goals and obstacles the last `Brain.plan` used, with goal sequencing on as by default) and the brain's fields
are recorded each tick. Afterwards, in the same run, `scipy.sparse.csgraph.dijkstra`
computes the same two fields from every recorded tick's masks (8-connected, no corner
cutting, multi-source `indices=goal cells`, `min_only=True`), timed with the sparse
graphs built from the masks (the realistic cost, as the obstacles change every tick) and
solve-only on prebuilt graphs, and each field is checked equal to the brain's. (Running
scipy between the agent's ticks instead evicted the agent's data from the caches and
made its 41 x 41 step about 1.6 times slower.) Every figure is the median over the timed ticks.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

from agent_runtime.config import AgentConfig
from bench.bench_spreading import scipy_field, scipy_graph
from conag import sim
from world_server.scenario import load_scenario

ROOT = Path(__file__).resolve().parent.parent
SCENARIO = ROOT / "scenarios" / "fig6.toml"
SIZES = (41, 101)
TARGET_MS = {41: 0.5, 101: 4.0}
TARGET_SPEEDUP = 5.0


def target(n: int) -> float:
    """The step target at n x n: the issue's for 41 and 101; other sizes (81 and 121 for
    large worlds, issue 15) linear in the number of cells through those two."""
    if n in TARGET_MS:
        return TARGET_MS[n]
    (a, ta), (b, tb) = sorted(TARGET_MS.items())
    return round(ta + (n * n - a * a) * (tb - ta) / (b * b - a * a), 2)


def nav_masks(brain) -> list[tuple[np.ndarray, np.ndarray]]:
    """(goals, obstacles) the configuration and brick NMs of the last plan were computed
    from (with goal sequencing, as by default, the plan may have fallen back to the plain
    goals of one map)."""
    p = brain.plans
    return [(p.config_goals, p.config_obstacles), (p.brick_goals, p.brick_obstacles)]


def solve(goals: np.ndarray, obstacles: np.ndarray, graph=None) -> np.ndarray:
    if not (goals & ~obstacles).any():  # no source: nothing reachable (dijkstra needs one)
        if graph is None:
            scipy_graph(obstacles)  # the build is still part of the cost
        return np.full(goals.shape, np.inf)
    return scipy_field(goals, obstacles, graph)


def _same(ours: np.ndarray, ref: np.ndarray) -> bool:
    fin = np.isfinite(ours)
    return bool(np.array_equal(fin, np.isfinite(ref)) and np.allclose(ours[fin], ref[fin], rtol=0, atol=1e-9))


def measure(n: int, warmup: int, ticks: int) -> dict:
    scenario, cfg = load_scenario(SCENARIO), AgentConfig(map_size=n)
    step_ms, plan_ms, behaviours, recorded = [], [], {}, []
    episodes, run = 0, None
    # Phase 1: the agent alone, so scipy's allocations do not evict its working set
    # between ticks; each tick's masks and fields are kept for phase 2.
    while len(step_ms) < ticks:
        if run is None or run.world.completed():
            # A finished structure leaves the agent idle: time building agents only, so
            # start the next episode (another seed) and warm it up first.
            run = sim.start(scenario, agents=1, seed=scenario.seed + episodes, cfg=cfg)
            run.run(warmup, until_complete=False)
            episodes += 1
            continue
        (frame,) = run.world.frames()
        brain = run.brains[frame.agent_id]
        t0 = time.perf_counter_ns()
        s = brain.step(frame)
        step_ms.append((time.perf_counter_ns() - t0) / 1e6)
        behaviours[s.behaviour] = behaviours.get(s.behaviour, 0) + 1
        run.world.set_command(frame.agent_id, s.speed, s.turn, s.action)
        # The two navigation maps alone (what scipy is compared with), on the same maps.
        t0 = time.perf_counter_ns()
        plans = brain.plan()
        plan_ms.append((time.perf_counter_ns() - t0) / 1e6)
        recorded.append((nav_masks(brain), (plans.config, plans.brick), frame.tick))
        run.world.step()  # not timed
    # Phase 2: scipy on the very same maps, with and without building its graphs.
    built_ms, solve_ms = [], []
    for masks, ours, tick in recorded:
        t0 = time.perf_counter_ns()
        fields = [solve(g, o) for g, o in masks]
        built_ms.append((time.perf_counter_ns() - t0) / 1e6)
        graphs = [scipy_graph(o) for _, o in masks]
        t0 = time.perf_counter_ns()
        for (g, o), graph in zip(masks, graphs):
            solve(g, o, graph)
        solve_ms.append((time.perf_counter_ns() - t0) / 1e6)
        for mine, ref in zip(ours, fields):
            if not _same(mine, ref):
                raise AssertionError(f"map {n}: scipy field differs from the brain's at tick {tick}")
    return {"step": statistics.median(step_ms), "step_p90": sorted(step_ms)[int(0.9 * (len(step_ms) - 1))],
            "plan": statistics.median(plan_ms), "built": statistics.median(built_ms),
            "solve": statistics.median(solve_ms), "behaviours": behaviours, "checked": len(recorded),
            "episodes": episodes}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="a few ticks: a smoke run, not a measurement")
    parser.add_argument("--warmup", type=int, default=300, help="sim ticks before timing starts")
    parser.add_argument("--ticks", type=int, default=2000, help="timed decision steps per map size")
    parser.add_argument("--sizes", type=lambda t: tuple(int(v) for v in t.split(",")), default=SIZES,
                        metavar="N,N", help="map sizes (odd; default 41,101; large worlds: 81,121)")
    args = parser.parse_args(argv)
    if args.quick:
        args.warmup, args.ticks = 30, 20
    print("| map | decision step median ms (p90) | our 2 NMs ms | scipy 2 fields incl. build ms "
          "| scipy 2 fields solve only ms | NMs speed-up vs incl. build | vs solve only | step target ms "
          "| step met | 5x met |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|:---:|:---:|")
    notes = []
    for n in args.sizes:
        r = measure(n, args.warmup, args.ticks)
        up_built, up_solve = r["built"] / r["plan"], r["solve"] / r["plan"]
        yes = {True: "yes", False: "NO"}
        print(f"| {n} x {n} | {r['step']:.3f} ({r['step_p90']:.3f}) | {r['plan']:.3f} | {r['built']:.3f} "
              f"| {r['solve']:.3f} | {up_built:.1f}x | {up_solve:.1f}x | {target(n):g} "
              f"| {yes[r['step'] <= target(n)]} | {yes[up_built >= TARGET_SPEEDUP]} |", flush=True)
        mix = ", ".join(f"{k} {v}" for k, v in sorted(r["behaviours"].items(), key=lambda kv: -kv[1]))
        notes.append(f"{n} x {n}: {r['checked']} ticks timed in {r['episodes']} episode(s) (seeds from 6), "
                     f"each timed from tick {args.warmup} until the structure was complete (the last one until "
                     f"enough ticks); behaviours: {mix}")
    print()
    print("Targets: decision step <= " + ", ".join(f"{target(k):g} ms at {k} x {k}" for k in args.sizes)
          + f"; the two navigation maps >= {TARGET_SPEEDUP:g}x faster than scipy computing the same two fields"
          " (the realistic scipy cost includes building its graph: the obstacles change every tick).")
    for line in notes:
        print(f"- {line}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""Agent decision step on generated layouts: what the far memory, the border seeds, the
wall layer and the Explore sweep cost (issue 10).

    python3 -m bench.bench_agent_step            # the table of BENCHMARKS.md
    python3 -m bench.bench_agent_step --quick    # a smoke run, not a measurement

For each layout (scenarios/fig6.toml and three from the generalisation suite: a 21 x 21,
a 51 x 50 and a 117 x 116 world, the large ones with the blueprint or the supply beyond
the 41 x 41 maps), the in-process sim (conag/sim/loop.py, default AgentConfig: 41 x 41 maps,
goal sequencing on) warms up for `--warmup` ticks, then every agent's `Brain.step(frame)`
is timed on every tick for `--ticks` ticks (the world's step is not timed). Reported: the
median and 90th percentile of one step, the share of steps that planned with goals
beyond the map (border seeds), and the world ticks per second of the whole sim.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

from conag import sim
from world_server.scenario import load_scenario
from world_server.suite import materialise

ROOT = Path(__file__).resolve().parent.parent
# the generalisation suite's layouts, made from its manifest on first use (experiments/generalisation.py)
SUITE = ROOT / "experiments" / "generalisation" / "layouts"
MANIFEST = ROOT / "experiments" / "generalisation" / "layouts.json"
LAYOUTS = (ROOT / "scenarios" / "fig6.toml", SUITE / "001-gen-nested_rings-20260001.toml",
           SUITE / "021-gen-wall-20260021.toml", SUITE / "028-gen-nested_rings-20260028.toml")


def measure(path: Path, warmup: int, ticks: int) -> dict:
    sc = load_scenario(path)
    run = sim.start(sc)
    run.run(warmup, until_complete=False)
    steps, beyond = [], 0
    began = time.perf_counter()
    for _ in range(ticks):
        for frame in run.world.frames():
            brain = run.brains[frame.agent_id]
            t = time.perf_counter()
            s = brain.step(frame)
            steps.append(time.perf_counter() - t)
            beyond += bool(len(brain.far.far_open_sites()) or len(brain.far.bricks))
            run.world.set_command(frame.agent_id, s.speed, s.turn, s.action)
        run.world.step()
    wall = time.perf_counter() - began
    steps.sort()
    return dict(layout=path.stem, size=f"{sc.cols} x {sc.rows}", agents=len(run.brains),
                median_ms=1e3 * statistics.median(steps), p90_ms=1e3 * steps[int(0.9 * (len(steps) - 1))],
                beyond=beyond / max(len(steps), 1), ticks_per_s=ticks / wall)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="a few ticks: a smoke run, not a measurement")
    ap.add_argument("--warmup", type=int, default=500, help="sim ticks before timing starts")
    ap.add_argument("--ticks", type=int, default=1000, help="timed ticks per layout")
    args = ap.parse_args(argv)
    warmup, ticks = (20, 20) if args.quick else (args.warmup, args.ticks)
    materialise(MANIFEST, SUITE)
    print("| layout | world | agents | decision step median ms (p90) | steps with goals beyond the map "
          "| sim ticks/s |")
    print("|---|---|---:|---:|---:|---:|")
    for path in LAYOUTS:
        r = measure(path, warmup, ticks)
        print(f"| {r['layout']} | {r['size']} | {r['agents']} | {r['median_ms']:.3f} ({r['p90_ms']:.3f}) | "
              f"{100 * r['beyond']:.0f}% | {r['ticks_per_s']:.0f} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

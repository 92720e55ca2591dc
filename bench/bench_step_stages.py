"""Where an agent's decision step spends its time, stage by stage (issue 31).

    python3 -m bench.bench_step_stages                        # 001-gen-nested_rings at 41 x 41
    python3 -m bench.bench_step_stages --layout fig6 --map 121
    python3 -m bench.bench_step_stages --quick                # a smoke run, not a measurement

The in-process sim (default AgentConfig but for the map size) warms up, then every
agent's `Brain.step(frame)` is timed for `--ticks` ticks with each stage of `STAGES`
wrapped by a timer (about half a microsecond per wrapped call, so the total is a little
above `bench_agent_step`'s). For each stage the table gives its mean per step over all
steps, its calls per step, and its mean over the typical steps, those within 10% of the
median step: what a median step is made of. Stages nest (sensing is part of perceiving),
so the column does not add up to the step.

`--cold` also times the distance-field kernel on the last fields the run computed, warm
(called again at once) and after 32 MB were read in between: how much of a kernel's time
in the step is the caches', not its instructions'.
"""

from __future__ import annotations

import argparse
import collections
import importlib
import statistics
import sys
import time
from pathlib import Path

from bench.bench_agent_step import LAYOUTS

# (module under agent_runtime, attribute path): the stages, outermost first.
STAGES = (
    ("brain", "Brain.perceive"), ("brain", "Brain._shift_belief"), ("esm", "EgocentricMaps.sense"),
    ("esm", "EgocentricMaps._geometry_for"), ("esm", "_sense_kernel"), ("brain", "step_marks"),
    ("brain", "Brain._enclosed_sites"), ("brain", "Brain.plan"), ("brain", "Brain.nav_masks"),
    ("brain", "Brain._nav_inputs"), ("brain", "Brain._sequenced_goals"), ("seal_guard", "SealGuard.unsafe"),
    ("field_cache", "FieldCache.distance"), ("spreading", "_field_into"), ("brain", "Brain._nearest"),
    ("brain", "Brain.state_nodes"), ("brain", "Brain._select"), ("brain", "Brain._need_field"),
    ("brain", "Brain._off_own_brick"), ("brain", "Brain._unstick"),
)


def wrap_stages(totals: dict[str, float], calls: collections.Counter) -> None:
    """Replace each stage by a timed wrapper adding to `totals` and `calls` (by name)."""
    clock = time.perf_counter
    for module, path in STAGES:
        owner = importlib.import_module(f"agent_runtime.{module}")
        *parents, name = path.split(".")
        for part in parents:
            owner = getattr(owner, part)
        inner = getattr(owner, name)

        def timed(*args, _inner=inner, _name=path, **kwargs):
            start = clock()
            try:
                return _inner(*args, **kwargs)
            finally:
                totals[_name] += clock() - start
                calls[_name] += 1
        setattr(owner, name, timed)


def measure(layout: Path, map_size: int, warmup: int, ticks: int) -> tuple[list[float], dict[str, list[float]], dict]:
    """Per-step totals and per-stage seconds of `ticks` ticks after `warmup`, and the calls."""
    from agent_runtime.config import AgentConfig
    from conag import sim
    from world_server.scenario import load_scenario

    totals: dict[str, float] = collections.defaultdict(float)
    calls: collections.Counter = collections.Counter()
    wrap_stages(totals, calls)
    run = sim.start(load_scenario(layout), cfg=AgentConfig(map_size=map_size))
    run.run(warmup, until_complete=False)
    calls.clear()
    steps: list[float] = []
    per_stage: dict[str, list[float]] = {path: [] for _, path in STAGES}
    for _ in range(ticks):
        for frame in run.world.frames():
            before = dict(totals)
            start = time.perf_counter()
            step = run.brains[frame.agent_id].step(frame)
            steps.append(time.perf_counter() - start)
            for path in per_stage:
                per_stage[path].append(totals[path] - before.get(path, 0.0))
            run.world.set_command(frame.agent_id, step.speed, step.turn, step.action)
        run.world.step()
    return steps, per_stage, {path: calls[path] / len(steps) for path in per_stage}


def table(steps: list[float], per_stage: dict[str, list[float]], calls: dict) -> str:
    median = statistics.median(steps)
    typical = [i for i, s in enumerate(steps) if abs(s - median) < 0.1 * median]
    lines = [(f"step: mean {1e6 * statistics.mean(steps):.0f} us, median {1e6 * median:.0f} us "
              f"({len(steps)} steps, {len(typical)} typical)"), "",
             "| stage | mean us per step | calls per step | mean us, typical steps |", "|---|---:|---:|---:|"]
    for path, seconds in per_stage.items():
        typ = statistics.mean(seconds[i] for i in typical) if typical else 0.0
        lines.append(f"| {path} | {1e6 * statistics.mean(seconds):.1f} | {calls[path]:.2f} | {1e6 * typ:.1f} |")
    return "\n".join(lines)


def cold_kernel(layout: Path, map_size: int, warmup: int) -> str:
    """The distance-field kernel on the last 200 fields a run computed: warm, and with the
    caches flushed by reading 32 MB before each call. A run of its own, not `measure`'s:
    copying every field's inputs inside the timed steps would add to the stages' times."""
    import numpy as np

    from agent_runtime import field_cache
    from agent_runtime.config import AgentConfig
    from agent_runtime.spreading import FieldWork, distance_field
    from conag import sim
    from world_server.scenario import load_scenario

    seen: list[tuple[np.ndarray, np.ndarray]] = []
    plain = field_cache.distance_field

    def keep(goals, obstacles, work=None):
        seen.append((goals.copy(), obstacles.copy()))
        return plain(goals, obstacles, work)
    field_cache.distance_field = keep
    run = sim.start(load_scenario(layout), cfg=AgentConfig(map_size=map_size))
    run.run(warmup, until_complete=False)
    field_cache.distance_field = plain
    fields = seen[-200:]
    if not fields:
        return "no field was computed"
    work = FieldWork(fields[0][0].shape)
    junk = np.ones(4_000_000)
    out = []
    for flush in (False, True):
        times = []
        for goals, obstacles in fields:
            if flush:
                junk.sum()
            start = time.perf_counter()
            distance_field(goals, obstacles, work)
            times.append(time.perf_counter() - start)
        out.append(f"{'after 32 MB read' if flush else 'warm'}: median {1e6 * statistics.median(times):.1f} us")
    return f"distance-field kernel, {len(fields)} fields of this run: " + "; ".join(out)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--layout", default="001-gen-nested_rings", help="a layout of bench_agent_step (name part)")
    ap.add_argument("--map", type=int, default=41, help="map size (default 41)")
    ap.add_argument("--warmup", type=int, default=300)
    ap.add_argument("--ticks", type=int, default=600)
    ap.add_argument("--cold", action="store_true", help="also time the field kernel warm and with flushed caches")
    ap.add_argument("--quick", action="store_true", help="a few ticks: a smoke run, not a measurement")
    args = ap.parse_args(argv)
    matches = [p for p in LAYOUTS if args.layout in p.name]
    if not matches:
        ap.error(f"no layout of bench_agent_step matches {args.layout!r}: {', '.join(p.stem for p in LAYOUTS)}")
    warmup, ticks = (20, 20) if args.quick else (args.warmup, args.ticks)
    print(f"{matches[0].stem} at {args.map} x {args.map}, {ticks} ticks after {warmup}")
    print(table(*measure(matches[0], args.map, warmup, ticks)))
    if args.cold:
        print(cold_kernel(matches[0], args.map, warmup))
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""What a reactive worker's step costs against a ConAg agent's decision step (issue 37 item 4).

    python3 -m bench.bench_society                 # the table of docs/results/benchmarks.md
    python3 -m bench.bench_society --quick         # a smoke run, not a measurement

On one scenario (default scenarios/fig19.toml), in process: a society of `--foremen` foremen
and `--workers` workers (conag.sim.society), and a team of as many ConAg agents
(conag.sim.start), each stepped for `--ticks` ticks after `--warmup`. Every member's step
(`Brain.step`, `ForemanBrain.step`, `Worker.step`: frame in, command out; the world's step is
not timed) is timed with the thread's CPU clock; the table gives the median and the mean per
step by kind. Both runs share the machine and alternate `--repeats` times.
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections import defaultdict

from conag.sim.loop import SimRun, start
from conag.sim.society import start_society
from world_server.scenario import load_scenario


def timed(run: SimRun, ticks: int, warmup: int) -> dict[str, list[float]]:
    """CPU seconds of every step, by kind of member (the id's first letter: a, f, w)."""
    kind = {"a": "ConAg agent", "f": "foreman", "w": "worker"}
    times: dict[str, list[float]] = defaultdict(list)
    for k in range(warmup + ticks):
        if run.world.completed():
            break
        for frame in run.world.frames():
            t0 = time.thread_time()
            s = run.brains[frame.agent_id].step(frame)
            spent = time.thread_time() - t0
            if k >= warmup:
                times[kind[frame.agent_id[0]]].append(spent)
            run.world.set_command(frame.agent_id, s.speed, s.turn, s.action, s.mark)
        run.world.step()
    return times


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--scenario", default="scenarios/fig19.toml")
    ap.add_argument("--foremen", type=int, default=1)
    ap.add_argument("--workers", type=int, default=6)
    ap.add_argument("--ticks", type=int, default=600, help="timed ticks per run")
    ap.add_argument("--warmup", type=int, default=50, help="ticks before timing starts")
    ap.add_argument("--repeats", type=int, default=3, help="runs of each, alternating")
    ap.add_argument("--quick", action="store_true", help="a few ticks: a smoke run, not a measurement")
    args = ap.parse_args()
    if args.quick:
        args.ticks, args.warmup, args.repeats = 30, 5, 1
    scenario = load_scenario(args.scenario)
    n = args.foremen + args.workers
    times: dict[str, list[float]] = defaultdict(list)
    for _ in range(args.repeats):
        for run in (start_society(scenario, args.foremen, args.workers), start(scenario, n)):
            for kind, spent in timed(run, args.ticks, args.warmup).items():
                times[kind] += spent
    agent = statistics.median(times["ConAg agent"])
    print(f"{args.scenario}: {args.foremen} foremen + {args.workers} workers against {n} ConAg agents, "
          f"{args.ticks} ticks after {args.warmup}, {args.repeats} runs each\n")
    print("| member | steps | median ms | mean ms | median against a ConAg agent's |")
    print("|---|---:|---:|---:|---:|")
    for kind in ("ConAg agent", "foreman", "worker"):
        t = times[kind]
        if t:
            med = statistics.median(t)
            print(f"| {kind} | {len(t)} | {1e3 * med:.3f} | {1e3 * statistics.fmean(t):.3f} | {med / agent:.2f}x |")


if __name__ == "__main__":
    main()

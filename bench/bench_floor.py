"""The floor of agents in hosts (issue 31): the bus's tick with agents that think in no time,
added to the hosts' steps with no bus at all.

    python3 -m bench.bench_floor --agents 30 --per-process 15 --ticks 400
    python3 -m bench.bench_floor --agents 100 --per-process 50 --ticks 200 --warmup 50
    python3 -m bench.bench_floor --quick          # a smoke run, not a measurement

Issue 31 asks that 30 and 100 agents run as processes (hosts allowed) at 1.5x the in-process
simulator. In lockstep a tick as processes is a chain: the world steps and sends every
frame, each host steps its agents and sends their commands, and the world waits for the
last. This bench measures the two links of that chain apart, on one scenario and in one
run, one after the other:

* **in-process**: `conag.sim` (`bench_scale.in_process`): the world's step and the agents'
  decisions per tick;
* **processes**: `conag run --agents N --per-process K` (`bench_scale.as_processes`), the
  rate being compared;
* **null processes**: the same `conag run`, every agent's brain replaced by one that
  answers each frame at once (speed 0, no action). What is left of a tick is the world's
  step and loop, the frames and commands over zenoh and the hosts' handling of them. The
  replacement is a `sitecustomize` module put on the run's PYTHONPATH (`NULL_SITE`):
  nothing in the product knows of it;
* **hosts without a bus** (`bench_step_contention`): every frame each agent was given in
  process is kept, and the same brains step through them again in one process, and in
  processes of K brains meeting at a barrier after every tick, as hosts do (every decision
  checked against the recording). Their wall time per tick, after `--warmup` ticks.

The floor is the in-process tick (its world, plus the one-process replay's steps) over the
null tick plus the hosts' replayed steps: the rate the hosts would reach if the bus cost a
tick what it costs with nothing to think about, and the steps cost in the hosts what they
cost without the world's process and zenoh's threads beside them. It is not a bound in the
strict sense: the frames' transit could overlap a host's steps more than it does (the
table also gives the CPU that runs in series on the world's main thread).

Every run listens on a free port of its own. The machine should be otherwise idle.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import textwrap
from pathlib import Path

from bench.bench_scale import SCENARIO, as_processes, in_process
from bench.bench_step_contention import arrange, record

ROOT = Path(__file__).resolve().parent.parent
NULL_SITE = textwrap.dedent('''
    """bench_floor: every agent brain of this run answers each frame at once."""
    import os
    if os.environ.get("CONAG_BENCH_NULL_AGENTS") == "1":
        from agent_runtime import node
        from agent_runtime.brain import Step
        from agent_runtime.worker import Worker

        class NullBrain(Worker):   # a worker's reports and state, no thinking
            def __init__(self, welcome, cfg=None, rng=None, network=None):
                super().__init__(welcome, rng=rng)

            def step(self, frame):
                return Step(0.0, 0.0, "none", "explore", None)

        node.Brain = NullBrain
''')


def null_processes(scenario: str, agents: int, ticks: int, per_process: int) -> dict:
    """`as_processes` with every brain replaced by the null one (see the module)."""
    with tempfile.TemporaryDirectory() as site:
        (Path(site) / "sitecustomize.py").write_text(NULL_SITE, encoding="utf-8")
        path = os.pathsep.join([site, str(ROOT), os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep)
        return as_processes(ROOT, scenario, agents, ticks, per_process,
                            extra_env={"PYTHONPATH": path, "CONAG_BENCH_NULL_AGENTS": "1"})


def replayed_ticks(scenario: Path, agents: int, ticks: int, warmup: int, per_process: int,
                   repeats: int) -> dict:
    """Wall ms per tick of the recorded steps in one process and in hosts of `per_process`
    (medians of `repeats`), and whether every decision was as recorded."""
    rec = record(scenario, agents, ticks)
    ids = list(rec.welcomes)
    hosts = [ids[i:i + per_process] for i in range(0, len(ids), per_process)]
    one, split, same = [], [], True
    for _ in range(repeats):
        for groups, into in (([ids], one), (hosts, split)):
            r = arrange(rec, "", groups, True, warmup)
            into.append(1e3 * r.wall_s / (ticks - warmup))
            same = same and r.same
    return {"one_ms": statistics.median(one), "hosts_ms": statistics.median(split), "same": same}


def floor(sim: dict, null_rate: float, replay: dict) -> float:
    """The floor's rate over the in-process rate (see the module)."""
    in_process_ms = sim["world_ms"] + replay["one_ms"]
    return in_process_ms / (1e3 / null_rate + replay["hosts_ms"])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default=SCENARIO)
    ap.add_argument("--agents", type=int, default=30)
    ap.add_argument("--per-process", type=int, default=15, metavar="K", help="agents per host (default 15)")
    ap.add_argument("--ticks", type=int, default=400)
    ap.add_argument("--warmup", type=int, default=100, help="replayed ticks left out of the figures")
    ap.add_argument("--repeats", type=int, default=2, help="null runs and replays of each arrangement")
    ap.add_argument("--quick", action="store_true", help="4 agents in hosts of 2, 40 ticks: a smoke run")
    args = ap.parse_args(argv)
    if args.quick:
        args.agents, args.per_process, args.ticks, args.warmup, args.repeats = 4, 2, 40, 10, 1
    if not 0 <= args.warmup < args.ticks or args.per_process < 1 or args.agents < 1:
        ap.error("need 0 <= --warmup < --ticks, --per-process >= 1 and --agents >= 1")
    say = lambda text: print(text, file=sys.stderr, flush=True)  # noqa: E731
    sim = in_process(ROOT, args.scenario, args.agents, args.ticks)
    say(f"in-process: {sim['rate']:.1f} ticks/s (world {sim['world_ms']:.2f} ms, agents {sim['agents_ms']:.2f} ms)")
    real = as_processes(ROOT, args.scenario, args.agents, args.ticks, args.per_process)
    say(f"processes: {real['rate']:.1f} ticks/s")
    nulls = [null_processes(args.scenario, args.agents, args.ticks, args.per_process) for _ in range(args.repeats)]
    null_rate = statistics.median(n["rate"] for n in nulls)
    rates = ", ".join(f"{n['rate']:.1f}" for n in nulls)
    say(f"null processes: {rates} ticks/s")
    replay = replayed_ticks(ROOT / args.scenario, args.agents, args.ticks, args.warmup, args.per_process, args.repeats)
    say(f"replayed steps: one process {replay['one_ms']:.2f} ms a tick, hosts {replay['hosts_ms']:.2f}")
    ratio = floor(sim, null_rate, replay)
    print(f"{Path(args.scenario).name}, {args.agents} agents in hosts of {args.per_process}, {args.ticks} ticks "
          f"({args.warmup} left out of the replays), {os.cpu_count()} cores\n")
    print("| in-process ticks/s | processes ticks/s | processes / in-process | null processes: ms a tick "
          "(the first run's step / publish / wait) | replayed steps, one process: ms a tick | in hosts | "
          "floor / in-process | same decisions |")
    print("|---:|---:|---:|---|---:|---:|---:|---|")
    per = nulls[0]
    print(f"| {sim['rate']:.1f} | {real['rate']:.1f} | {real['rate'] / sim['rate']:.2f}x | {1e3 / null_rate:.2f} "
          f"({per['step_ms']:.2f} / {per['publish_ms']:.2f} / {per['wait_ms']:.2f}) | {replay['one_ms']:.2f} | "
          f"{replay['hosts_ms']:.2f} | {ratio:.2f}x | {'yes' if replay['same'] else 'no'} |")
    print(json.dumps({"in_process": sim, "processes": real, "null": nulls, "replay": replay, "floor": ratio}),
          file=sys.stderr)
    return 0 if replay["same"] else 1


if __name__ == "__main__":
    raise SystemExit(main())

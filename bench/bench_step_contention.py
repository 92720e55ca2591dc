"""Why a decision step costs more in an agent process of its own (issue 31), with no bus.

    python3 -m bench.bench_step_contention                 # 10 agents of scenarios/large/scale.toml
    python3 -m bench.bench_step_contention --agents 30 --ticks 300
    python3 -m bench.bench_step_contention --quick         # a smoke run, not a measurement

`bench_cpu_split` found that ten single agent processes spend 0.86 CPU ms a decision step
where the in-process simulator spends 0.51 on the same rows. This bench takes the bus, the
world and the frames' encoding out of that comparison. It builds the scenario in process
once (`conag.sim`, the default agent) and keeps every frame each agent was given. Then the
same brains (made as `conag.sim.start` makes them: the same Welcome, the same random
stream) step through those very frames, timed by the CPU clock of the stepping thread
(what `bench_agent_step` and `bench_cpu_split` count), in four arrangements:

* **one process**: every brain, tick by tick, as the in-process simulator steps them;
* **processes, lockstep**: one process per brain, all meeting at a barrier after every
  tick, as agent processes sleep until the world's next frame wakes them;
* **processes, free**: one process per brain, no barrier: each steps all its frames back to
  back and the kernel's scheduler interleaves them in its own slices;
* **two hosts, lockstep**: two processes of half the brains each, meeting at a barrier
  after every tick (`conag run --per-process`).

Each arrangement re-enacts the recorded run exactly: every brain decides as it did, and the
script checks it (a digest of every decision, per brain, against the recording). The first
`--warmup` ticks are left out of the figures (kernels load from numba's cache). Printed: the
median and mean step, the wall time of the steps after warm-up (first process's first to
last process's last) and the cores the steps kept busy over it.
"""

from __future__ import annotations

import argparse
import hashlib
import multiprocessing as mp
import os
import statistics
import sys
import time
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SCENARIO = ROOT / "scenarios" / "large" / "scale.toml"


@dataclass(frozen=True)
class Recorded:
    """What every arrangement replays: the scenario, its seed and each agent's Welcome and frames."""

    scenario: str
    seed: int
    welcomes: dict        # agent id -> Welcome
    frames: dict          # agent id -> [SensorFrame, ...], one per tick
    digests: dict         # agent id -> the digest of its decisions in the recorded run


def record(scenario: Path, agents: int, ticks: int) -> Recorded:
    """Build `scenario` with `agents` default agents for `ticks` ticks in process (as
    `conag.sim.start` and its loop do), keeping every frame, Welcome and decision digest."""
    import numpy as np

    from agent_runtime.brain import Brain
    from agent_runtime.config import AgentConfig
    from world_server.scenario import load_scenario
    from world_server.world import World

    sc = load_scenario(scenario)
    world = World(sc, np.random.default_rng(sc.seed))
    welcomes, brains = {}, {}
    for i in range(agents):
        aid = f"a{i + 1}"
        welcomes[aid] = world.attach(aid)
        brains[aid] = Brain(welcomes[aid], AgentConfig(), np.random.default_rng([sc.seed, i]))
    frames: dict[str, list] = {aid: [] for aid in brains}
    digests = {aid: hashlib.sha256() for aid in brains}
    for _ in range(ticks):
        for frame in world.frames():
            step = brains[frame.agent_id].step(frame)
            frames[frame.agent_id].append(frame)
            _digest(digests[frame.agent_id], step)
            world.set_command(frame.agent_id, step.speed, step.turn, step.action)
        world.step()
    return Recorded(str(scenario), sc.seed, welcomes, frames, {a: d.hexdigest() for a, d in digests.items()})


def _digest(digest, step) -> None:
    d = step.decision
    digest.update(repr((step.speed, step.turn, step.action, step.behaviour, d.state, d.outputs, d.arm,
                        d.motor)).encode())


def replay(rec: Recorded, ids: list[str], start, barrier, warmup: int, out) -> None:
    """Step the brains `ids` through their recorded frames, tick by tick (waiting at `barrier`
    after each tick, if any; all processes set off together from `start`, if any); put (agent
    id, step CPU seconds after warm-up, digest, when the steps after warm-up began and ended)
    on `out` (perf_counter is the system's monotonic clock: comparable across processes)."""
    import numpy as np

    from agent_runtime.brain import Brain
    from agent_runtime.config import AgentConfig

    index = {f"a{i + 1}": i for i in range(len(rec.welcomes))}
    brains = {a: Brain(rec.welcomes[a], AgentConfig(), np.random.default_rng([rec.seed, index[a]])) for a in ids}
    digests = {a: hashlib.sha256() for a in ids}
    cpu: dict[str, list[float]] = {a: [] for a in ids}
    clock = time.thread_time
    if start is not None:
        start.wait()
    began = time.perf_counter()
    for t in range(len(rec.frames[ids[0]])):
        if t == warmup:
            began = time.perf_counter()
        for a in ids:
            c = clock()
            step = brains[a].step(rec.frames[a][t])
            spent = clock() - c
            if t >= warmup:
                cpu[a].append(spent)
            _digest(digests[a], step)
        if barrier is not None:
            barrier.wait()
    ended = time.perf_counter()
    for a in ids:
        out.put((a, cpu[a], digests[a].hexdigest(), began, ended))


@dataclass(frozen=True)
class Result:
    arrangement: str
    median_ms: float
    mean_ms: float
    wall_s: float
    cores: float      # CPU of the steps over wall time: how many cores the steps kept busy
    same: bool        # every brain decided as in the recorded run


def arrange(rec: Recorded, name: str, groups: list[list[str]], lockstep: bool, warmup: int) -> Result:
    """Run `replay` in one process per group (in this process if there is one group)."""
    ctx = mp.get_context("spawn")
    out = ctx.Queue()
    if len(groups) == 1:
        replay(rec, groups[0], None, None, warmup, out)
        procs = []
    else:
        start = ctx.Barrier(len(groups))
        barrier = ctx.Barrier(len(groups)) if lockstep else None
        procs = [ctx.Process(target=replay, args=(rec, g, start, barrier, warmup, out)) for g in groups]
        for p in procs:
            p.start()
    got = [out.get(timeout=3600) for _ in (a for g in groups for a in g)]
    for p in procs:
        p.join()
    wall = max(g[4] for g in got) - min(g[3] for g in got)   # the steps after warm-up, first to last
    steps = [s for g in got for s in g[1]]
    same = all(rec.digests[g[0]] == g[2] for g in got)
    return Result(name, 1e3 * statistics.median(steps), 1e3 * statistics.mean(steps), wall, sum(steps) / wall, same)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", type=Path, default=SCENARIO)
    ap.add_argument("--agents", type=int, default=10)
    ap.add_argument("--ticks", type=int, default=600, help="ticks recorded and replayed")
    ap.add_argument("--warmup", type=int, default=100, help="first ticks left out of the figures")
    ap.add_argument("--repeats", type=int, default=2, help="times each arrangement runs, in alternation")
    ap.add_argument("--quick", action="store_true", help="3 agents, 40 ticks, once: a smoke run")
    args = ap.parse_args(argv)
    if args.quick:
        args.agents, args.ticks, args.warmup, args.repeats = 3, 40, 10, 1
    if args.warmup >= args.ticks:
        ap.error("--warmup must be below --ticks")
    rec = record(args.scenario, args.agents, args.ticks)
    ids = list(rec.welcomes)
    half = (len(ids) + 1) // 2
    plans = [("one process", [ids], True), ("processes, lockstep", [[a] for a in ids], True),
             ("processes, free", [[a] for a in ids], False), ("two hosts, lockstep", [ids[:half], ids[half:]], True)]
    results: dict[str, list[Result]] = {name: [] for name, _, _ in plans}
    for rep in range(args.repeats):
        for name, groups, lockstep in plans:
            r = arrange(rec, name, groups, lockstep, args.warmup)
            results[name].append(r)
            print(f"rep {rep + 1} {name}: step median {r.median_ms:.3f} ms, mean {r.mean_ms:.3f} ms, "
                  f"wall {r.wall_s:.1f} s, {r.cores:.2f} cores{'' if r.same else ', DECISIONS DIFFER'}",
                  file=sys.stderr, flush=True)
    base = statistics.median(r.median_ms for r in results["one process"])
    print(f"{args.scenario.name}, {args.agents} agents, {args.ticks} ticks ({args.warmup} left out), "
          f"{os.cpu_count()} cores, {args.repeats} repetitions, medians of the repetitions\n")
    print("| arrangement | step CPU median ms | mean ms | against one process | wall s | cores busy | same decisions |")
    print("|---|---:|---:|---:|---:|---:|---|")
    for name, rs in results.items():
        med = statistics.median(r.median_ms for r in rs)
        print(f"| {name} | {med:.3f} | {statistics.median(r.mean_ms for r in rs):.3f} | {med / base:.2f}x | "
              f"{statistics.median(r.wall_s for r in rs):.1f} | {statistics.median(r.cores for r in rs):.2f} | "
              f"{'yes' if all(r.same for r in rs) else 'no'} |")
    return 0 if all(r.same for rs in results.values() for r in rs) else 1


if __name__ == "__main__":
    raise SystemExit(main())

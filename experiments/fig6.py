"""Fig. 6 (paper §4.5): the diamond built beyond a food-and-water wall, and repaired (Fig. 6b).

    python3 -m experiments.fig6 --jobs 2                       # the default agent, 20 seeds
    python3 -m experiments.fig6 --jobs 2 --agent paper         # the paper's agent
    python3 -m experiments.fig6 --jobs 2 --agent paper --without ghost_association

For each seed, in process (`conag.sim`, lockstep, hunger and thirst on as in the scenario):

* build: scenarios/fig6.toml with its three agents (what `conag run scenarios/fig6.toml`
  starts), until complete, stalled (no site filled for `--stall` ticks) or the scenario's
  `max_ticks`;
* repair (Fig. 6b): one agent; once two sites are filled, the brick of the first is removed
  (as in tests/test_agent.py), and the run goes on until the structure is complete again,
  stalled or out of ticks.

Fig. 6c (a gap opened in the wall) is not measured here. Writes experiments/fig6{SUFFIX}.json
(no suffix for the default agent; `_paper`, `_paper-ghost_association`, ...); the table
(experiments/fig6.md) and the `fig6` section of docs/results/experiments.md have one row
per agent whose json is there.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from experiments import runner
from experiments.agents import Agent, add_arguments, chosen
from experiments.report import RESULTS_DOC, write_section
from protocol.messages import Perturbation
from world_server.scenario import load_scenario

ROOT = Path(__file__).resolve().parent.parent
SCENARIO = ROOT / "scenarios" / "fig6.toml"
STEM = "fig6"


@dataclass(frozen=True)
class Job:
    task: str          # "build" or "repair"
    seed: int
    agent: Agent
    stall: int


@dataclass(frozen=True)
class Run:
    task: str
    seed: int
    agent: str         # Agent.label
    completed: bool
    ticks: int         # build: to the end; repair: from the removal to the end (-1: no removal)
    distance: float    # walked by all agents, world units


def run_one(job: Job) -> Run:
    """One build or repair (see the module)."""
    from conag import sim

    sc = load_scenario(SCENARIO)
    cfg = job.agent.config()
    if job.task == "build":
        run = sim.start(sc, seed=job.seed, cfg=cfg)
        result = run.run(sc.max_ticks, stall_ticks=job.stall)
        return Run("build", job.seed, job.agent.label, result.completed, result.ticks,
                   float(sum(run.world.status().agent_distance)))
    run = sim.start(sc, agents=1, seed=job.seed, cfg=cfg)
    two = run.run(sc.max_ticks, stall_ticks=job.stall, stop=[lambda r: r.world.sites_filled().sum() >= 2])
    if not two.stopped:   # two sites were never filled: nothing to repair
        return Run("repair", job.seed, job.agent.label, False, -1, float(sum(run.world.status().agent_distance)))
    first = int(np.flatnonzero(run.world.sites_filled())[0])
    x, y = run.world.sites_xy[first]
    assert run.world.perturb(Perturbation("remove", float(x), float(y))).ok
    removed_at = run.world.tick
    result = run.run(sc.max_ticks - removed_at, stall_ticks=job.stall)
    return Run("repair", job.seed, job.agent.label, result.completed, result.ticks - removed_at,
               float(sum(run.world.status().agent_distance)))


def _median(values: list[float], fmt: str = ",.0f") -> str:
    return format(statistics.median(values), fmt) if values else "-"


def table(rows: dict[str, list[Run]]) -> str:
    """One row per agent (label -> its runs)."""
    lines = [("| agent | build: completed | build: median ticks | build: median distance "
              "| repair: completed | repair: median ticks after the removal |"),
             "|---|---:|---:|---:|---:|---:|"]
    for label, runs in rows.items():
        build = [r for r in runs if r.task == "build"]
        repair = [r for r in runs if r.task == "repair"]
        done_b = [r for r in build if r.completed]
        done_r = [r for r in repair if r.completed]
        lines.append(f"| {label} | {len(done_b)}/{len(build)} | {_median([r.ticks for r in done_b])} | "
                     f"{_median([r.distance for r in done_b])} | {len(done_r)}/{len(repair)} | "
                     f"{_median([r.ticks for r in done_r])} |")
    return "\n".join(lines)


def measured(out: Path) -> dict[str, list[Run]]:
    """Every agent's runs found in `out` (fig6.json first, then the others by name)."""
    files = sorted(out.glob(f"{STEM}*.json"), key=lambda p: (p.stem != STEM, p.stem))
    rows = {}
    for path in files:
        runs = [Run(**r) for r in json.loads(path.read_text(encoding="utf-8"))]
        if runs:
            rows[runs[0].agent] = runs
    return rows


def report(tab: str, seeds: int, stall: int) -> str:
    return f"""## Fig. 6: the diamond beyond the wall, built and repaired (issue 33) {{#fig6}}

```sh
python3 -m experiments.fig6 --jobs 2                  # the default agent: experiments/fig6.json
python3 -m experiments.fig6 --jobs 2 --agent paper    # the paper's agent: experiments/fig6_paper.json
python3 -m experiments.fig6 --jobs 2 --agent paper --without ghost_association
```

`scenarios/fig6.toml` in process, seeds 1 to {seeds}, hunger and thirst on. Build: its three
agents, as `conag run scenarios/fig6.toml` starts them. Repair (Fig. 6b): one agent; once two
sites are filled the first one's brick is removed, and the structure must be completed again.
A run stops when complete, after {stall} ticks with no site filled (stalled) or at the scenario's
30,000 ticks. Medians are over the completed runs; distance is all agents', in world units.

{tab}
"""


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_arguments(ap)
    ap.add_argument("--seeds", type=int, default=20, help="seeds 1..N per task (default 20)")
    ap.add_argument("--stall", type=int, default=3000, help="ticks with no site filled that stop a run")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    runner.add_cluster_argument(ap)
    ap.add_argument("--out", type=Path, default=ROOT / "experiments", help="folder for the json and md")
    ap.add_argument("--doc", default=str(RESULTS_DOC), help="markdown report to update (fig6 section)")
    args = ap.parse_args(argv)
    agent = chosen(ap, args)
    jobs = [Job(task, seed, agent, args.stall) for task in ("build", "repair") for seed in range(1, args.seeds + 1)]
    done: dict[Job, Run] = {}
    try:
        for k, d in enumerate(runner.run(run_one, jobs, runner.where_of(args, args.jobs)), 1):
            r = done[d.job] = d.result
            print(f"[{k}/{len(jobs)}] {r.task} seed {r.seed} {r.agent}: "
                  f"{'complete' if r.completed else 'not complete'} ({r.ticks} ticks, {d.worker})",
                  file=sys.stderr, flush=True)
    except runner.ClusterError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    args.out.mkdir(parents=True, exist_ok=True)
    runs = [done[j] for j in jobs]
    (args.out / f"{STEM}{agent.suffix}.json").write_text(json.dumps([asdict(r) for r in runs], indent=1) + "\n",
                                                         encoding="utf-8")
    tab = table(measured(args.out))
    (args.out / f"{STEM}.md").write_text(tab + "\n", encoding="utf-8")
    write_section(args.doc, "fig6", report(tab, args.seeds, args.stall))
    print(tab)
    return 0


if __name__ == "__main__":
    raise SystemExit(runner.by_name(main)())

"""Issue 37 item 5: a society of foremen and workers against teams of ConAg agents.

    python3 -m experiments.society --quick          # 3 small layouts, F = 1, W = 4: society_quick.md
    python3 -m experiments.society --jobs 2         # the sample, F = 2, W = 4, 10, 30: society.md
    python3 -m experiments.society --report-only    # the table again from society.json

The sample: the first SAMPLE layouts of the generated suite that `experiments.noise` uses
(longer side at most 30 cells; made from the suite's committed manifest). Each is built in
process (`conag.sim`, lockstep) by, for each W of `--workers`:

* `society F+W`: F foremen and W workers (`conag.sim.society.start_society`);
* `ConAg F+W`: as many ConAg agents (the default agent);

and once by `ConAg F`: the foremen's number of ConAg agents alone. The layout's own agent
count is ignored. A run stops when complete, after `--stall` ticks with no site filled (as
the generalisation suite), or at the layout's `max_ticks`. A team that does not fit in the
world (no free start cell left) is reported as not started.

Reported per team: completion, the median ticks of completed runs and, over layouts both
teams completed, the median ratio of its ticks to `ConAg F`'s; total distance; bricks left
misplaced (`experiments.noise.misplaced_bricks`); CPU per tick: the members' decision steps
summed (thread CPU time), and the world's step. Every run is reproduced by its seed.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from agent_runtime.config import AgentConfig
from conag import sim
from conag.sim.society import start_society
from experiments import runner
from experiments.generalisation import DEFAULT_STALL, LAYOUTS, family_of, stall_limit
from experiments.noise import misplaced_bricks, quick_sample, sample
from experiments.report import RESULTS_DOC, write_section
from world_server.scenario import parse_scenario

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "experiments"
SAMPLE = 40
QUICK_LAYOUTS = 3


@dataclass(frozen=True)
class Job:
    layout: str
    team: str          # "society F+W", "ConAg N"
    foremen: int
    workers: int       # 0 for a ConAg team of `foremen` agents
    stall: int
    text: str = field(default="", repr=False)
    seed_offset: int = 0  # added to the layout's seed, for the world and every member


@dataclass(frozen=True)
class Outcome:
    layout: str
    family: str
    team: str
    started: bool
    completed: bool
    ticks: int
    sites_filled: int
    sites_total: int
    distance: float
    misplaced: int
    worker_drops: int     # bricks the workers laid on sites (society only; not those taken back)
    agent_ms: float       # the members' decision steps per tick, CPU ms
    world_ms: float       # the world's step per tick, CPU ms


def teams(foremen: int, workers: list[int]) -> list[tuple[str, int, int]]:
    """(name, foremen or agents, workers) of every team, in table order."""
    out = [(f"ConAg {foremen}", foremen, 0)]
    for w in workers:
        out += [(f"society {foremen}+{w}", foremen, w), (f"ConAg {foremen + w}", foremen + w, 0)]
    return out


def run_one(job: Job) -> Outcome:
    """Build one layout with one team, timing every decision step and world step."""
    sc = parse_scenario(job.text, job.layout)
    seed = sc.seed + job.seed_offset
    try:
        run = (start_society(sc, job.foremen, job.workers, seed=seed) if job.workers
               else sim.start(sc, agents=job.foremen, cfg=AgentConfig(), seed=seed))
    except RuntimeError:  # no free cell left for a body: the team does not fit in this world
        return Outcome(job.layout, family_of(sc), job.team, False, False, 0, 0, 0, 0.0, 0, 0, 0.0, 0.0)
    start_cells = sc.to_cell(run.world.discs.xy)
    spent = {"agents": 0.0, "world": 0.0}
    clock = time.thread_time

    def step() -> None:
        t0 = clock()
        for frame in run.world.frames():
            s = run.brains[frame.agent_id].step(frame)
            run.world.set_command(frame.agent_id, s.speed, s.turn, s.action, s.mark)
        t1 = clock()
        run.world.step()
        run._record_fills()
        spent["agents"] += t1 - t0
        spent["world"] += clock() - t1

    run.step = step  # type: ignore[method-assign] -- the loop's step, timed
    result = run.run(sc.max_ticks, stall_ticks=stall_limit(sc, job.stall))
    st = run.world.status()
    ticks = max(result.ticks, 1)
    # Bricks the workers laid: their drops less those that took a brick back to a supply.
    workers = sum(d for a, d in zip(st.agent_ids, st.agent_drops) if a.startswith("w")) - sum(
        getattr(run.brains[a], "returns", 0) for a in st.agent_ids if a.startswith("w"))
    return Outcome(job.layout, family_of(sc), job.team, True, result.completed, result.ticks, st.sites_filled,
                   st.sites_total, round(float(sum(st.agent_distance)), 1), misplaced_bricks(run, start_cells),
                   workers, round(1e3 * spent["agents"] / ticks, 3), round(1e3 * spent["world"] / ticks, 3))


def _median(values: list[float], fmt: str) -> str:
    return format(statistics.median(values), fmt) if values else "—"


def table(outcomes: list[Outcome], order: list[str]) -> str:
    """One row per team."""
    base_name = order[0]
    base = {o.layout: o for o in outcomes if o.team == base_name}
    lines = ["| team | completed | ticks (median, completed) | ticks / " + base_name + " (median) "
             "| distance (median) | misplaced bricks | bricks laid by workers | CPU ms per tick: decisions "
             "| CPU ms per tick: world |",
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for team in order:
        runs = [o for o in outcomes if o.team == team]
        if not runs:
            continue
        started = [o for o in runs if o.started]
        done = [o for o in started if o.completed]
        ratios = [o.ticks / base[o.layout].ticks for o in done
                  if team != base_name and o.layout in base and base[o.layout].completed]
        unfit = len(runs) - len(started)
        lines.append(
            f"| {team} | {len(done)}/{len(runs)} ({100 * len(done) / len(runs):.0f}%)"
            + (f", {unfit} did not fit" if unfit else "")
            + f" | {_median([o.ticks for o in done], '.0f')} | {_median(ratios, '.2f')} "
            f"| {_median([o.distance for o in started], '.0f')} | {sum(o.misplaced for o in started)} "
            f"| {sum(o.worker_drops for o in started) if team.startswith('society') else '—'} "
            f"| {_median([o.agent_ms for o in started], '.2f')} | {_median([o.world_ms for o in started], '.2f')} |")
    return "\n".join(lines)


def failures(outcomes: list[Outcome]) -> str:
    """Where societies did not complete: layout, family, sites filled, bricks by workers."""
    bad = [o for o in outcomes if o.team.startswith("society") and o.started and not o.completed]
    if not bad:
        return "Every society run that started completed."
    rows = ["| team | layout | family | sites filled | bricks laid by workers |", "|---|---|---|---:|---:|"]
    rows += [f"| {o.team} | {o.layout} | {o.family} | {o.sites_filled}/{o.sites_total} | {o.worker_drops} |"
             for o in bad]
    return "\n".join(rows)


def markdown(outcomes: list[Outcome], args: argparse.Namespace, order: list[str]) -> str:
    layouts = sorted({o.layout for o in outcomes})
    command = "python3 -m experiments.society " + ("--quick" if args.quick else f"--jobs {args.jobs}") + "".join(
        f" --{flag} {value}" for flag, value in (("workers", args.workers), ("seed-offset", args.seed_offset))
        if value)
    which = (f"the {QUICK_LAYOUTS} cheapest to build of" if args.quick
             else "all of" if len(layouts) >= args.sample
             else f"the sweep stopped part way: the first {len(layouts)} of")
    return f"""## A society of foremen and workers (issue 37) {{#society}}

`{command}` builds {len(layouts)} generated layouts ({which} the first {SAMPLE} of the suite
of `experiments.generalisation` whose longer side is at most 30 cells, as `experiments.noise`)
with each team below, in process (`conag.sim`, lockstep; the layout's own agent count
ignored). A run stops when complete, after {args.stall} ticks with no site filled, or at the
layout's `max_ticks`. Every run is reproduced by its seed; the CPU columns are not (the
machine's load moves them). See [Cues, foremen and workers](../docs/society.md).

{table(outcomes, order)}

- *ticks / {order[0]}*: over the layouts completed by both, the median ratio of the ticks.
- *misplaced bricks*: bricks left in one of the 8 cells around a site but on no site, moved
  there by an agent (`experiments.noise.misplaced_bricks`), summed over the runs.
- *bricks laid by workers*: the workers' drops, less the bricks they took back beside a
  supply cue (bricks no site cue in sight wanted), summed over the runs.
- *CPU ms per tick*: thread CPU time, per tick, of every member's decision step summed
  (*decisions*), and of the world's step; the median over the runs.

Societies that did not complete:

{failures(outcomes)}
"""


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help=f"{QUICK_LAYOUTS} small layouts, F = 1, W = 4")
    ap.add_argument("--sample", type=int, default=SAMPLE, help=f"layouts in the sample (default {SAMPLE})")
    ap.add_argument("--foremen", type=int, help="F (default 2; 1 with --quick)")
    ap.add_argument("--workers", help="W, comma separated (default 4,10,30; 4 with --quick)")
    ap.add_argument("--stall", type=int, default=DEFAULT_STALL, help="ticks without a site filled that end a run")
    ap.add_argument("--seed-offset", type=int, default=0,
                    help="add this to every layout's seed (worlds and members; another draw of the same "
                         "sweep): writes society_seeds+N.json and .md, and leaves the results page alone")
    ap.add_argument("--report-only", action="store_true", help="the tables again from the JSON")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    runner.add_cluster_argument(ap)
    args = ap.parse_args()
    foremen = args.foremen or (1 if args.quick else 2)
    workers = [int(w) for w in (args.workers or ("4" if args.quick else "4,10,30")).split(",")]
    order = [name for name, _, _ in teams(foremen, workers)]
    stem = ("society_quick" if args.quick else "society") + (f"_seeds{args.seed_offset:+d}" if args.seed_offset else "")
    path = OUT / f"{stem}.json"
    if args.report_only:
        outcomes = [Outcome(**o) for o in json.loads(path.read_text(encoding="utf-8"))]
        # A sweep stopped part way: only the layouts every team has built.
        whole = {o.layout for o in outcomes if sum(p.layout == o.layout for p in outcomes) == len(order)}
        outcomes = sorted((o for o in outcomes if o.layout in whole), key=lambda o: (order.index(o.team), o.layout))
    else:
        names = sample(args.sample)
        if args.quick:
            names = quick_sample(names, QUICK_LAYOUTS)
        jobs = [Job(name, team, f, w, args.stall, (LAYOUTS / name).read_text(encoding="utf-8"), args.seed_offset)
                for name in names for team, f, w in teams(foremen, workers)]
        outcomes, began = [], time.monotonic()
        for done in runner.run(run_one, jobs, runner.where_of(args, args.jobs)):
            o = done.result
            outcomes.append(o)
            print(f"[{len(outcomes)}/{len(jobs)} {time.monotonic() - began:5.0f} s] {o.layout} {o.team}: "
                  f"{'complete' if o.completed else 'NOT complete'} in {o.ticks} ticks", file=sys.stderr, flush=True)
            # As it goes: a sweep stopped part way still leaves its runs (--report-only tables them).
            path.write_text(json.dumps([asdict(o) for o in outcomes], indent=1) + "\n", encoding="utf-8")
        outcomes.sort(key=lambda o: (order.index(o.team), o.layout))
        path.write_text(json.dumps([asdict(o) for o in outcomes], indent=1) + "\n", encoding="utf-8")
    text = markdown(outcomes, args, order)
    (OUT / f"{stem}.md").write_text(text, encoding="utf-8")
    if not args.quick and not args.seed_offset:  # the results page holds the sample's table
        write_section(RESULTS_DOC, "society", text.replace("../docs/", "../"))
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(runner.by_name(main)())

"""Issue 36, item 4: ConAg's distance against the least distance any plan needs, on small layouts.

Small generated layouts (15 x 15 cells, 6 to 8 open sites, `world_server.generator` with
`max_sites=8`; the wall, ring, pocket and polyomino families in turn) are solved exactly
(`experiments/optimal_plan.py`: the least total distance, every brick known, in its grid
model) and built by the default agent in-process (conag/sim, lockstep; hunger and thirst
off, so every step is construction), 1 agent on most and 2 agents on a few, several seeds.

Reported per layout: the optimum; the ideal-order replay (`experiments/replay.replay`:
goal sequencing on the fully known map) costed in the optimum's model; ConAg's distance
(median over seeds); and what ConAg's excess over the optimum is made of, from the
behaviour each agent ran on each tick and the (brick, site) trips it made:

* order: its own trips, walked as short as the model allows, less the optimum (the
  bricks and sites it chose, and their order);
* explore: distance walked while exploring (no matched brick or site in its maps);
* approach: distance walked while approaching a brick to grab it (approach_red: slowing,
  turning to face it);
* other: avoid, unstick, anything else;
* path: the rest of the distance, walked navigating to a brick or a site, beyond the
  model's shortest trips (arcs and detours; the continuous world also allows a little
  less than grid paths, so this can be negative).

Each part is a fraction of the optimum, so ratio = 1 + order + explore + approach + other + path.

    python3 -m experiments.optimum            # full run (tens of minutes on a loaded machine)
    python3 -m experiments.optimum --quick    # a few layouts, one seed; writes to --out

Writes experiments/optimum.json, experiments/optimum.md and the optimum section of
docs/results/experiments.md (not with --quick).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from collections import Counter
from concurrent.futures import as_completed
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from agent_runtime.config import AgentConfig
from conag import sim
from experiments.optimal_plan import SearchBudgetExceeded, optimal_plan, plan_distance
from experiments.replay import replay
from experiments.report import RESULTS_DOC, write_section
from experiments.workers import pool
from world_server.discs import BRICK_DISC, CARRIED
from world_server.generator import generate
from world_server.scenario import Scenario, parse_scenario

ROOT = Path(__file__).resolve().parent.parent
FAMILIES = ("wall", "ring", "pocket", "polyomino")
SIZE = 15
MAX_SITES = 8
SUITE_SEED = 36_000         # layout i is generate(SUITE_SEED + i, ...)
ONE_AGENT, TWO_AGENTS = 32, 8
SEEDS = (1, 2, 3)
STALL = 3000
TWO_AGENT_BUDGET = 60_000   # states the 2-agent search may expand
TARGET = 1.3                # the goal: median ConAg / optimum with 1 agent
PARTS = ("order", "explore", "approach", "other", "path")


@dataclass(frozen=True)
class Layout:
    index: int
    seed: int
    family: str
    agents: int

    def scenario(self) -> Scenario:
        g = generate(self.seed, family=self.family, size=SIZE, agents=self.agents, max_sites=MAX_SITES)
        return parse_scenario(g.text, f"<{g.name}>")


@dataclass(frozen=True)
class Live:
    """One live build."""

    seed: int
    completed: bool
    ticks: int
    distance: float
    own: float                                  # its trips costed in the model (inf: not in the model)
    by_behaviour: dict[str, float] = field(default_factory=dict)  # distance walked per behaviour


@dataclass(frozen=True)
class Result:
    layout: Layout
    name: str
    sites: int
    bricks: int
    optimum: float              # inf: over the search budget
    expanded: int
    ideal: float | None         # the ideal-order replay costed in the model (1 agent)
    runs: tuple[Live, ...]
    seconds: float


def layouts(quick: bool) -> list[Layout]:
    one, two = (4, 0) if quick else (ONE_AGENT, TWO_AGENTS)
    out = [Layout(i, SUITE_SEED + i, FAMILIES[i % len(FAMILIES)], 1) for i in range(one)]
    return out + [Layout(one + i, SUITE_SEED + 500 + i, FAMILIES[i % len(FAMILIES)], 2) for i in range(two)]


def _grids(sc: Scenario) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    return sc.grid("b"), sc.grid("+"), sc.grid("FWB#")


def run_live(sc: Scenario, seed: int, starts: list[tuple[int, int]]) -> Live:
    """Build once; keep the distance per behaviour and the trips (brick, site) made."""
    run = sim.start(sc, seed=seed, cfg=AgentConfig(hunger_rate=0.0, thirst_rate=0.0))
    world = run.world
    is_brick = world.discs.kind == BRICK_DISC
    brick_cell = {int(i): tuple(int(v) for v in c[::-1])
                  for i, c in zip(np.flatnonzero(is_brick), sc.to_cell(world.discs.xy[is_brick]))}
    status = world.status()
    ids = status.agent_ids
    last = {"distance": list(status.agent_distance), "grabs": list(status.agent_grabs),
            "drops": list(status.agent_drops), "carried": set()}
    held: dict[int, tuple[int, int]] = {}
    trips: list[tuple[int, tuple[int, int], tuple[int, int]]] = []
    walked: Counter = Counter()

    def observe(r: sim.SimRun) -> None:
        st = r.world.status()
        carried = {int(i) for i in np.flatnonzero(r.world.discs.state == CARRIED)}
        new = sorted(carried - last["carried"])
        for a, agent_id in enumerate(ids):
            walked[r.behaviours.get(agent_id, "none")] += st.agent_distance[a] - last["distance"][a]
            if st.agent_grabs[a] > last["grabs"][a] and new:
                held[a] = brick_cell.get(new.pop(0), (-1, -1))
            if st.agent_drops[a] > last["drops"][a] and a in held:
                xy = np.array([[st.agent_x[a], st.agent_y[a]]])
                site = tuple(int(v) for v in sc.to_cell(xy)[0][::-1])
                trips.append((a, held.pop(a), site))
        last.update(distance=list(st.agent_distance), grabs=list(st.agent_grabs), drops=list(st.agent_drops),
                    carried=carried)

    result = run.run(sc.max_ticks, stall_ticks=STALL, observers=[observe])
    own = plan_distance(*_grids(sc), starts, trips).distance if result.completed else np.inf
    return Live(seed, result.completed, result.ticks, float(sum(world.status().agent_distance)), float(own),
                {k: float(v) for k, v in walked.items()})


def solve(lay: Layout, seeds: tuple[int, ...]) -> Result:
    began = time.perf_counter()
    sc = lay.scenario()
    run = sim.start(sc, seed=seeds[0])
    starts = [tuple(int(v) for v in c[::-1]) for c in sc.to_cell(run.world.agent_poses()[:, :2])]
    grids = _grids(sc)
    budget = TWO_AGENT_BUDGET if lay.agents > 1 else 10 * TWO_AGENT_BUDGET
    try:
        opt = optimal_plan(*grids, starts, max_expanded=budget)
        optimum, expanded = opt.distance, opt.expanded
    except SearchBudgetExceeded:
        optimum, expanded = np.inf, budget
    ideal = None
    if lay.agents == 1:
        r = replay(*grids, starts[0])
        ideal = plan_distance(*grids, starts, [(0, b, s) for b, s in r.order]).distance if r.completed else np.inf
    runs = tuple(run_live(sc, s, starts) for s in seeds)
    return Result(lay, sc.name, int(grids[1].sum()), int(grids[0].sum()), float(optimum), expanded,
                  None if ideal is None else float(ideal), runs, time.perf_counter() - began)


def parts(res: Result, live: Live) -> dict[str, float] | None:
    """What a completed run's excess over the optimum is made of, as fractions of it."""
    if not live.completed or not np.isfinite(live.own) or not np.isfinite(res.optimum) or res.optimum <= 0:
        return None
    b = live.by_behaviour
    explore, approach = b.get("explore", 0.0), b.get("approach_red", 0.0)
    nav = {"brick_nav", "config_nav", "grab", "drop"}
    other = sum(v for k, v in b.items() if k not in nav | {"explore", "approach_red"})
    path = live.distance - live.own - explore - approach - other
    out = dict(order=live.own - res.optimum, explore=explore, approach=approach, other=other, path=path)
    return {k: v / res.optimum for k, v in out.items()}


def _median(xs: list[float]) -> float:
    return float(statistics.median(xs)) if xs else float("nan")


def summary(results: list[Result]) -> dict:
    out: dict = {}
    for agents in sorted({r.layout.agents for r in results}):
        rs = [r for r in results if r.layout.agents == agents and np.isfinite(r.optimum)]
        conag = [live.distance / r.optimum for r in rs for live in r.runs if live.completed]
        per_layout = [_median([lv.distance / r.optimum for lv in r.runs if lv.completed]) for r in rs
                      if any(lv.completed for lv in r.runs)]
        split = [p for r in rs for lv in r.runs if (p := parts(r, lv)) is not None]
        out[str(agents)] = dict(
            layouts=len([r for r in results if r.layout.agents == agents]), solved=len(rs),
            runs=sum(len(r.runs) for r in rs), completed=len(conag),
            conag_median=_median(conag), conag_layout_median=_median(per_layout),
            conag_quartiles=[float(np.percentile(conag, q)) for q in (25, 75)] if conag else [],
            ideal_median=_median([r.ideal / r.optimum for r in rs if r.ideal is not None and np.isfinite(r.ideal)]),
            parts={k: _median([p[k] for p in split]) for k in PARTS},
            parts_mean={k: float(np.mean([p[k] for p in split])) if split else float("nan") for k in PARTS})
    return out


def _f(v: float | None, fmt: str = ".2f") -> str:
    return "-" if v is None or not np.isfinite(v) else format(v, fmt)


def table(results: list[Result]) -> str:
    lines = [("| layout | agents | sites | bricks | optimum (cells) | ideal order / optimum | ConAg / optimum "
              "(median of seeds) | completed | own trips / optimum |"),
             "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in results:
        done = [lv for lv in r.runs if lv.completed]
        ratio = _median([lv.distance / r.optimum for lv in done]) if np.isfinite(r.optimum) else None
        own = _median([lv.own / r.optimum for lv in done if np.isfinite(lv.own)]) if np.isfinite(r.optimum) else None
        ideal = None if r.ideal is None or not np.isfinite(r.optimum) else r.ideal / r.optimum
        lines.append(f"| {r.name} | {r.layout.agents} | {r.sites} | {r.bricks} | "
                     f"{_f(r.optimum, '.1f') if np.isfinite(r.optimum) else 'over budget'} | {_f(ideal)} | "
                     f"{_f(ratio)} | {len(done)}/{len(r.runs)} | {_f(own)} |")
    return "\n".join(lines)


def summary_table(s: dict) -> str:
    lines = [("| agents | layouts (solved) | runs completed | ConAg / optimum: median (quartiles) "
              "| ideal order / optimum: median | excess: order | explore | approach | other | path |"),
             "|---:|---|---|---|---:|---:|---:|---:|---:|---:|"]
    for agents, v in s.items():
        q = v["conag_quartiles"]
        quart = f" ({q[0]:.2f}-{q[1]:.2f})" if q else ""
        p = v["parts"]
        lines.append(f"| {agents} | {v['layouts']} ({v['solved']}) | {v['completed']}/{v['runs']} | "
                     f"{_f(v['conag_median'])}{quart} | {_f(v['ideal_median'])} | "
                     + " | ".join(f"{_f(p[k], '+.2f')}" for k in PARTS) + " |")
    return "\n".join(lines)


def report(results: list[Result], quick: bool) -> str:
    s = summary(results)
    one = s.get("1", {})
    met = one and one["conag_median"] <= TARGET
    cmd = "python3 -m experiments.optimum" + (" --quick" if quick else "")
    return f"""## Distance against the optimum (issue 36) {{#optimum}}

`{cmd}` ({'writes to --out' if quick else 'writes this section, experiments/optimum.md and optimum.json'}).
Small generated layouts ({SIZE} x {SIZE} cells, at most {MAX_SITES} open sites, wall, ring,
pocket and polyomino in turn; layout i is `generate({SUITE_SEED} + i, family, size={SIZE},
max_sites={MAX_SITES})`, 2-agent ones from seed {SUITE_SEED + 500}) are solved exactly by
`experiments/optimal_plan.py`: A* over (sites filled, bricks taken, where each agent stands),
each transition one trip (walk to beside a brick, grab it, carry it to a site), with an
admissible lower bound, so the first finished plan is a least-distance one. The model: cells,
8-connected moves (diagonals sqrt 2, no corner cutting), free bricks and filled sites block,
a brick is grabbed from one of its 4 neighbours, every brick is known from the start. With 2
agents the plan is a sequence of whole trips (each by either agent). The live runs (seeds
{', '.join(map(str, SEEDS))}; hunger and thirst off) walk in the continuous world, which allows
paths up to 8% shorter than grid paths, so a ratio slightly under 1 is possible.

{summary_table(s)}

The excess columns are medians over completed runs, each a fraction of the optimum: **order** =
the run's own trips (the bricks and sites it chose, in its order) walked as short as the model
allows, less the optimum; **explore** = distance walked exploring; **approach** = distance walked
approaching a brick to grab it (approach_red); **other** = avoid, unstick and the rest; **path**
= what remains, navigating to bricks and sites beyond the model's shortest trips (arcs, detours).

Goal (median ConAg / optimum with 1 agent at most {TARGET}): **{'met' if met else 'not met'}**
(median {_f(one.get('conag_median'))}; per-layout median {_f(one.get('conag_layout_median'))}).

<details><summary>Every layout</summary>

{table(results)}

</details>
"""


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="4 layouts, one seed; writes to --out")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--out", type=Path, default=None, help="folder for optimum.json and .md (default experiments/)")
    args = ap.parse_args(argv)
    seeds = SEEDS[:1] if args.quick else SEEDS
    out = args.out or (ROOT / "out" / "optimum-quick" if args.quick else ROOT / "experiments")
    out.mkdir(parents=True, exist_ok=True)
    todo = layouts(args.quick)
    results = []
    with pool(args.jobs) as ex:
        futures = [ex.submit(solve, lay, seeds) for lay in todo]
        for k, fut in enumerate(as_completed(futures), 1):
            r = fut.result()
            results.append(r)
            done = sum(lv.completed for lv in r.runs)
            print(f"[{k}/{len(todo)}] {r.name} ({r.layout.agents} agent(s), {r.sites} sites): optimum "
                  f"{r.optimum:.1f} ({r.expanded} states), ConAg {[round(lv.distance, 1) for lv in r.runs]} "
                  f"({done}/{len(r.runs)} completed), {r.seconds:.0f} s", file=sys.stderr, flush=True)
    results.sort(key=lambda r: r.layout.index)
    data = dict(summary=summary(results), results=[asdict(r) for r in results])
    (out / "optimum.json").write_text(json.dumps(data, indent=1, default=float) + "\n", encoding="utf-8")
    text = report(results, args.quick)
    (out / "optimum.md").write_text(text, encoding="utf-8")
    if not args.quick:
        write_section(RESULTS_DOC, "optimum", text)
    print(summary_table(data["summary"]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

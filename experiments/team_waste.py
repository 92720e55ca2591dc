"""Issue 36, item 2's diagnosis: where a big team's agent-ticks and distance go.

Runs layouts of `experiments.team_size` in-process (lockstep, the default agent or one
with `--with`/`--without` additions) and watches every agent on sampled ticks:

* **why an agent is idle** (behaviour explore, or avoid_red while holding a brick):
  it holds no brick and no site is a goal for it (sequencing held every one back, or
  none reachable); it knows no free brick at all (`searching`); it knows free bricks but
  none is reachable; the same but reachable if other agents were not obstacles; it holds
  a brick and has no goal site;
* **where idle agents are**: straight-line distance (cells) to the nearest free brick and
  the nearest open site, as the world has them;
* **contention**: agents heading for the same brick (brick_nav/approach_red, the goal at
  the end of their gradient) or the same site (config_nav), and how many free bricks and
  open sites the world has then;
* **distance by behaviour**: the cells walked on ticks of each behaviour.

    python3 -m experiments.team_waste --layouts gen-ring-3601 gen-multi-3600 --teams 8 32

Prints one table per (layout, team); nothing is written (the figures go in the results page).
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections import Counter
from concurrent.futures import as_completed
from dataclasses import dataclass, field, replace

import numpy as np

from agent_runtime.brain import Brain
from agent_runtime.config import ADDITIONS, AgentConfig
from agent_runtime.esm import AGENT
from conag import sim
from experiments.generalisation import DEFAULT_STALL, stall_limit
from experiments.team_size import layouts
from experiments.workers import pool
from world_server.scenario import parse_scenario

SAMPLE = 10  # ticks between looks at the agents


@dataclass
class Tally:
    """What the watcher counted over one run."""

    samples: int = 0                                            # agent-samples
    behaviours: Counter = field(default_factory=Counter)        # agent-samples per behaviour
    idle: Counter = field(default_factory=Counter)              # idle agent-samples per reason
    idle_to_brick: list = field(default_factory=list)           # cells from an idle agent to the nearest brick
    idle_to_site: list = field(default_factory=list)            # ... and to the nearest open site
    brick_chasers: int = 0                                      # agent-samples heading for a brick ...
    brick_shared: int = 0                                       # ... that another agent heads for too
    site_chasers: int = 0
    site_shared: int = 0
    free_bricks: list = field(default_factory=list)             # per sample: free bricks in the world
    open_sites: list = field(default_factory=list)              # ... open sites
    goal_sites: list = field(default_factory=list)              # per holding agent-sample: goal / open sites on its map
    walked: Counter = field(default_factory=Counter)            # cells walked per behaviour


def _goal_at_end(field_: np.ndarray, start: int) -> tuple[int, int] | None:
    """The goal cell (value 0) the steepest descent from (start, start) ends at, or None."""
    r = c = start
    n = field_.shape[0]
    if not np.isfinite(field_[r, c]):
        return None
    for _ in range(4 * n):
        if field_[r, c] == 0.0:
            return r, c
        best, nxt = field_[r, c], None
        for dr in (-1, 0, 1):
            for dc in (-1, 0, 1):
                rr, cc = r + dr, c + dc
                if (dr or dc) and 0 <= rr < n and 0 <= cc < n and field_[rr, cc] < best:
                    best, nxt = field_[rr, cc], (rr, cc)
        if nxt is None:
            return None   # a far goal beyond the border: no cell on the map
        r, c = nxt
    return None


def _world_cell(brain: Brain, pose: np.ndarray, cell: tuple[int, int], size: float) -> tuple[int, int]:
    dx, dy = brain.maps.offset_of(*cell)
    return math.floor(pose[0] / size + dx), math.floor(pose[1] / size + dy)


def _idle_reason(brain: Brain, holding: bool) -> str:
    p, c = brain.plans, brain.centre
    if holding:
        return "holding, no goal site"
    if not np.isfinite(p.config[c, c]):
        return "no goal site"
    if brain.searching():
        return "knows no free brick"
    clear = p.brick_obstacles & ~(brain.maps.maps[AGENT] > 0.5)
    if np.isfinite(brain._field(p.brick_goals, clear, brain.far.far_bricks(), "team_waste")[c, c]):
        return "bricks blocked by agents"
    return "bricks known, none reachable"


class Watcher:
    """A loop observer: tallies the agents every SAMPLE ticks and the distance every tick."""

    def __init__(self, run: sim.SimRun):
        self.t = Tally()
        self.size = run.world.scenario.world.cell_size
        self.last = np.array(run.world.status().agent_distance)

    def __call__(self, run: sim.SimRun) -> None:
        status = run.world.status()
        now = np.array(status.agent_distance)
        for k, a in enumerate(status.agent_ids):
            self.t.walked[run.behaviours.get(a, "none")] += (now[k] - self.last[k]) / self.size
        self.last = now
        if run.world.tick % SAMPLE == 0:
            self._sample(run)

    def _sample(self, run: sim.SimRun) -> None:
        view = run.world.view()
        kinds = np.array(view.disc_kinds)
        discs = np.column_stack([view.disc_xs, view.disc_ys])[kinds == "brick"] / self.size if len(kinds) else \
            np.zeros((0, 2))
        sites = np.column_stack([view.site_xs, view.site_ys]) / self.size
        filled = np.array(view.site_filled)
        open_sites = sites[~filled]
        on_site = np.zeros(len(discs), bool)
        if len(discs) and len(sites):
            on_site = (np.hypot(*(discs[:, None, :] - sites[None, :, :]).transpose(2, 0, 1)) < 0.45).any(axis=1)
        free = discs[~on_site]
        self.t.free_bricks.append(len(free))
        self.t.open_sites.append(len(open_sites))
        poses = run.world.agent_poses()
        brick_goal: Counter = Counter()
        site_goal: Counter = Counter()
        for k, (a, brain) in enumerate(run.brains.items()):
            beh = run.behaviours.get(a, "none")
            holding = brain._taken_from is not None
            self.t.samples += 1
            self.t.behaviours[beh] += 1
            p, c = brain.plans, brain.centre
            if p is None:
                continue
            here = poses[k, :2] / self.size
            if beh == "explore" or (holding and beh == "avoid_red"):
                self.t.idle[_idle_reason(brain, holding)] += 1
                if len(free):
                    self.t.idle_to_brick.append(float(np.hypot(*(free - here).T).min()))
                if len(open_sites):
                    self.t.idle_to_site.append(float(np.hypot(*(open_sites - here).T).min()))
            if holding:
                open_on_map = int(brain._nav_inputs(brain.layers()).config_goals.sum())
                if open_on_map:
                    self.t.goal_sites.append(int(p.config_goals.sum()) / open_on_map)
            if beh in ("brick_nav", "approach_red"):
                goal = _goal_at_end(p.brick, c)
                if goal is not None:
                    brick_goal[_world_cell(brain, poses[k], goal, self.size)] += 1
                    self.t.brick_chasers += 1
            elif beh == "config_nav":
                goal = _goal_at_end(p.config, c)
                if goal is not None:
                    site_goal[_world_cell(brain, poses[k], goal, self.size)] += 1
                    self.t.site_chasers += 1
        self.t.brick_shared += sum(n for n in brick_goal.values() if n > 1)
        self.t.site_shared += sum(n for n in site_goal.values() if n > 1)


def watch_one(name: str, text: str, agents: int, seed: int, cfg: AgentConfig) -> tuple[str, int, int, dict, Tally]:
    began = time.perf_counter()
    sc = parse_scenario(text, f"<{name}>")
    run = sim.start(sc, agents=agents, seed=seed, cfg=cfg)
    w = Watcher(run)
    result = run.run(sc.max_ticks, stall_ticks=stall_limit(sc, DEFAULT_STALL), observers=[w])
    status = run.world.status()
    summary = dict(ticks=result.ticks, completed=result.completed, filled=status.sites_filled,
                   sites=status.sites_total, seconds=time.perf_counter() - began,
                   distance=sum(status.agent_distance) / sc.world.cell_size)
    return name, agents, seed, summary, w.t


def _pct(part: float, whole: float) -> str:
    return f"{100 * part / whole:.0f}%" if whole else "-"


def table(name: str, agents: int, summaries: list[dict], tallies: list[Tally]) -> str:
    t = Tally()
    for x in tallies:
        t.samples += x.samples
        t.behaviours.update(x.behaviours)
        t.idle.update(x.idle)
        t.idle_to_brick += x.idle_to_brick
        t.idle_to_site += x.idle_to_site
        t.brick_chasers += x.brick_chasers
        t.brick_shared += x.brick_shared
        t.site_chasers += x.site_chasers
        t.site_shared += x.site_shared
        t.free_bricks += x.free_bricks
        t.open_sites += x.open_sites
        t.goal_sites += x.goal_sites
        t.walked.update(x.walked)
    idle = sum(t.idle.values())
    walked = sum(t.walked.values())
    runs = ", ".join(f"{s['ticks']} ticks " + ("done" if s["completed"] else f"{s['filled']}/{s['sites']}")
                     for s in summaries)
    lines = [f"### {name}, {agents} agents ({runs})",
             "behaviour shares: " + ", ".join(f"{b} {_pct(n, t.samples)}" for b, n in t.behaviours.most_common(8)),
             f"idle (explore, or avoid_red holding): {_pct(idle, t.samples)} of agent-samples; why: "
             + ", ".join(f"{r} {_pct(n, idle)}" for r, n in t.idle.most_common()),
             (f"idle agents: median {np.median(t.idle_to_brick) if t.idle_to_brick else float('nan'):.1f} cells from "
             f"the nearest free brick, {np.median(t.idle_to_site) if t.idle_to_site else float('nan'):.1f} from the "
             "nearest open site"),
             (f"heading for a brick another agent heads for: {_pct(t.brick_shared, t.brick_chasers)} of "
             f"{t.brick_chasers} brick-chasing samples; for a shared site: {_pct(t.site_shared, t.site_chasers)} "
             f"of {t.site_chasers}"),
             (f"holding agents: median {np.median(t.goal_sites) if t.goal_sites else float('nan'):.2f} of the open "
             "sites on their map are goals"),
             f"world: median free bricks {np.median(t.free_bricks):.0f}, open sites {np.median(t.open_sites):.0f}",
             "distance walked (cells) by behaviour: " + ", ".join(f"{b} {_pct(n, walked)}"
                                                              for b, n in t.walked.most_common(6))
             + f" (total {walked:,.0f})"]
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--layouts", nargs="+", default=["gen-ring-3601", "gen-multi-3600"])
    ap.add_argument("--teams", type=int, nargs="+", default=[8, 32])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1])
    ap.add_argument("--with", dest="on", default="", help="additions to switch on (comma-separated)")
    ap.add_argument("--without", default="", help="additions to switch off (comma-separated)")
    ap.add_argument("--jobs", type=int, default=2)
    args = ap.parse_args(argv)
    flags = {**{n: True for n in args.on.split(",") if n}, **{n: False for n in args.without.split(",") if n}}
    unknown = set(flags) - set(ADDITIONS)
    if unknown:
        ap.error(f"unknown addition(s): {', '.join(sorted(unknown))}")
    cfg = replace(AgentConfig(), **flags)
    every = layouts()
    jobs = [(n, every[n], a, s, cfg) for n in args.layouts for a in args.teams for s in args.seeds]
    done: dict[tuple[str, int], list] = {}
    with pool(args.jobs) as ex:
        for fut in as_completed([ex.submit(watch_one, *j) for j in jobs]):
            name, agents, seed, summary, tally = fut.result()
            print(f"{name} {agents} seed {seed}: {summary}", file=sys.stderr, flush=True)
            done.setdefault((name, agents), []).append((summary, tally))
    for (name, agents) in sorted(done, key=lambda k: (args.layouts.index(k[0]), k[1])):
        got = done[name, agents]
        print(table(name, agents, [s for s, _ in got], [t for _, t in got]) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

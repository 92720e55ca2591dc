"""How often agents believe an empty blueprint site filled: what `site_core` buys the maps.

    python3 -m experiments.site_beliefs --jobs 2            # the ablation's 60 layouts: default and -site_core
    python3 -m experiments.site_beliefs --sample 10 --agents default,-ghost_association

`site_core` changes no build of the ablation's 60-layout sample (`experiments.ablation`:
completed 60 of 60 without it, ticks 1.00 of the default's). What it is for is the maps: a
sector that only grazes a site's cell, its reading a structure brick beside the site, no
longer marks the site as holding a brick. This measures that belief against the truth:
every `EVERY` ticks, for every agent, the blueprint sites it believes hold a brick
(`FarMemory.site_open` false: a brick was seen on the site's cell) that the world has
empty. In these runs no brick ever leaves a site, so each such belief is a wrong one: a
ghost brick on a site, not a site filled out of sight. The layouts and agents are the
ablation's (`experiments.ablation.agent_of`), built in process as it builds them.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass

import numpy as np

from conag.sim import SimRun
from experiments import runner
from experiments.ablation import Job, agents_arg, job_of, sample, start_job
from experiments.generalisation import DEFAULT_STALL, stall_limit

EVERY = 10   # ticks between samples


@dataclass(frozen=True)
class Beliefs:
    layout: str
    agent: str
    completed: bool
    ticks: int
    samples: int      # agent-sample pairs
    ghost_sites: int  # over the samples: sites believed filled that the world has empty
    ghost_samples: int  # samples with at least one such site


class GhostCount:
    """A loop observer (`SimRun.run`): every `every` ticks, each agent's sites believed
    filled that the world has empty."""

    def __init__(self, every: int = EVERY):
        self.every = every
        self.samples = self.ghost_sites = self.ghost_samples = 0

    def __call__(self, run: SimRun) -> None:
        if run.world.tick % self.every:
            return
        empty = ~run.world.sites_filled()
        for brain in run.brains.values():
            ghosts = int(np.count_nonzero(~brain.far.site_open & empty))
            self.samples += 1
            self.ghost_sites += ghosts
            self.ghost_samples += ghosts > 0


def run_one(job: Job) -> Beliefs:
    sc, run = start_job(job)
    count = GhostCount()
    result = run.run(sc.max_ticks, stall_ticks=stall_limit(sc, job.stall), observers=[count])
    return Beliefs(job.layout, job.agent, result.completed, result.ticks, count.samples, count.ghost_sites,
                   count.ghost_samples)


def table(rows: list[Beliefs], agents: list[str]) -> str:
    """One row per agent: completion, and the ghost sites per 1,000 agent-samples, summed
    over the layouts, with on how many layouts any sample held one."""
    lines = [("| agent | completed | agent-samples | sites believed filled but empty, per 1,000 samples | "
              "samples with one (%) | layouts with one |"), "|---|---:|---:|---:|---:|---:|"]
    for agent in agents:
        mine = [r for r in rows if r.agent == agent]
        samples = sum(r.samples for r in mine) or 1
        lines.append(f"| {agent} | {sum(r.completed for r in mine)} of {len(mine)} | {samples:,} | "
                     f"{1000 * sum(r.ghost_sites for r in mine) / samples:.1f} | "
                     f"{100 * sum(r.ghost_samples for r in mine) / samples:.2f} | "
                     f"{sum(r.ghost_samples > 0 for r in mine)} |")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sample", type=int, default=60, help="layouts, as the ablation samples them (default 60)")
    ap.add_argument("--agents", default="default,-site_core", help="comma separated (default: default,-site_core)")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    args = ap.parse_args(argv)
    agents = agents_arg(ap, args.agents)
    jobs = [job_of(path, agent, DEFAULT_STALL) for path in sample(args.sample) for agent in agents]
    began, rows = time.monotonic(), []
    for done in runner.run(run_one, jobs, runner.Where(workers=args.jobs)):
        rows.append(done.result)
        print(f"[{len(rows)}/{len(jobs)} {time.monotonic() - began:.0f} s] {done.result}", file=sys.stderr, flush=True)
    print(table(rows, agents))
    return 0


if __name__ == "__main__":
    raise SystemExit(runner.by_name(main)())

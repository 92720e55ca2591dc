"""`python3 -m faults.cutoff`: `faults.partition`'s story, in process and from a seed.

`faults.partition` cuts a host's agents off over a real bus, so what a run meets depends on
the machine's timing, and a failure there (31 of 32 sites on nested_squares, once in about
twenty CI runs) cannot be run again. This runs the same story in one process, lockstep
(`conag.sim`), reproducibly from a seed: agents a1 and a2 stop answering at tick `cut` (three
ticks later the world stops their bodies, as a lockstep world does after three missed
deadlines), are seen dead at tick `dead` (the world detaches them: a held brick is put down,
the bodies leave after the grace) and attach again at tick `back` with new brains, as the
agent processes do when their link returns; a3 builds throughout. The three ticks are drawn
from the seed in the ranges partition runs show (cut 150-259, dead 150-349 ticks later, back
600-799 ticks after the cut). A run ends complete, or stalled once no site has been filled
for `stall` ticks (`SimRun.run`'s stall clock), or at the scenario's `max_ticks`.

    python3 -m faults.cutoff --seeds 1-400        # a line per run (about a second each); which stall
    python3 -m faults.cutoff --seeds 364 -v       # one run, and each agent's last word
"""

from __future__ import annotations

import argparse
import re
import sys
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from agent_runtime.brain import Brain
from conag import sim
from conag.sim import SimRun
from protocol.messages import AgentState
from world_server.scenario import Scenario, load_scenario

ROOT = Path(__file__).resolve().parent.parent
NESTED_SQUARES = ROOT / "scenarios" / "nested_squares.toml"
CUT = ("a1", "a2")        # the agents cut off; a3 is not
HALT_AFTER = 3            # ticks without a command before the world stops a body (missed deadlines)
STALL = 6000              # ticks without a site filled that end a run (60 s at a partition run's 100 Hz)


@dataclass
class CutoffRun:
    """One run: when the cut came, how the build ended, and the agents' last word."""

    seed: int
    cut: int
    dead: int
    back: int
    completed: bool = False
    stalled: bool = False        # ended by the stall clock (else complete, or out of ticks)
    ticks: int = 0
    sites_filled: int = 0
    sites_total: int = 0
    bricks_total: int = 0
    restarts: dict[str, int] = field(default_factory=dict)
    agents: list[str] = field(default_factory=list)   # per agent: behaviour, sites it believes open, blocker

    def line(self) -> str:
        state = "complete" if self.completed else "STALLED" if self.stalled else "out of ticks"
        return (f"seed {self.seed}: {state}, {self.sites_filled}/{self.sites_total} sites in {self.ticks} ticks; "
                f"cut at tick {self.cut}, dead at {self.dead}, back at {self.back}; bricks_total {self.bricks_total}")


def schedule(seed: int) -> tuple[int, int, int]:
    """(cut, dead, back) ticks of run `seed`."""
    rng = np.random.default_rng(seed)
    cut = int(rng.integers(150, 260))
    return cut, cut + int(rng.integers(150, 350)), cut + int(rng.integers(600, 800))


def cutoff_run(seed: int, scenario: Scenario | None = None, stall: int = STALL) -> CutoffRun:
    """Build `scenario` (nested_squares) with three agents, a1 and a2 cut off as `schedule` says."""
    sc = scenario or load_scenario(NESTED_SQUARES)
    run = sim.start(sc, agents=3, seed=seed)
    out = CutoffRun(seed, *schedule(seed))
    run.before_step = lambda r, frame: None if frame.agent_id in CUT and out.cut <= r.world.tick < out.back else frame
    result = run.run(sc.max_ticks, stall_ticks=stall, observers=[lambda r: _cut_events(r, out)])
    status = run.world.status()
    out.completed, out.stalled, out.ticks = result.completed, result.stalled, result.ticks
    out.sites_filled, out.sites_total = status.sites_filled, status.sites_total
    out.bricks_total = status.bricks_total
    out.restarts = dict(zip(status.agent_ids, status.agent_restarts))
    out.agents = [_last_word(agent, brain.state_report(result.ticks)) for agent, brain in run.brains.items()]
    return out


def _cut_events(run: SimRun, out: CutoffRun) -> None:
    """What the world does to the cut agents once it has reached this tick: stop their bodies
    (deadlines missed), detach them (seen dead), attach them again with new brains (the link
    is back)."""
    world, tick = run.world, run.world.tick
    if tick == out.cut + HALT_AFTER:
        for agent in CUT:
            world.halt(agent)
    if tick == out.dead:
        for agent in CUT:
            world.detach(agent)
    if tick == out.back:
        for i, agent in enumerate(CUT):
            old = run.brains[agent]
            run.brains[agent] = Brain(world.attach(agent), old.cfg, np.random.default_rng([out.seed, 7, i]))


def _last_word(agent: str, said: AgentState) -> str:
    return (f"{agent}: {said.behaviour}, {'holding a brick' if said.holding else 'holding nothing'}, "
            f"{said.sites_open} sites open, blocker: {said.blocker or 'none'}")


def seeds_arg(text: str) -> list[int]:
    """'1-400', '364' or '3,7,10-12' as a list of seeds."""
    seeds: list[int] = []
    for part in text.split(","):
        match = re.fullmatch(r"(\d+)(?:-(\d+))?", part.strip())
        if match is None or int(match[2] or match[1]) < int(match[1]):
            raise argparse.ArgumentTypeError(f"seeds as 1-400 or 3,7,10-12, not {text!r}")
        seeds += range(int(match[1]), int(match[2] or match[1]) + 1)
    return seeds


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python3 -m faults.cutoff", description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=seeds_arg, default=seeds_arg("1-20"), help="seeds to run (default 1-20)")
    p.add_argument("--stall", type=int, default=STALL, help=f"ticks without a fill that end a run (default {STALL})")
    p.add_argument("-v", "--verbose", action="store_true",
                   help="each agent's last word after every run's line (without: after a stalled run's only)")
    args = p.parse_args(argv)
    stalled = []
    for k, seed in enumerate(args.seeds, 1):
        r = cutoff_run(seed, stall=args.stall)
        print(f"[{k}/{len(args.seeds)}] {r.line()}", flush=True)
        if args.verbose or not r.completed:
            for line in r.agents:
                print(f"  {line}", flush=True)
        if not r.completed:
            stalled.append(seed)
    print(f"{len(stalled)} of {len(args.seeds)} runs stalled" + (f": seeds {stalled}" if stalled else ""))
    return 1 if stalled else 0


if __name__ == "__main__":
    sys.exit(main())

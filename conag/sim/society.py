"""A society of foremen and workers in process (issue 37 item 4; docs/society.md).

`start_society` makes a world with cues (`cue_reach`) and attaches `foremen` ConAg foremen
(`f1`, `f2`, ...: `agent_runtime.foreman_brain.ForemanBrain`) and `workers` reactive
workers (`w1`, ...: `agent_runtime.worker.Worker`), each with a stream of its own; the
returned `SimRun` steps them in lockstep like any run (`SimRun.run`). Ids, seeds and the
order of attaching are those of `conag run --foremen F --workers W`.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from agent_runtime.config import AgentConfig
from agent_runtime.foreman_brain import ForemanBrain
from agent_runtime.worker import Worker
from conag.sim.loop import SimRun
from world_server.noise import NoiseSettings
from world_server.scenario import Scenario
from world_server.world import World

DEFAULT_CUE_REACH = 5.0  # world units: how far a body marks in a society's world (conag run --cue-reach)


def society_ids(foremen: int, workers: int) -> list[str]:
    """The agent ids of a society, in the order they attach: foremen, then workers."""
    return [f"f{i + 1}" for i in range(foremen)] + [f"w{i + 1}" for i in range(workers)]


def start_society(scenario: Scenario, foremen: int, workers: int, seed: int | None = None,
                  cfg: AgentConfig | None = None, noise: NoiseSettings | None = None,
                  cue_reach: float = DEFAULT_CUE_REACH) -> SimRun:
    """A world with cues, `foremen` foremen and `workers` workers (see the module)."""
    seed = scenario.seed if seed is None else seed
    cfg = cfg or AgentConfig()
    if noise is not None:
        scenario = noise.apply(scenario)
    scenario = dataclasses.replace(scenario, world=dataclasses.replace(scenario.world, cue_reach=cue_reach))
    world = World(scenario, np.random.default_rng(seed))
    run = SimRun(world, agent=cfg.describe(None))
    run._record_fills()
    for i, agent_id in enumerate(society_ids(foremen, workers)):
        welcome = world.attach(agent_id)
        rng = np.random.default_rng([seed, i])
        run.brains[agent_id] = (ForemanBrain(welcome, cfg, rng) if agent_id.startswith("f")  # type: ignore[assignment]
                                else Worker(welcome, rng=rng))
    return run

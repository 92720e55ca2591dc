"""Run a scenario in one process: the world core and one Brain per agent, no bus.

The same World and Brain code as the processes, in lockstep, for tests and experiments
that need many runs quickly. `conag run` is the real thing: one process per agent.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from agent_runtime.brain import Brain, Step
from agent_runtime.config import AgentConfig
from world_server.scenario import Scenario
from world_server.world import World


@dataclass
class SimRun:
    world: World
    brains: dict[str, Brain] = field(default_factory=dict)
    behaviours: dict[str, str] = field(default_factory=dict)
    filled_at: np.ndarray | None = None  # per site (world order), the tick it was last filled; -1: empty
    on_step: Callable[[str, Step], None] | None = None  # sees every decision (the teacher's view)

    def step(self) -> None:
        """One lockstep tick: every brain answers its frame, then the world steps."""
        for frame in self.world.frames():
            s = self.brains[frame.agent_id].step(frame)
            self.behaviours[frame.agent_id] = s.behaviour
            if self.on_step is not None:
                self.on_step(frame.agent_id, s)
            self.world.set_command(frame.agent_id, s.speed, s.turn, s.action)
        self.world.step()
        self._record_fills()

    def _record_fills(self) -> None:
        filled = self.world.sites_filled()
        if self.filled_at is None:
            self.filled_at = np.full(filled.shape, -1, np.int64)
        self.filled_at[filled & (self.filled_at < 0)] = self.world.tick
        self.filled_at[~filled] = -1  # emptied again (a perturbation): not filled any more

    def fill_ticks(self) -> dict[tuple[int, int], int]:
        """The tick each site, as (row, col) of the layout, was filled at (-1: empty)."""
        cells = self.world.scenario.to_cell(self.world.sites_xy)
        return {(int(r), int(c)): int(t) for (c, r), t in zip(cells, self.filled_at)}

    def run(self, max_ticks: int, until_complete: bool = True) -> bool:
        """Step until the structure is complete (True) or `max_ticks` pass (False)."""
        for _ in range(max_ticks):
            if until_complete and self.world.status().completed:
                return True
            self.step()
        return self.world.status().completed


def start(scenario: Scenario, agents: int | None = None, seed: int | None = None,
          cfg: AgentConfig | None = None, network=None) -> SimRun:
    """A world and its brains; `network` (one for every agent) replaces the Fig. 8 network."""
    seed = scenario.seed if seed is None else seed
    world = World(scenario, np.random.default_rng(seed))
    run = SimRun(world)
    run._record_fills()  # sites filled from the start count as filled at tick 0
    for i in range(scenario.agents if agents is None else agents):
        agent_id = f"a{i + 1}"
        welcome = world.attach(agent_id)
        run.brains[agent_id] = Brain(welcome, cfg, np.random.default_rng([seed, i]), network=network)
    return run

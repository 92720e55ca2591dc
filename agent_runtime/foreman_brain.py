"""A foreman agent (issue 37 item 4): a ConAg Brain that also marks cues for workers.

It builds as any ConAg agent does; on a step whose decision asks for no gripper or
consummatory action, it may put or take one cue instead (`agent_runtime.foreman.Foreman`
decides where, from the maps the step has just updated). In a world without cues
(`Welcome.cue_reach` 0) it never marks and decides exactly as a plain Brain.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from agent_runtime.brain import Brain, Step
from agent_runtime.config import AgentConfig
from agent_runtime.foreman import Foreman, ForemanConfig
from agent_runtime.network import ActionNetwork
from protocol.messages import SensorFrame, Welcome


class ForemanBrain(Brain):
    """A Brain whose idle action slot puts and takes cues (see the module)."""

    def __init__(self, welcome: Welcome, cfg: AgentConfig | None = None, rng: np.random.Generator | None = None,
                 network: ActionNetwork | None = None, foreman: ForemanConfig | None = None):
        super().__init__(welcome, cfg, rng, network)
        f = foreman or ForemanConfig()
        # It marks no farther than the world lets it, nor than it sees (less a cell, so the
        # site it marks is one it has just seen whole).
        reach = min(f.reach, welcome.cue_reach / welcome.cell_size, self.sensor_range - 1.0)
        self.foreman = Foreman(dataclasses.replace(f, reach=max(reach, 0.5))) if welcome.cue_reach > 0 else None

    def step(self, frame: SensorFrame) -> Step:
        """The Brain's step; with no action of its own, maybe a cue put or taken."""
        s = super().step(frame)
        if self.foreman is None:
            return s
        if s.action == "drop" and self.foreman.cues:
            first = self.foreman.before_drop(self.layers(), self.maps.clear_age, self.odometry, self.maps.cell_of)
            if first is not None:
                return dataclasses.replace(s, action=first.action,
                                           mark=(first.dx * self.cell, first.dy * self.cell, first.kind))
        if not self.foreman.due() or s.action != "none":
            return s
        mark = self.foreman.decide(self.layers(), self.maps.clear_age, self.odometry, self.maps.offset_of,
                                   self.maps.cell_of)
        if mark is None:
            return s
        return dataclasses.replace(s, action=mark.action, mark=(mark.dx * self.cell, mark.dy * self.cell, mark.kind))

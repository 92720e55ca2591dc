"""Brains started again at the worst moment: the tick their body drops a brick.

An agent process that dies and is started again while its body still stands on the brick
it just dropped gets a brain that never saw the drop, on a body the world still lets pass
through that brick until it is off it. If the brick closed a ring's last gap, a step to the
wrong side shuts the agent in for good (`AgentConfig.off_own_brick` is there for it). Under
`python3 -m faults.chaos` that moment comes by chance only (60 chaos runs of nested_squares,
every killed agent started again at once, all completed with the addition and without it);
`RestartAtDrop` makes it come on purpose, in process and reproducibly from a seed, so that
what an addition buys there can be measured (`python3 -m experiments.ablation
--restart-at-drop P`).
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from protocol.messages import SensorFrame

if TYPE_CHECKING:
    from conag.sim.loop import SimRun


class RestartAtDrop:
    """A `SimRun.before_step`: with chance `share`, the brain of an agent whose body has
    just dropped a brick is started again before it sees that frame (`SimRun.restart`).
    The new brain steps on the frame without its `dropped` flag, as a process started
    again after the drop never hears of it. `seed` draws the chances and the new brains'
    generators; `restarts` counts them."""

    def __init__(self, share: float, seed: int) -> None:
        if not 0.0 <= share <= 1.0:
            raise ValueError(f"the share of drops followed by a restart must be in [0, 1], not {share}")
        self.share = share
        self.restarts = 0
        self._rng = np.random.default_rng([seed, 0x5EED])

    def __call__(self, run: SimRun, frame: SensorFrame) -> SensorFrame:
        """The frame the agent's brain steps on: `frame`, or, after a restart, `frame` unflagged."""
        if not frame.dropped or self._rng.random() >= self.share:
            return frame
        self.restarts += 1
        run.restart(frame.agent_id, np.random.default_rng([int(self._rng.integers(2**62)), self.restarts]))
        return replace(frame, dropped=False)

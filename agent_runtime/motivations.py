"""Motivations (paper §3, §4.1): hunger and thirst grow with time, reset on eat/drink.

Avoid is always on, so it needs no state here. A need "interrupts" construction once it
passes `need_threshold` and keeps the agent at it until eating or drinking succeeds
(the world reports that in the next frame), so a need is never half-satisfied.
"""

from __future__ import annotations

from dataclasses import dataclass

from agent_runtime.config import AgentConfig


@dataclass
class Motivations:
    """Hunger and thirst (0 sated .. 1) and whether each has interrupted construction."""

    hunger: float = 0.0
    thirst: float = 0.0
    seeking_food: bool = False
    seeking_water: bool = False

    def update(self, cfg: AgentConfig, ate: bool, drank: bool) -> None:
        """One tick: grow, reset what the last action satisfied, latch what is urgent."""
        self.hunger = 0.0 if ate else min(1.0, self.hunger + cfg.hunger_rate)
        self.thirst = 0.0 if drank else min(1.0, self.thirst + cfg.thirst_rate)
        self.seeking_food = self.hunger >= cfg.need_threshold or (self.seeking_food and not ate)
        self.seeking_water = self.thirst >= cfg.need_threshold or (self.seeking_water and not drank)

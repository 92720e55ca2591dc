"""Motivations (paper §3, §4.1): hunger and thirst grow with time, reset on eat/drink.

Avoid is always on, so it needs no state here. A need "interrupts" construction while it
is at or above `need_threshold`. Only eating or drinking (the world reports it in the next
frame) lowers a need, to 0, so a need that interrupted stays on until it is met: that is
the paper's rule itself, not a latch added to it, and a need is never half-satisfied.
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
        """One tick: grow, reset what the last action satisfied, say what is urgent."""
        self.hunger = 0.0 if ate else min(1.0, self.hunger + cfg.hunger_rate)
        self.thirst = 0.0 if drank else min(1.0, self.thirst + cfg.thirst_rate)
        self.seeking_food = self.hunger >= cfg.need_threshold
        self.seeking_water = self.thirst >= cfg.need_threshold

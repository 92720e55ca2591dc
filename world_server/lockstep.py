"""Whom a lockstep world waits for: live agents, except those that stopped answering.

An agent that holds its liveliness token but misses `miss_limit` lockstep deadlines in a
row (hung, stopped, or fed absurd input) is unresponsive: the world steps without waiting
for it, so one silent agent does not slow everyone to one tick per `lockstep_timeout`.
Any command it sends again takes it back. When every live agent is unresponsive the world
waits for them all as before (nobody else paces it). Plain bookkeeping, no bus and no
clock: the server tells it what happened.
"""

from __future__ import annotations

from collections.abc import Iterable


class LockstepWaits:
    """Consecutive missed deadlines per agent, and from them whom to wait for."""

    def __init__(self, miss_limit: int):
        if miss_limit < 1:
            raise ValueError("miss_limit must be >= 1")
        self.miss_limit = miss_limit
        self.missed: dict[str, int] = {}

    def unresponsive(self, agent: str) -> bool:
        """Whether `agent` has missed `miss_limit` deadlines in a row (and not answered since)."""
        return self.missed.get(agent, 0) >= self.miss_limit

    def awaited(self, live: Iterable[str]) -> list[str]:
        """The live agents to wait for: the responsive ones, or all of them if none is."""
        live = list(live)
        responsive = [a for a in live if not self.unresponsive(a)]
        return responsive or live

    def heard(self, agent: str) -> bool:
        """`agent` sent a command (whatever its tick): it answers again. True if it had been
        unresponsive (the world waits for it from now on)."""
        was = self.unresponsive(agent)
        self.missed.pop(agent, None)
        return was

    def deadline_passed(self, late: Iterable[str]) -> list[str]:
        """The world stepped without the commands of `late` (agents it waited for): one more
        miss each. Returns those that have just become unresponsive."""
        now = []
        for agent in late:
            self.missed[agent] = self.missed.get(agent, 0) + 1
            if self.missed[agent] == self.miss_limit:
                now.append(agent)
        return now

    def forget(self, agent: str) -> None:
        """The agent's process is gone, or a new one attached: it starts afresh."""
        self.missed.pop(agent, None)

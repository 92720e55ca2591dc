"""The run summary (a contract, docs/design.md), from the world's final status (`conag world --summary`, `conag run`).

{scenario, seed, completed, stalled, ticks, sites_total, sites_filled, bricks_total,
 total_distance, agents: [{id, distance, grabs, drops, restarts, behaviour_ticks}]}
and, from `conag run`, `agent` (which agent ran: {preset, without, changed}, see
`agent_runtime.config.AgentConfig.describe`; with --learn also learn and eta) and
world_restarts. `RunSummary` is it typed; `as_dict`/`to_json` give the JSON.

`behaviour_ticks` maps each behaviour the agent has spent ticks in to that count, from
its last AgentState ({} if none arrived); `stalled` is set by `conag run --stall-ticks`.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from protocol.messages import BEHAVIOURS, AgentState, WorldStatus
from world_server.files import write_text_whole


def behaviour_ticks(state: AgentState | None) -> dict[str, int]:
    """Ticks per behaviour (only those used, in BEHAVIOURS order) from an AgentState."""
    if state is None:
        return {}
    return {name: n for name, n in zip(BEHAVIOURS, state.behaviour_ticks) if n}


@dataclass(frozen=True)
class AgentSummary:
    """One agent's line of the run summary."""

    id: str
    distance: float
    grabs: int
    drops: int
    restarts: int
    behaviour_ticks: dict[str, int] = field(default_factory=dict)

    def as_dict(self) -> dict[str, Any]:
        """The JSON object, keys in the contract's order."""
        return {"id": self.id, "distance": self.distance, "grabs": self.grabs, "drops": self.drops,
                "restarts": self.restarts, "behaviour_ticks": dict(self.behaviour_ticks)}


@dataclass(frozen=True)
class RunSummary:
    """The run summary (see the module). `agent` (which agent ran) and `world_restarts` (how
    often it restarted a world process that died) are set by `conag run`; a summary
    without them has no such keys (the world does not know its agents' settings)."""

    scenario: str
    seed: int
    completed: bool
    stalled: bool
    ticks: int
    sites_total: int
    sites_filled: int
    bricks_total: int
    total_distance: float
    agents: tuple[AgentSummary, ...]
    world_restarts: int | None = None
    agent: dict[str, Any] | None = None

    @classmethod
    def of(cls, status: WorldStatus, states: Mapping[str, AgentState] | None = None,
           stalled: bool = False) -> RunSummary:
        """The summary of a final status, with the agents' last AgentStates."""
        states = states or {}
        agents = sorted(
            (AgentSummary(a, round(d, 6), g, dr, r, behaviour_ticks(states.get(a)))
             for a, d, g, dr, r in zip(status.agent_ids, status.agent_distance, status.agent_grabs,
                                       status.agent_drops, status.agent_restarts)),
            key=lambda agent: str(agent.id))  # by id, not by who happened to attach first
        return cls(scenario=status.scenario, seed=status.seed, completed=status.completed, stalled=stalled,
                   ticks=status.tick, sites_total=status.sites_total, sites_filled=status.sites_filled,
                   bricks_total=status.bricks_total, total_distance=round(sum(status.agent_distance), 6),
                   agents=tuple(agents))

    def as_dict(self) -> dict[str, Any]:
        """The JSON object, keys in the contract's order (then `agent` and `world_restarts`, if set)."""
        out = {"scenario": self.scenario, "seed": self.seed, "completed": self.completed, "stalled": self.stalled,
               "ticks": self.ticks, "sites_total": self.sites_total, "sites_filled": self.sites_filled,
               "bricks_total": self.bricks_total, "total_distance": self.total_distance,
               "agents": [a.as_dict() for a in self.agents]}
        if self.agent is not None:
            out["agent"] = self.agent
        if self.world_restarts is not None:
            out["world_restarts"] = self.world_restarts
        return out

    def to_json(self) -> str:
        """The summary file's text."""
        return json.dumps(self.as_dict(), indent=2) + "\n"

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> RunSummary:
        """A summary from its JSON object (`as_dict`'s inverse)."""
        return cls(**{**data, "agents": tuple(AgentSummary(**a) for a in data["agents"])})

    @classmethod
    def from_json(cls, text: str) -> RunSummary:
        """A summary from a summary file's text."""
        return cls.from_dict(json.loads(text))


def run_summary(status: WorldStatus, states: Mapping[str, AgentState] | None = None,
                stalled: bool = False) -> dict[str, Any]:
    """The run summary (see the module) of a final status as its JSON object."""
    return RunSummary.of(status, states, stalled).as_dict()


def write_summary(status: WorldStatus, path: str | Path, states: Mapping[str, AgentState] | None = None,
                  stalled: bool = False) -> RunSummary:
    """Write the run summary as JSON to `path`, whole or not at all (`world_server.files`); returns it."""
    summary = RunSummary.of(status, states, stalled)
    write_text_whole(path, summary.to_json())
    return summary

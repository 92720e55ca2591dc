"""The run summary (a contract, docs/design.md), from the world's final status (`conag world --summary`, `conag run`).

{scenario, seed, completed, stalled, ticks, sites_total, sites_filled, bricks_total,
 total_distance, agents: [{id, distance, grabs, drops, restarts, behaviour_ticks}]}

`behaviour_ticks` maps each behaviour the agent has spent ticks in to that count, from
its last AgentState ({} if none arrived); `stalled` is set by `conag run --stall-ticks`.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path

from protocol.messages import BEHAVIOURS, AgentState, WorldStatus


def behaviour_ticks(state: AgentState | None) -> dict[str, int]:
    """Ticks per behaviour (only those used, in BEHAVIOURS order) from an AgentState."""
    if state is None:
        return {}
    return {name: n for name, n in zip(BEHAVIOURS, state.behaviour_ticks) if n}


def run_summary(status: WorldStatus, states: Mapping[str, AgentState] | None = None,
                stalled: bool = False) -> dict:
    """The run summary (see the module) of a final status, with the agents' last AgentStates."""
    states = states or {}
    agents = sorted(
        ({"id": a, "distance": round(d, 6), "grabs": g, "drops": dr, "restarts": r,
          "behaviour_ticks": behaviour_ticks(states.get(a))}
         for a, d, g, dr, r in zip(status.agent_ids, status.agent_distance, status.agent_grabs,
                                   status.agent_drops, status.agent_restarts)),
        key=lambda agent: str(agent["id"]))  # by id, not by who happened to attach first
    return {
        "scenario": status.scenario,
        "seed": status.seed,
        "completed": status.completed,
        "stalled": stalled,
        "ticks": status.tick,
        "sites_total": status.sites_total,
        "sites_filled": status.sites_filled,
        "bricks_total": status.bricks_total,
        "total_distance": round(sum(status.agent_distance), 6),
        "agents": agents,
    }


def write_summary(status: WorldStatus, path: str | Path, states: Mapping[str, AgentState] | None = None,
                  stalled: bool = False) -> dict:
    """Write the run summary as JSON to `path`; returns it."""
    summary = run_summary(status, states, stalled)
    Path(path).write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    return summary

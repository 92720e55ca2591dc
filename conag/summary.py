"""The run summary of MISSION.md, built from the world's final status.

{scenario, seed, completed, ticks, sites_total, sites_filled, bricks_total,
 total_distance, agents: [{id, distance, grabs, drops, restarts}]}
"""

from __future__ import annotations

import json
from pathlib import Path

from protocol.messages import WorldStatus


def run_summary(status: WorldStatus) -> dict:
    agents = sorted(
        ({"id": a, "distance": round(d, 6), "grabs": g, "drops": dr, "restarts": r}
         for a, d, g, dr, r in zip(status.agent_ids, status.agent_distance, status.agent_grabs,
                                   status.agent_drops, status.agent_restarts)),
        key=lambda agent: agent["id"])  # by id, not by who happened to attach first
    return {
        "scenario": status.scenario,
        "seed": status.seed,
        "completed": status.completed,
        "ticks": status.tick,
        "sites_total": status.sites_total,
        "sites_filled": status.sites_filled,
        "bricks_total": status.bricks_total,
        "total_distance": round(sum(status.agent_distance), 6),
        "agents": agents,
    }


def write_summary(status: WorldStatus, path: str | Path) -> dict:
    summary = run_summary(status)
    Path(path).write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    return summary

"""An agent's maps as AgentMap messages (issue 13: what a viewer or a recording shows of its mind).

`map_snapshot(brain, tick)` quantises the six ESMs, both navigation maps of its last plan
and its Matching grid to 0..MAP_LEVEL per cell (see `protocol.messages.AgentMap`), one
message per layer; layers the brain has not computed yet (no plan before its first step,
no Matching grid without goal sequencing) are left out.
"""

from __future__ import annotations

import numpy as np

from protocol.messages import MAP_LAYERS, MAP_LEVEL, NM_UNREACHABLE, AgentMap


def _levels(values: np.ndarray) -> tuple[int, ...]:
    return tuple(np.clip(np.rint(np.asarray(values, np.float64) * MAP_LEVEL), 0, MAP_LEVEL).astype(np.int64)
                 .ravel().tolist())


def _distances(field: np.ndarray) -> tuple[int, ...]:
    d = np.asarray(field, np.float64)
    q = np.where(np.isfinite(d), np.minimum(np.rint(np.nan_to_num(d, posinf=0.0)), NM_UNREACHABLE - 1),
                 NM_UNREACHABLE)
    return tuple(q.astype(np.int64).ravel().tolist())


def map_snapshot(brain, tick: int) -> list[AgentMap]:
    """The brain's maps at `tick`, one AgentMap per layer it has (see the module)."""
    n = brain.maps.size
    out = [AgentMap(brain.agent_id, tick, name, n, _levels(brain.maps.maps[i]))
           for i, name in enumerate(MAP_LAYERS[:6])]
    plans = brain.plans
    if plans is not None:
        out.append(AgentMap(brain.agent_id, tick, "config_nm", n, _distances(plans.config)))
        out.append(AgentMap(brain.agent_id, tick, "brick_nm", n, _distances(plans.brick)))
        if plans.matching is not None:
            out.append(AgentMap(brain.agent_id, tick, "matching", n, _levels(plans.matching.match)))
    return out

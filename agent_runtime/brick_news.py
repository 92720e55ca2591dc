"""Brick news between agents (`AgentConfig.share_bricks`, issue 36), off by default.

In a big team most idle time is search: an agent that holds no brick and knows of none
walks until it sees one, while bricks another agent passed lie 15-30 cells away, beyond its
sensors (docs/results/experiments.md, "Teams that use their numbers"). What one agent has
seen, no other knows. With `share_bricks` each agent tells the others, every `NEWS_EVERY`
ticks, the free bricks in sight, the brick it heads for (its claim) and the bricks it took
since its last news; a listener remembers the reported bricks beyond its own map as its far
memory remembers bricks it walked away from (so they are goals at the map's border, by the
whole distance), and forgets the claimed and the taken ones: a whole idle team told of one
brick would all walk to it.

The common frame is the world's grid: every agent knows its attach cell in it (the
Welcome's position), as it knows the blueprint's sites. A report is what its sender's map
holds now, not its memory of what it was told, so news of a brick stops once no agent's map
holds it; a listener's own sensors clear a reported brick that is not there when it comes
into view, and a report of the brick taken clears it at once. Each agent still plans on its
own maps alone: news only adds and removes remembered bricks.

In `conag.sim` (and so in every experiment) the loop hands each report to the other
brains. Agent processes cannot share bricks yet: the bus message is not built, and
`conag run`, `conag agent(s)` and the env refuse the addition (`require_in_process`)
rather than run it as a silent no-op.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

NEWS_EVERY = 10   # ticks between an agent's reports: a brick is many ticks' walk away


@dataclass(frozen=True)
class BrickNews:
    """One agent's report: world cells (x east, y north), each an (k, 2) int64 array."""

    sender: str
    tick: int
    seen: np.ndarray    # the free bricks in the sender's sight
    taken: np.ndarray   # the bricks it took since its last report
    claimed: np.ndarray  # the brick it heads for (none, or one)


def require_in_process(cfg, where: str) -> None:
    """ValueError if `cfg` (an AgentConfig) asks for brick news where no loop carries it."""
    if cfg.share_bricks:
        raise ValueError(f"{where}: share_bricks runs in the in-process simulator only (conag.sim and the "
                         "experiments); agent processes have no bus message for brick news yet")


def cells(pairs) -> np.ndarray:
    """(k, 2) int64 cells from any sequence of (x, y) pairs (empty: shape (0, 2))."""
    return np.asarray(pairs, np.int64).reshape(-1, 2)

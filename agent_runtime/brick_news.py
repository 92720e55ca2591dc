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
Welcome's position), as it knows the blueprint's sites. A report is what its sender sees
now, not its memory of what it saw or was told, so news of a brick stops once no agent sees
it; a listener's own sensors clear a reported brick that is not there when it comes
into view, and a report of the brick taken clears it at once. Each agent still plans on its
own maps alone: news only adds and removes remembered bricks.

On the bus a report is a `BrickNews` message (protocol.messages) on the sender's key
`agent/<id>/bricks`, best effort: the next report says it all again. In `conag.sim` (and so
in every experiment) the loop hands each report to the other brains directly.
"""

from __future__ import annotations

import numpy as np

from protocol.messages import BrickNews

NEWS_EVERY = 10   # ticks between an agent's reports: a brick is many ticks' walk away


def report(agent_id: str, tick: int, seen: np.ndarray, taken: np.ndarray, claimed: np.ndarray) -> BrickNews:
    """The BrickNews of (k, 2) world-cell arrays (x, y)."""
    def xs_ys(c: np.ndarray) -> tuple[tuple[int, ...], tuple[int, ...]]:
        return tuple(c[:, 0].tolist()), tuple(c[:, 1].tolist())
    return BrickNews(agent_id, tick, *xs_ys(seen), *xs_ys(taken), *xs_ys(claimed))


def seen_cells(news: BrickNews) -> np.ndarray:
    """The free bricks the sender sees, (k, 2) world cells."""
    return _stacked(news.seen_xs, news.seen_ys)


def gone_cells(news: BrickNews) -> np.ndarray:
    """The bricks the sender took or heads for, (k, 2) world cells: not to be fetched."""
    return _stacked(news.taken_xs + news.claimed_xs, news.taken_ys + news.claimed_ys)


def _stacked(xs: tuple[int, ...], ys: tuple[int, ...]) -> np.ndarray:
    return np.array([xs, ys], np.int64).T.reshape(-1, 2)


def cells(pairs) -> np.ndarray:
    """(k, 2) int64 cells from any sequence of (x, y) pairs (empty: shape (0, 2))."""
    return np.asarray(pairs, np.int64).reshape(-1, 2)

"""Construction planned on a fully known map: the ideal order of goal sequencing, and a
lower bound on the distance any agent must travel (paper §6, Fig. 13; MISSION G3).

A live agent knows only what its sector sensors have shown it, one disc per sector, so
the order it fills sites in depends on what it has seen. `replay` removes that: it runs
the decision rules of the agent (§6.2, or nearest-first with `sequencing=False`) on the
true layout, one brick at a time, and reports the order and whether every site could be
filled. The tests use it for the orders the paper describes (Fig. 18-20, nested
squares); the Fig. 13 experiment reports it beside the live runs.

`lower_bound` is the optimal assignment of bricks to sites by shortest-path distance
(scipy's linear_sum_assignment) plus what the trips between them must cost at least.

Grids are bool [row, col] arrays in cells; distances are in cells.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from agent_runtime.matching import calculate_matching, select_goals
from agent_runtime.spreading import distance_field

# An 8-connected grid path is at most 1/cos(22.5 deg) longer than the straight line an
# agent in the continuous world can take, so grid distances divided by this bound it below.
OCTILE_SLACK = 1.0 / np.cos(np.pi / 8)


@dataclass(frozen=True)
class Replay:
    order: tuple[tuple[tuple[int, int], tuple[int, int]], ...]  # (brick taken, site filled), in order
    distance: float     # cells walked: to each brick, then with it to its site
    completed: bool     # every site filled (False: the rest were cut off)


def _one_cell(shape: tuple[int, int], cell: tuple[int, int]) -> np.ndarray:
    mask = np.zeros(shape, bool)
    mask[cell] = True
    return mask


def _nearest_goal(field: np.ndarray, goals: np.ndarray) -> tuple[int, int] | None:
    """The goal cell with the smallest finite `field` (first in reading order on a tie)."""
    d = np.where(goals, field, np.inf)
    i = int(np.argmin(d))
    return None if not np.isfinite(d.flat[i]) else (i // d.shape[1], i % d.shape[1])


def _goals(bricks, sites, obstacles, sequencing: bool) -> tuple[np.ndarray, np.ndarray]:
    if not sequencing:
        return sites, bricks
    return select_goals(calculate_matching(bricks, sites, obstacles), bricks, sites)


def _walk_to(here, goals, fallback, obstacles) -> tuple[tuple[int, int] | None, float]:
    """The nearest of `goals` reachable from `here` (else of `fallback`, as the agent's
    plan falls back when sequencing leaves nothing reachable) and the path length."""
    field = distance_field(_one_cell(obstacles.shape, here), obstacles & ~_one_cell(obstacles.shape, here))
    for candidates in (goals, fallback):
        target = _nearest_goal(field, candidates)
        if target is not None:
            return target, float(field[target])
    return None, 0.0


def replay(bricks: np.ndarray, sites: np.ndarray, obstacles: np.ndarray, start: tuple[int, int],
           sequencing: bool = True) -> Replay:
    """One agent builds on a map it knows entirely: walk to the nearest selected brick,
    take it, carry it to the nearest selected site (free bricks are in the way, as on the
    agent's configuration NM), drop it there (it becomes an obstacle); repeat until every
    site is filled or nothing reachable is left."""
    bricks, sites, obstacles = (np.array(g, dtype=bool) for g in (bricks, sites, obstacles))
    here, walked, order = tuple(start), 0.0, []
    while sites.any():
        _, brick_goals = _goals(bricks, sites, obstacles, sequencing)
        brick, d_fetch = _walk_to(here, brick_goals, bricks, obstacles)
        if brick is None:
            break
        bricks[brick] = False
        site_goals, _ = _goals(bricks, sites, obstacles, sequencing)
        site, d_carry = _walk_to(brick, site_goals, sites, obstacles | bricks)
        if site is None:
            break
        sites[site], obstacles[site] = False, True
        order.append((brick, site))
        walked += d_fetch + d_carry
        here = site
    return Replay(tuple(order), walked, not sites.any())


def lower_bound(bricks: np.ndarray, sites: np.ndarray, obstacles: np.ndarray,
                starts: list[tuple[int, int]], reach: float = 1.0) -> float:
    """Least total distance (cells) that agents starting at `starts` can build in.

    Every site gets a distinct brick carried to it: at least the optimal assignment of
    bricks to sites by shortest-path distance on the initial map (later drops only add
    obstacles). Every agent first walks to some brick, and after every drop but the last
    of each agent someone walks from that site to a brick: at least the site's distance
    to its nearest brick, and the agents' last drops save at most the largest of those.
    Each leg can be `reach` shorter (bricks are taken from beside them) and straighter
    than a grid path (OCTILE_SLACK). 0 if no brick can reach a site. Needs scipy.
    """
    from scipy.optimize import linear_sum_assignment

    bricks, sites, obstacles = (np.array(g, dtype=bool) for g in (bricks, sites, obstacles))
    brick_cells, site_cells = np.argwhere(bricks), np.argwhere(sites)
    if len(brick_cells) < len(site_cells) or not len(site_cells):
        return 0.0
    # Paths may run over free bricks and open sites; other discs are in the way.
    cost = np.array([distance_field(_one_cell(sites.shape, tuple(s)), obstacles)[bricks] for s in site_cells])
    if not np.isfinite(cost.min(axis=1)).all():
        return 0.0
    finite = np.where(np.isfinite(cost), cost, 1e9)
    rows, cols = linear_sum_assignment(finite)
    leg = lambda d: np.maximum(np.asarray(d, dtype=float) - reach, 0.0)  # noqa: E731
    carry = leg(finite[rows, cols]).sum()
    returns = np.sort(leg(cost.min(axis=1)))[::-1]
    to_bricks = distance_field(bricks, obstacles)
    approach = sum(float(leg(to_bricks[s])) for s in starts if np.isfinite(to_bricks[s]))
    return float(carry + returns[len(starts):].sum() + approach) / OCTILE_SLACK

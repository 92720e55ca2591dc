"""Construction planned on a fully known map: the ideal order of goal sequencing, and a
lower bound on the distance any agent must travel (paper §6, Fig. 13; G3).

A live agent knows only what its sector sensors have shown it, one disc per sector, so
the order it fills sites in depends on what it has seen. `replay` removes that: it runs
the decision rules of the agent (§6.2, or nearest-first with `sequencing=False`) on the
true layout, one brick at a time, and reports the order and whether every site could be
filled. The tests use it for the orders the paper describes (Fig. 18-20, nested
squares); the Fig. 13 experiment reports it beside the live runs.

`assignment_bound` is the optimal assignment of bricks to sites by shortest-path distance
(scipy's linear_sum_assignment), the carrying alone; `lower_bound` adds the walks between
trips, by an assignment over the chain of trips each agent must make.

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
    start = _one_cell(obstacles.shape, here)
    for candidates in (goals, fallback):
        field = distance_field(start, obstacles & ~start & ~candidates)
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
        # Unselected bricks are in the way, as on the agent's brick NM.
        brick, d_fetch = _walk_to(here, brick_goals, bricks, obstacles | (bricks & ~brick_goals))
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


def _site_fields(cells: np.ndarray, obstacles: np.ndarray) -> list[np.ndarray]:
    return [distance_field(_one_cell(obstacles.shape, tuple(c)), obstacles) for c in cells]


def assignment_bound(bricks: np.ndarray, sites: np.ndarray, obstacles: np.ndarray) -> float:
    """The optimal assignment of distinct bricks to sites by shortest-path distance on the
    initial map (cells): the least total carrying distance, walks between trips aside.
    0 if some site cannot be reached from any brick or there are too few bricks."""
    from scipy.optimize import linear_sum_assignment

    bricks, sites, obstacles = (np.array(g, dtype=bool) for g in (bricks, sites, obstacles))
    site_cells = np.argwhere(sites)
    if not len(site_cells) or bricks.sum() < len(site_cells):
        return 0.0
    cost = np.array([f[bricks] for f in _site_fields(site_cells, obstacles)])
    if not np.isfinite(cost.min(axis=1)).all():
        return 0.0
    rows, cols = linear_sum_assignment(np.where(np.isfinite(cost), cost, 1e9))
    return float(cost[rows, cols].sum())


def lower_bound(bricks: np.ndarray, sites: np.ndarray, obstacles: np.ndarray,
                starts: list[tuple[int, int]], reach: float = 1.0, centering: float = 0.0) -> float:
    """Least total distance (cells) that agents starting at `starts` can build in.

    Each agent's walk is a chain of trips: from where it stands (its start, or the site it
    filled last) to a brick and with the brick to the next site. A trip from p to site s
    costs at least t(p, s) = min over bricks b of d(p, b) + d(b, s), shortest paths on
    the initial map (later drops only add obstacles). Every site is entered by one trip
    and left by at most one, every start begins at most one chain: an assignment of
    predecessors to sites (scipy's linear_sum_assignment), which relaxes the chains (it
    may close loops, and bricks may repeat) and so bounds them from below. Where distinct
    bricks matter more (a supply used up from near to far), carrying and walking back to
    distinct bricks (`_distinct_legs_bound`) bound it higher; the larger of the two is
    returned.

    Per trip the agent may stop `reach` short of the brick and start carrying from there,
    and end `centering` off the site's centre; legs may be straighter than grid paths
    (OCTILE_SLACK). 0 if no chain can fill every site.
    """
    from scipy.optimize import linear_sum_assignment

    bricks, sites, obstacles = (np.array(g, dtype=bool) for g in (bricks, sites, obstacles))
    site_cells = np.argwhere(sites)
    k, m = len(site_cells), len(starts)
    if not k or not m or bricks.sum() < k:
        return 0.0
    to_sites = np.array([f[bricks] for f in _site_fields(site_cells, obstacles)])           # (k, B)
    from_starts = np.array([f[bricks] for f in _site_fields(np.array(starts), obstacles)])   # (m, B)
    legs = np.vstack([from_starts, to_sites])                                                # (m + k, B)
    trip = (legs[:, None, :] + to_sites[None, :, :]).min(axis=2)                             # (m + k, k)
    trip = np.maximum(trip / OCTILE_SLACK - 2 * reach - centering, 0.0)
    trip[m + np.arange(k), np.arange(k)] = np.inf                                            # no trip to itself
    ends = np.zeros((m + k, m))                                                              # a chain may end anywhere
    cost = np.hstack([trip, ends])
    big = 1e9
    rows, cols = linear_sum_assignment(np.where(np.isfinite(cost), cost, big))
    total = cost[rows, cols]
    if not np.isfinite(total).all():
        return 0.0
    # The chains may reuse a brick; with distinct bricks the legs bound it again.
    leg = lambda d: np.maximum(d / OCTILE_SLACK - reach - centering, 0.0)  # noqa: E731
    return float(max(total.sum(), _distinct_legs_bound(leg(to_sites), leg(from_starts).min(axis=1))))


def _distinct_legs_bound(legs: np.ndarray, approach: np.ndarray) -> float:
    """Carrying plus walking back, each leg to a distinct brick. `legs` (sites, bricks):
    least leg length between each pair; `approach` (agents,): each agent's least walk to a
    first brick.

    Every site gets a distinct brick carried to it: at least the optimal assignment of
    bricks to sites. After each drop but the last of each active agent the agent walks to
    the next brick it takes, a distinct brick each time: at least the optimal assignment of
    all but `a` sites to distinct bricks, for `a` active agents, who also walk to their
    first bricks. The least over `a` bounds every way of sharing the work.
    """
    from scipy.optimize import linear_sum_assignment

    k, m = len(legs), len(approach)
    finite = np.where(np.isfinite(legs), legs, 1e9)
    rows, cols = linear_sum_assignment(finite)
    carry = float(legs[rows, cols].sum())
    best = np.inf
    for active in range(1, min(m, k) + 1):
        # `active` sites may end a chain: dummy bricks at no cost.
        returns = np.hstack([finite, np.zeros((k, active))])
        r, c = linear_sum_assignment(returns)
        best = min(best, float(returns[r, c].sum()) + float(np.sort(approach)[:active].sum()))
    return carry + best if np.isfinite(carry) else 0.0

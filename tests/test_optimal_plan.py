"""The exact planner of experiments/optimal_plan.py: its plans are least-distance ones.

Checked against an independent search that knows nothing of trips: Dijkstra over the
agent's every single step (cell, brick in hand or not, bricks left, sites filled), on
small random layouts."""

from __future__ import annotations

import heapq
import math

import numpy as np
import pytest

from experiments.optimal_plan import SearchBudgetExceeded, optimal_plan, plan_distance
from experiments.replay import replay

MOVES = [(-1, 0, 1.0), (1, 0, 1.0), (0, -1, 1.0), (0, 1, 1.0),
         (-1, -1, math.sqrt(2)), (-1, 1, math.sqrt(2)), (1, -1, math.sqrt(2)), (1, 1, math.sqrt(2))]


def step_by_step(bricks, sites, obstacles, start) -> float:
    """Least distance for one agent by single moves: 8-connected, no corner cutting, over
    cells not blocked by a fixed obstacle, a free brick or a filled site; grab a free brick
    from a 4-neighbour cell; drop it on the open site the agent stands on."""
    rows, cols = obstacles.shape
    brick_cells = [tuple(map(int, c)) for c in np.argwhere(bricks)]
    site_cells = [tuple(map(int, c)) for c in np.argwhere(sites)]
    full = (1 << len(site_cells)) - 1

    def blocked(cell, left, filled):
        if obstacles[cell]:
            return True
        if cell in brick_cells and left >> brick_cells.index(cell) & 1:
            return True
        return cell in site_cells and bool(filled >> site_cells.index(cell) & 1)

    first = (tuple(start), False, (1 << len(brick_cells)) - 1, 0)
    best = {first: 0.0}
    queue = [(0.0, first)]
    while queue:
        d, state = heapq.heappop(queue)
        if d > best[state]:
            continue
        (r, c), holding, left, filled = state
        if filled == full:
            return d
        nxt = []
        for dr, dc, cost in MOVES:
            cell = (r + dr, c + dc)
            if not (0 <= cell[0] < rows and 0 <= cell[1] < cols) or blocked(cell, left, filled):
                continue
            if dr and dc and (blocked((r + dr, c), left, filled) or blocked((r, c + dc), left, filled)):
                continue
            nxt.append(((cell, holding, left, filled), cost))
        if not holding:
            for i, (br, bc) in enumerate(brick_cells):
                if left >> i & 1 and abs(br - r) + abs(bc - c) == 1:
                    nxt.append((((r, c), True, left & ~(1 << i), filled), 0.0))
        elif (r, c) in site_cells and not filled >> site_cells.index((r, c)) & 1:
            nxt.append((((r, c), False, left, filled | 1 << site_cells.index((r, c))), 0.0))
        for s2, cost in nxt:
            if d + cost < best.get(s2, math.inf) - 1e-12:
                best[s2] = d + cost
                heapq.heappush(queue, (d + cost, s2))
    return math.inf


def random_layout(rng: np.random.Generator, n_sites: int, n_bricks: int, size: int = 6):
    cells = rng.permutation(size * size)
    grids = [np.zeros((size, size), bool) for _ in range(3)]
    k = 0
    for grid, n in zip(grids, (n_bricks, n_sites, int(rng.integers(0, 5)))):
        for i in cells[k:k + n]:
            grid[divmod(int(i), size)] = True
        k += n
    start = divmod(int(cells[k]), size)
    return grids[0], grids[1], grids[2], start


@pytest.mark.parametrize("seed", range(12))
def test_the_plan_is_as_short_as_any_sequence_of_single_steps(seed):
    rng = np.random.default_rng([36, seed])
    bricks, sites, obstacles, start = random_layout(rng, n_sites=int(rng.integers(1, 4)), n_bricks=4)
    exact = step_by_step(bricks, sites, obstacles, start)
    plan = optimal_plan(bricks, sites, obstacles, [start])
    assert plan.distance == pytest.approx(exact)
    if math.isfinite(exact):
        # ... and its trips, costed again, walk exactly that far
        trips = [(t.agent, t.brick, t.site) for t in plan.trips]
        assert plan_distance(bricks, sites, obstacles, [start], trips).distance == pytest.approx(exact)


def test_a_straight_carry():
    # start at (0, 0), brick at (0, 3), site at (0, 6): walk to (0, 2), carry 4 cells
    bricks, sites, obstacles = (np.zeros((3, 8), bool) for _ in range(3))
    bricks[0, 3], sites[0, 6] = True, True
    plan = optimal_plan(bricks, sites, obstacles, [(0, 0)])
    assert plan.distance == pytest.approx(2 + 4)
    assert [(t.brick, t.site) for t in plan.trips] == [((0, 3), (0, 6))]


def test_a_site_that_must_be_filled_first_is_filled_first():
    # a dead-end corridor of two sites: the inner one first, or the outer blocks it
    obstacles = np.zeros((3, 6), bool)
    obstacles[0, 2:] = obstacles[2, 2:] = True
    obstacles[1, 5] = True
    sites, bricks = np.zeros_like(obstacles), np.zeros_like(obstacles)
    sites[1, 3] = sites[1, 4] = True
    bricks[0, 0] = bricks[2, 0] = True
    plan = optimal_plan(bricks, sites, obstacles, [(1, 0)])
    assert [t.site for t in plan.trips] == [(1, 4), (1, 3)]
    assert plan_distance(bricks, sites, obstacles, [(1, 0)], [(0, (0, 0), (1, 3)), (0, (2, 0), (1, 4))]
                         ).distance == math.inf


def test_two_agents_never_need_more_than_one():
    rng = np.random.default_rng(7)
    bricks, sites, obstacles, start = random_layout(rng, n_sites=3, n_bricks=4)
    other = tuple(int(v) for v in np.argwhere(~(bricks | sites | obstacles))[-1])
    one = optimal_plan(bricks, sites, obstacles, [start])
    two = optimal_plan(bricks, sites, obstacles, [start, other])
    assert two.distance <= one.distance + 1e-9


@pytest.mark.parametrize("seed", range(4))
def test_the_ideal_order_is_never_shorter_than_the_optimum(seed):
    rng = np.random.default_rng([360, seed])
    bricks, sites, obstacles, start = random_layout(rng, n_sites=3, n_bricks=5, size=7)
    r = replay(bricks, sites, obstacles, start)
    opt = optimal_plan(bricks, sites, obstacles, [start])
    ideal = plan_distance(bricks, sites, obstacles, [start], [(0, b, s) for b, s in r.order])
    assert ideal.distance >= opt.distance - 1e-9


def test_the_search_says_when_it_gives_up():
    rng = np.random.default_rng(3)
    bricks, sites, obstacles, start = random_layout(rng, n_sites=3, n_bricks=5, size=7)
    with pytest.raises(SearchBudgetExceeded):
        optimal_plan(bricks, sites, obstacles, [start], max_expanded=1)

"""Minimal-distance building plans for small layouts, by an exact search (issue 36).

The model is the grid of `experiments/replay.py` and `world_server/buildability.py`, with
every brick known from the start:

* cells are [row, col]; an agent moves 8-connected, an orthogonal step costing 1 and a
  diagonal one sqrt(2), never cutting a corner (`agent_runtime.spreading.distance_field`);
* it walks over empty cells, starts and unfilled sites; free bricks, filled sites and
  fixed obstacles (food, water, `#`, a prefilled `B`) block;
* a trip: an agent walks from where it stands to a cell beside a free brick (one of its
  4 neighbours: the gripper reaches 1.2 cells, a diagonal neighbour is 1.41 away), grabs
  it (its cell becomes free), carries it to an unfilled site's cell and drops it there;
  the site then blocks, and the agent's next trip starts from it. An agent carries one
  brick at a time; every brick grabbed is dropped on a site (as ConAg does).

With several agents a plan is a sequence of whole trips, each by any agent, the state
after one trip being the state the next starts in (the obstacles a trip meets are those
left by the trips before it). Its distance is the sum over trips: the total walked.

`optimal_plan` is A* over the states (sites filled, bricks taken, where each agent
stands). A transition is one trip; its cost is exact in the model: one distance field
from the agent, then per brick one seeded field from the cells beside it (carrying
starts where the walk ended), read at every open site. The heuristic never overestimates
(`_Heuristic`), so the first finished state taken from the queue is a least-distance plan
(A* with an admissible heuristic; a state reached again more cheaply is queued again).
`plan_distance` costs a given sequence of trips in the same model, so any order (the
ideal-order replay's, a live agent's) compares with the optimum: it is never below it.

Pure: numpy, the compiled distance fields; no world, no randomness.
"""

from __future__ import annotations

import heapq
import itertools
from dataclasses import dataclass

import numpy as np
from numba import njit

from agent_runtime.spreading import distance_field, seeded_distance_field

Cell = tuple[int, int]  # (row, col)

# States expanded before the search gives up (a layout too large for an exact answer).
MAX_EXPANDED = 400_000
_NEIGHBOURS = ((-1, 0), (1, 0), (0, -1), (0, 1))  # where an agent can stand to grab a brick


class SearchBudgetExceeded(RuntimeError):
    """The search expanded `max_expanded` states without finishing."""


@dataclass(frozen=True)
class Trip:
    """One trip of a plan: `agent` fetches the brick at `brick` and drops it at `site`."""

    agent: int
    brick: Cell
    site: Cell
    distance: float  # walked on this trip: to the cell beside the brick, then to the site


@dataclass(frozen=True)
class Plan:
    """A least-distance plan (`optimal_plan`) or a costed order (`plan_distance`)."""

    distance: float          # cells walked by all agents; inf when the trips cannot be made
    trips: tuple[Trip, ...]
    expanded: int = 0        # states the search expanded (0: costed, not searched)


@dataclass(frozen=True)
class _Map:
    """A layout's fixed parts: bool [row, col] grids and the cells of bricks and sites."""

    fixed: np.ndarray        # cells that always block
    brick_cells: tuple[Cell, ...]
    site_cells: tuple[Cell, ...]

    @classmethod
    def of(cls, bricks: np.ndarray, sites: np.ndarray, obstacles: np.ndarray) -> _Map:
        bricks, sites, obstacles = (np.array(g, dtype=bool) for g in (bricks, sites, obstacles))
        cells = lambda g: tuple((int(r), int(c)) for r, c in np.argwhere(g))  # noqa: E731
        return cls(obstacles & ~bricks & ~sites, cells(bricks), cells(sites))

    def blocked(self, filled: int, taken: int) -> np.ndarray:
        """Cells that block after the sites in `filled` got the bricks in `taken` (bit masks)."""
        grid = self.fixed.copy()
        for i, (r, c) in enumerate(self.brick_cells):
            if not taken >> i & 1:
                grid[r, c] = True
        for i, (r, c) in enumerate(self.site_cells):
            if filled >> i & 1:
                grid[r, c] = True
        return grid

    def beside(self, cell: Cell) -> list[Cell]:
        rows, cols = self.fixed.shape
        return [(cell[0] + dr, cell[1] + dc) for dr, dc in _NEIGHBOURS
                if 0 <= cell[0] + dr < rows and 0 <= cell[1] + dc < cols]


def _walk_field(blocked: np.ndarray, here: Cell) -> np.ndarray:
    """Distance from `here` to every cell (`here` may be the site just filled)."""
    start = np.zeros(blocked.shape, bool)
    start[here] = True
    return distance_field(start, blocked & ~start)


def _carry_field(m: _Map, blocked: np.ndarray, walk: np.ndarray, brick: int) -> np.ndarray:
    """Least distance (`walk`: from where the agent stands) to a cell beside brick `brick`
    plus from there, the brick in hand (its cell now free), to every cell: the cost of a
    trip to each site."""
    seed = np.full(blocked.shape, np.inf)
    for n in m.beside(m.brick_cells[brick]):
        seed[n] = walk[n]
    if not np.isfinite(seed).any():
        return seed
    after = blocked.copy()
    after[m.brick_cells[brick]] = False
    return seeded_distance_field(seed, after)


class _Heuristic:
    """A lower bound on the distance still to walk, from distances on the map with only
    the fixed obstacles (bricks and sites are open: every later map blocks more, so its
    distances are no shorter).

    g0(x, b) is the least such distance from x to a cell beside brick b. Every open site s
    is entered by a carry from beside some brick still free: at least c(s) = min over
    those bricks of g0(s, b). Every trip but each agent's first starts at a site filled
    before, walking to beside a free brick: at least c of that site; the sites that end
    an agent's chain start no trip. With m of the agents working: the m least first walks
    f (min over bricks of g0(agent, b)), plus twice the sum of c, less the m largest c.
    The least over m bounds every plan."""

    def __init__(self, m: _Map, starts: list[Cell]):
        self.m = m
        self.row_of: dict[Cell, int] = {}
        rows = []
        for cell in [*m.site_cells, *starts]:
            if cell in self.row_of:
                continue
            d = _walk_field(m.fixed, cell)
            self.row_of[cell] = len(rows)
            rows.append([min((d[n] for n in m.beside(b)), default=np.inf) for b in m.brick_cells])
        self.rows = np.array(rows, np.float64).reshape(len(rows), len(m.brick_cells))
        self.sites = np.array([self.row_of[s] for s in m.site_cells], np.int64)

    def __call__(self, filled: int, taken: int, where: tuple[Cell, ...]) -> float:
        return float(_bound(self.rows, self.sites, np.array([self.row_of[p] for p in where], np.int64),
                            filled, taken))


@njit(cache=True)
def _bound(rows, site_rows, agent_rows, filled, taken):
    """`_Heuristic` on arrays: `rows` (cells, bricks) holds g0 from the sites and starts,
    `site_rows` and `agent_rows` index it; `filled` and `taken` are bit masks."""
    n_sites, n_bricks = len(site_rows), rows.shape[1]
    sites = np.array([site_rows[i] for i in range(n_sites) if not filled >> i & 1], np.int64)
    bricks = np.array([j for j in range(n_bricks) if not taken >> j & 1], np.int64)
    walks = rows[agent_rows]
    n, nb, na = len(sites), len(bricks), len(agent_rows)
    if n == 0:
        return 0.0
    if nb < n:
        return np.inf  # too few bricks left: no plan goes on from here
    carry = np.empty((n, nb))
    for i in range(n):
        for j in range(nb):
            carry[i, j] = rows[sites[i], bricks[j]]
    # The chains: first walks, carries, and walks from every site but the chains' ends.
    c = np.empty(n)
    for i in range(n):
        c[i] = carry[i].min()
    f = np.empty(na)
    for a in range(na):
        f[a] = np.inf
        for j in range(nb):
            f[a] = min(f[a], walks[a, bricks[j]])
    c = np.sort(c)[::-1]
    f = np.sort(f)
    chains = np.inf
    for active in range(1, min(na, n) + 1):
        chains = min(chains, f[:active].sum() + 2 * c.sum() - c[:active].sum())
    # The assignment: each site a distinct brick, carried, after a walk to beside it from
    # an agent or from another open site.
    cost = np.empty((n, nb))
    for j in range(nb):
        before = np.inf
        for a in range(na):
            before = min(before, walks[a, bricks[j]])
        for i in range(n):
            other = before
            for i2 in range(n):
                if i2 != i:
                    other = min(other, carry[i2, j])
            cost[i, j] = carry[i, j] + other
    return max(chains, _assignment(cost))


@njit(cache=True)
def _assignment(a):
    """Least total cost of giving each row a distinct column (rows <= columns): the
    Hungarian method by shortest augmenting paths. inf if every way uses an inf entry."""
    n, m = a.shape
    big = 1e9
    u = np.zeros(n + 1)
    v = np.zeros(m + 1)
    p = np.zeros(m + 1, np.int64)
    way = np.zeros(m + 1, np.int64)
    for i in range(1, n + 1):
        p[0] = i
        j0 = 0
        minv = np.full(m + 1, np.inf)
        used = np.zeros(m + 1, np.bool_)
        while True:
            used[j0] = True
            i0 = p[j0]
            delta = np.inf
            j1 = 0
            for j in range(1, m + 1):
                if not used[j]:
                    x = a[i0 - 1, j - 1]
                    cur = (x if x < big else big) - u[i0] - v[j]
                    if cur < minv[j]:
                        minv[j] = cur
                        way[j] = j0
                    if minv[j] < delta:
                        delta = minv[j]
                        j1 = j
            for j in range(m + 1):
                if used[j]:
                    u[p[j]] += delta
                    v[j] -= delta
                else:
                    minv[j] -= delta
            j0 = j1
            if p[j0] == 0:
                break
        while True:
            j1 = way[j0]
            p[j0] = p[j1]
            j0 = j1
            if j0 == 0:
                break
    total = 0.0
    for j in range(1, m + 1):
        if p[j] != 0:
            total += a[p[j] - 1, j - 1]
    return total if total < big else np.inf


def optimal_plan(bricks: np.ndarray, sites: np.ndarray, obstacles: np.ndarray, starts: list[Cell],
                 max_expanded: int = MAX_EXPANDED) -> Plan:
    """A least-distance plan (cells walked by all agents) for agents at `starts` to fill
    every site, in the model of this module. Grids are bool [row, col]; `obstacles` are
    the fixed ones (prefilled sites among them). Distance inf (no trips) if no plan fills
    every site; SearchBudgetExceeded after `max_expanded` states."""
    m = _Map.of(bricks, sites, obstacles)
    k, nb = len(m.site_cells), len(m.brick_cells)
    starts = [(int(r), int(c)) for r, c in starts]
    h = _Heuristic(m, starts)
    done = (1 << k) - 1
    first = (0, 0, tuple(starts))
    best: dict[tuple, float] = {first: 0.0}
    parent: dict[tuple, tuple[tuple, Trip]] = {}
    tie = itertools.count()
    site_at = tuple(np.array(m.site_cells, np.int64).reshape(-1, 2).T)
    queue = [(h(*first), -0.0, next(tie), first)]  # ties: the deeper state first
    expanded = 0
    while queue:
        _, minus_g, _, state = heapq.heappop(queue)
        g = -minus_g
        if g > best[state]:
            continue  # reached again more cheaply since it was queued
        filled, taken, where = state
        if filled == done:
            return Plan(g, _trips(parent, state), expanded)
        expanded += 1
        if expanded > max_expanded:
            raise SearchBudgetExceeded(f"more than {max_expanded} states expanded")
        blocked = m.blocked(filled, taken)
        for agent, here in enumerate(where):
            if here in where[:agent]:
                continue  # two agents on one cell: the same trips
            walk = _walk_field(blocked, here)
            for b in range(nb):
                if taken >> b & 1:
                    continue
                costs = _carry_field(m, blocked, walk, b)[site_at].tolist()
                for s in range(k):
                    cost = costs[s]
                    if filled >> s & 1 or cost == np.inf:
                        continue
                    nxt = (filled | 1 << s, taken | 1 << b, (*where[:agent], m.site_cells[s], *where[agent + 1:]))
                    g2 = g + cost
                    if g2 < best.get(nxt, np.inf) - 1e-9:
                        best[nxt] = g2
                        parent[nxt] = (state, Trip(agent, m.brick_cells[b], m.site_cells[s], cost))
                        heapq.heappush(queue, (g2 + h(*nxt), -g2, next(tie), nxt))
    return Plan(np.inf, (), expanded)


def _trips(parent: dict, state: tuple) -> tuple[Trip, ...]:
    out = []
    while state in parent:
        state, trip = parent[state]
        out.append(trip)
    return tuple(reversed(out))


def plan_distance(bricks: np.ndarray, sites: np.ndarray, obstacles: np.ndarray, starts: list[Cell],
                  trips: list[tuple[int, Cell, Cell]]) -> Plan:
    """The distance of the trips (agent, brick cell, site cell), in order, in this model:
    each walked as short as the map then allows. inf if one cannot be made (a brick that
    is not free or cannot be reached, a site filled or cut off); trips may fill only some
    sites."""
    m = _Map.of(bricks, sites, obstacles)
    where = [(int(r), int(c)) for r, c in starts]
    filled = taken = 0
    costed, total = [], 0.0
    for agent, brick, site in trips:
        brick, site = (int(brick[0]), int(brick[1])), (int(site[0]), int(site[1]))
        if brick not in m.brick_cells or site not in m.site_cells:
            return Plan(np.inf, tuple(costed))
        b, s = m.brick_cells.index(brick), m.site_cells.index(site)
        if taken >> b & 1 or filled >> s & 1:
            return Plan(np.inf, tuple(costed))
        blocked = m.blocked(filled, taken)
        cost = float(_carry_field(m, blocked, _walk_field(blocked, where[agent]), b)[site])
        if not np.isfinite(cost):
            return Plan(np.inf, tuple(costed))
        total += cost
        costed.append(Trip(agent, brick, site, cost))
        filled, taken, where[agent] = filled | 1 << s, taken | 1 << b, site
    return Plan(total, tuple(costed))

"""Goal sequencing (paper §6, Fig. 15-18; G1-G2): calculateMatching and drop-site selection.

The Matching grid lies cell for cell on the agent's ESMs. calculateMatching (Fig. 16)
spreads activation a from the free bricks (S) and b from the unfilled drop sites (T),
every other disc being an obstacle (X). The cells of maximal a + b lie on the shortest
path of the closest brick/site pair; from each such site's neighbour the path is traced
down the gradient of a (succ, Eq. 3) to a brick, every cell on it gets match = 1, the
site leaves T, and the loop repeats until T is empty or no site can reach a brick.

Drop-site selection (§6.2) reads the grid: a site with match = 1 lies on the path of
another pair, so it is inhibited on the configuration NM (it would block that pair); a
brick with match = 1 was matched, so it alone excites the brick NM.

Two implementations of the same algorithm:
- `calculate_matching`: compiled (numba). a and b are exact distance fields from the
  spreading module's kernel (the fixed point of Eq. 2, which M rounds aim at), the
  maximum of a + b is a minimum of distance sums, and paths are pointer walks.
- `calculate_matching_grid`: Fig. 16 step by step as whole-grid numpy operations (shifts
  and minima over the grid, iterated until they settle), the reference the tests hold
  the compiled one to.

Both make the same choices where Fig. 16 is silent (S is never updated; unreachable sites
stay unmatched; step 3 compares with the best anywhere; succ is Eq. 3 in move order; a tie
at a site traces every tied way; closed sites for several agents): docs/design.md, "Goal
sequencing (§6)".
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import numpy as np
from numba import njit

from agent_runtime.spreading import _DC, _DR, _STEP, _TIE, _move_masks, _shift, distance_field, readonly


@dataclass(frozen=True)
class Matching:
    """The Matching grid after calculateMatching."""

    match: np.ndarray                                   # bool [row, col]: match = 1
    pairs: tuple[tuple[tuple[int, int], tuple[int, int]], ...]  # (site, brick) in matching order
    unmatched: tuple[tuple[int, int], ...]              # sites no brick can reach


def _grids(bricks, sites, obstacles, closed=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(S, T, walls): free bricks, open sites, and every cell no path may cross."""
    if closed is None:
        closed = np.zeros(np.shape(obstacles), bool)
    grids = [np.ascontiguousarray(g, dtype=np.bool_) for g in (bricks, sites, obstacles, closed)]
    if grids[0].ndim != 2 or len({g.shape for g in grids}) != 1:
        raise ValueError(f"bricks, sites, obstacles and closed must be equal 2-D shapes, got "
                         f"{[g.shape for g in grids]}")
    bricks, sites, obstacles, closed = grids
    # A disc that is an obstacle is neither a free brick nor an open site; a site that
    # already holds a brick is filled (the caller passes unfilled sites, this makes sure).
    sites = sites & ~obstacles & ~bricks
    return readonly(bricks & ~obstacles), readonly(sites), readonly(obstacles | (closed & sites))


def _result(match, rounds, site_r, site_c, brick_r, brick_c, left_r, left_c) -> Matching:
    """The Matching of the rounds' pairs; `left_r`, `left_c`: the unmatched sites in
    reading order."""
    n = int(rounds)
    sr, sc, br, bc = (a[:n].tolist() for a in (site_r, site_c, brick_r, brick_c))
    pairs = tuple(((r, c), (rb, cb)) for r, c, rb, cb in zip(sr, sc, br, bc))
    return Matching(match, pairs, tuple(zip(left_r.tolist(), left_c.tolist())))


# --- compiled ---------------------------------------------------------------------------


@njit(cache=True)
def _can_step(obstacles, r, c, j):
    """Whether move j leads from (r, c) to a free cell on the grid without cutting a corner
    (the cell (r, c) itself may be a wall: a closed site's path starts beside it)."""
    n, m = obstacles.shape
    rr, cc = r + _DR[j], c + _DC[j]
    if rr < 0 or rr >= n or cc < 0 or cc >= m or obstacles[rr, cc]:
        return False
    return j < 4 or not (obstacles[r + _DR[j], c] or obstacles[r, c + _DC[j]])


@njit(cache=True)
def _neighbour(da, obstacles, r, c, j):
    """da of the neighbour move j leads to, inf where the move is not allowed."""
    return da[r + _DR[j], c + _DC[j]] if _can_step(obstacles, r, c, j) else np.inf


@njit(cache=True)
def _nearest(da, obstacles, r, c):
    """The least da among the neighbours of (r, c) a move may reach (inf: none)."""
    best = np.inf
    for j in range(8):
        best = min(best, _neighbour(da, obstacles, r, c, j))
    return best


@njit(cache=True)
def _first_nearest(da, obstacles, r, c):
    """Eq. 3's succ: the first move in move order to a neighbour nearest a brick (within
    the tie). With no move allowed every move ties, and it is the first."""
    best = _nearest(da, obstacles, r, c)
    for j in range(8):
        if _neighbour(da, obstacles, r, c, j) <= best + _TIE:
            return j
    return 0


@njit(cache=True)
def _trace(da, obstacles, match, end, path, r, c):
    """Mark the path from (r, c) down the gradient of a to a brick; returns the brick.

    succ is a function of the cell alone, so from a cell an earlier path crossed the
    rest of the way is that path's: the walk stops there (every cell on it is marked
    already) and takes its brick from `end` (flat index per cell, -1: not walked yet),
    which it fills in for its own cells. `path`: scratch, one slot per cell."""
    m = da.shape[1]
    k = 0
    while end[r, c] < 0 and da[r, c] > 0.0:
        match[r, c] = True
        path[k] = r * m + c
        k += 1
        j = _first_nearest(da, obstacles, r, c)
        r, c = r + _DR[j], c + _DC[j]
    match[r, c] = True
    brick = end[r, c] if end[r, c] >= 0 else r * m + c
    end[r, c] = brick
    for i in range(k):
        end[path[i] // m, path[i] % m] = brick
    return brick // m, brick % m


@njit(cache=True)
def _site_value(da, obstacles, r, c):
    """A site's distance to its nearest brick through its best neighbour: da itself for an
    open site, and what it would be for a closed one (a wall to every other path)."""
    best = np.inf
    for j in range(8):
        if _can_step(obstacles, r, c, j):
            best = min(best, da[r + _DR[j], c + _DC[j]] + _STEP[j])
    return 0.0 if da[r, c] == 0.0 else best


@njit(cache=True)
def _matching_kernel(bricks, sites, obstacles, da):
    """The rounds of Fig. 16 over `da`, the distance field of the free bricks round the
    obstacles (step 1: a = 1 - k d): the grid, the rounds' pairs and the unmatched sites."""
    n, m = bricks.shape
    total = 0
    for r in range(n):
        for c in range(m):
            total += sites[r, c]
    # The sites in reading order, with their values: each round scans these, not the grid.
    rows = np.empty(total, np.int64)
    cols = np.empty(total, np.int64)
    value = np.empty(total)
    k = 0
    for r in range(n):
        for c in range(m):
            if sites[r, c]:
                rows[k], cols[k], value[k] = r, c, _site_value(da, obstacles, r, c)
                k += 1
    todo = np.ones(total, np.bool_)
    match = np.zeros((n, m), np.bool_)
    end = np.full((n, m), -1, np.int64)
    path = np.empty(n * m, np.int64)
    site_r = np.empty(total, np.int64)
    site_c = np.empty(total, np.int64)
    brick_r = np.empty(total, np.int64)
    brick_c = np.empty(total, np.int64)
    done = 0
    while True:
        best = np.inf
        for i in range(total):
            if todo[i]:
                best = min(best, value[i])
        if not np.isfinite(best):
            break                                               # no remaining site reaches a brick
        for i in range(total):                                  # steps 4-5, each maximal site
            if not todo[i] or value[i] > best + _TIE:
                continue
            todo[i] = False
            r, c = rows[i], cols[i]
            best_way = _nearest(da, obstacles, r, c)
            first = _first_nearest(da, obstacles, r, c)
            for j in range(8):                                  # every tied way out (see above)
                if _neighbour(da, obstacles, r, c, j) <= best_way + _TIE:
                    br, bc = _trace(da, obstacles, match, end, path, r + _DR[j], c + _DC[j])
                    if j == first:
                        brick_r[done], brick_c[done] = br, bc
            site_r[done], site_c[done] = r, c
            done += 1
    return match, done, site_r, site_c, brick_r, brick_c, rows[todo], cols[todo]


def _compiled(bricks, sites, obstacles, closed, distance: Callable[[np.ndarray, np.ndarray], np.ndarray]) -> Matching:
    bricks, sites, walls = _grids(bricks, sites, obstacles, closed)
    return _result(*_matching_kernel(bricks, sites, walls, readonly(distance(bricks, walls))))


def _around_closed(matcher, bricks, sites, obstacles, closed) -> Matching:
    """Match with `closed` sites uncrossable; sites that then reach no brick are matched
    again with them crossable: closed sites are avoided when there is another way, but a
    site whose every way out crosses one is still protected."""
    first = matcher(bricks, sites, obstacles, closed)
    if closed is None or not first.unmatched or not np.any(closed):
        return first
    rest = np.zeros(np.shape(sites), bool)
    rest[tuple(np.array(first.unmatched).T)] = True
    second = matcher(bricks, rest, obstacles, None)
    return Matching(first.match | second.match, first.pairs + second.pairs, second.unmatched)


def calculate_matching(bricks: np.ndarray, sites: np.ndarray, obstacles: np.ndarray,
                       closed: np.ndarray | None = None,
                       distance: Callable[[np.ndarray, np.ndarray], np.ndarray] = distance_field) -> Matching:
    """Fig. 16, compiled: `bricks` free bricks (S), `sites` unfilled drop sites (T),
    `obstacles` every other disc (X); bool grids of one shape, indexed [row, col].

    `closed` marks sites that other paths should not cross (the agent has not seen them
    open lately: another agent may have filled them). They are matched like any site; a
    site whose only ways out cross closed sites is matched as if they were open.

    `distance`: how step 1's distance field of the free bricks is made, as
    `spreading.distance_field` makes it (an agent passes its field cache's, which often
    holds it already: it is also the mouth-side rule's depth).
    """
    return _around_closed(partial(_compiled, distance=distance), bricks, sites, obstacles, closed)


# --- Fig. 16 as whole-grid steps (the reference) ----------------------------------------


def _spread(sources: np.ndarray, masks: list[np.ndarray]) -> np.ndarray:
    """Eq. 2 in distance form (a = 1 - k d): every cell takes the best of its passable
    neighbours plus the step, over the whole grid at once, until nothing changes."""
    d = np.where(sources, 0.0, np.inf)
    while True:
        new = d.copy()
        for (dr, dc), step, ok in zip(zip(_DR.tolist(), _DC.tolist()), _STEP.tolist(), masks):
            np.minimum(new, np.where(ok, _shift(d, dr, dc, np.inf) + step, np.inf), out=new)
        if np.array_equal(new, d):
            return d
        d = new


def _exits(walls: np.ndarray) -> list[np.ndarray]:
    """Per move, where a cell may step to that neighbour: the neighbour is free and, for a
    diagonal, so are both flanking cells. The cell itself may be a wall (a closed site's
    path starts beside it)."""
    free = ~walls
    exits = []
    for dr, dc in zip(_DR.tolist(), _DC.tolist()):
        ok = _shift(free, dr, dc, False)
        if dr and dc:
            ok &= _shift(free, dr, 0, False) & _shift(free, 0, dc, False)
        exits.append(ok)
    return exits


def _succ_grid(da: np.ndarray, exits: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """succ(n) of Eq. 3 for every cell at once, as (row, col) index grids, and per move
    whether that neighbour ties for nearest (a (8, N, M) mask)."""
    n, m = da.shape
    cand = np.stack([np.where(ok, _shift(da, dr, dc, np.inf), np.inf)
                     for dr, dc, ok in zip(_DR.tolist(), _DC.tolist(), exits)])
    tied = cand <= cand.min(axis=0) + _TIE
    first = np.argmax(tied, axis=0)  # first move within the tie
    rows, cols = np.indices((n, m))
    return np.clip(rows + _DR[first], 0, n - 1), np.clip(cols + _DC[first], 0, m - 1), tied


def calculate_matching_grid(bricks: np.ndarray, sites: np.ndarray, obstacles: np.ndarray,
                            closed: np.ndarray | None = None) -> Matching:
    """Fig. 16 step by step as whole-grid operations (slow; the tests' reference)."""
    return _around_closed(_whole_grid, bricks, sites, obstacles, closed)


def _whole_grid(bricks, sites, obstacles, closed) -> Matching:
    bricks, sites, walls = _grids(bricks, sites, obstacles, closed)
    masks, exits = _move_masks(~walls), _exits(walls)
    da = _spread(bricks, masks)                                          # step 1
    succ_r, succ_c, tied = _succ_grid(da, exits)
    value = np.where(da == 0, 0.0, np.min([np.where(ok, _shift(da, dr, dc, np.inf) + step, np.inf)
                                            for dr, dc, step, ok in zip(_DR.tolist(), _DC.tolist(),
                                                                        _STEP.tolist(), exits)], axis=0))
    todo, match = sites.copy(), np.zeros(sites.shape, bool)
    pairs: list[tuple[int, int, int, int]] = []
    while np.isfinite(value[todo]).any():
        c = np.where(todo, value, da + _spread(todo & ~walls, masks))   # steps 2-3
        chosen = todo & (c <= c.min() + _TIE)                            # T[n] and hasMaxValue[n]
        on_path = np.zeros_like(match)                                   # step 4: every tied way out
        for (dr, dc), way in zip(zip(_DR.tolist(), _DC.tolist()), tied):
            on_path |= _shift(chosen & way, -dr, -dc, False)
        while True:
            grow = on_path.copy()
            walking = on_path & (da > 0)
            grow[succ_r[walking], succ_c[walking]] = True
            if np.array_equal(grow, on_path):
                break
            on_path = grow
        match |= on_path                                                 # step 5
        todo &= ~chosen
        for r, c_ in zip(*np.nonzero(chosen)):  # the pairs, for the report only
            pairs.append((r, c_, *_trace_end(int(succ_r[r, c_]), int(succ_c[r, c_]), da, succ_r, succ_c)))
    site_r, site_c, brick_r, brick_c = np.array(pairs, np.int64).reshape(-1, 4).T
    left = sites.copy()
    left[site_r, site_c] = False
    return _result(match, len(pairs), site_r, site_c, brick_r, brick_c, *np.nonzero(left))


def _trace_end(r: int, c: int, da: np.ndarray, succ_r: np.ndarray, succ_c: np.ndarray) -> tuple[int, int]:
    while da[r, c] > 0:
        r, c = int(succ_r[r, c]), int(succ_c[r, c])
    return r, c


# --- drop-site selection (§6.2) ---------------------------------------------------------


def select_goals(matching: Matching, bricks: np.ndarray, sites: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(site goals, brick goals) for the configuration and brick NMs.

    The Matching grid inhibits the configuration NM (a site with match = 1 would block
    another pair's path) and excites the brick NM (only matched bricks are goals).
    """
    return sites & ~matching.match, bricks & matching.match

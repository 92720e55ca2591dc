"""Where the world puts things an agent can no longer place itself: pure functions on grids.

A dead agent's brick must land where nothing needs it (`brick_drop_cell`), a restarted
agent's body where it overlaps nothing and the open world reaches (`body_cell`,
`reachable_cells`), and agents beyond a scenario's `A` cells near those starts
(`extra_start_cells`). They take bool grids indexed
[row, col] like `Scenario.grid` (row 0 is the north) and a start in fractional cell
coordinates (col, row), the centre of cell (c, r) being (c + 0.5, r + 0.5); they return
the nearest cell that qualifies, by straight-line distance from the start, ties in
reading order (row, then column), so the choice is deterministic.

`spread_cells` is for a layout's author (the generator): the starts of a crowd, spread
over the floor rather than packed together, since a packed crowd is every body's obstacle.
"""

from __future__ import annotations

from collections import deque

import numpy as np


def _by_distance(ok: np.ndarray, start: tuple[float, float]) -> tuple[int, int] | None:
    """The (col, row) of the `ok` cell nearest `start`; None if there is none."""
    rows, cols = np.nonzero(ok)  # reading order
    if rows.size == 0:
        return None
    d2 = np.square(cols + 0.5 - start[0]) + np.square(rows + 0.5 - start[1])
    best = int(np.argmin(d2))  # the first of equals: reading order
    return int(cols[best]), int(rows[best])


def _dilate(grid: np.ndarray, outside: bool) -> np.ndarray:
    """Cells whose 8-neighbourhood (themselves included) holds a True cell; beyond the
    grid's edge counts as `outside`."""
    padded = np.pad(grid, 1, constant_values=outside)
    out = np.zeros_like(grid)
    rows, cols = grid.shape
    for dr in (0, 1, 2):
        for dc in (0, 1, 2):
            out |= padded[dr:dr + rows, dc:dc + cols]
    return out


def brick_drop_cell(free: np.ndarray, site: np.ndarray, start: tuple[float, float]) -> tuple[int, int] | None:
    """The cell where a dead agent's brick is dropped: the nearest one, in order of preference,

    1. that is free, is no drop site and has no drop site among its 8 neighbours (the
       structure and the ring round it, where builders walk, stay clear), and whose 8
       neighbours are all free and inside the world: a brick there cannot cut any path,
       since a way through the cell can go round it by the free ring of neighbours;
    2. failing that, free, no site and no site among its neighbours;
    3. failing that, free and no site.

    `free`: the cell can take a brick (no wall, disc or body in it); `site`: it is a drop
    site. None when no free cell is left that is not a site (the caller drops the brick
    where it is).
    """
    free = np.asarray(free, bool)
    site = np.asarray(site, bool)
    candidates = free & ~site
    clear = candidates & ~_dilate(site, outside=False)
    open_ = clear & ~_dilate(~free, outside=True)
    for ok in (open_, clear, candidates):
        cell = _by_distance(ok, start)
        if cell is not None:
            return cell
    return None


def body_cell(free: np.ndarray, start: tuple[float, float], reachable: np.ndarray | None = None
              ) -> tuple[int, int] | None:
    """The free cell nearest `start` for a body to come back at; None if there is none.

    With `reachable` (`reachable_cells`), only a cell the open world reaches: bricks laid
    while the body was away may have sealed where it stood into a pocket, and a body put
    there could never get out. Where no such cell is free, any free cell (a crowded world
    is no reason to refuse an agent its body)."""
    free = np.asarray(free, bool)
    if reachable is not None:
        cell = _by_distance(free & np.asarray(reachable, bool), start)
        if cell is not None:
            return cell
    return _by_distance(free, start)


def reachable_cells(passable: np.ndarray, seeds: np.ndarray) -> np.ndarray:
    """bool [row, col]: the `passable` cells a body can walk to (4-connected steps through
    `passable` cells) from any passable seed (k, 2) (col, row); all False if none is."""
    passable = np.asarray(passable, bool)
    seeds = np.asarray(seeds, np.int64).reshape(-1, 2)
    rows, cols = passable.shape
    inside = (seeds[:, 0] >= 0) & (seeds[:, 0] < cols) & (seeds[:, 1] >= 0) & (seeds[:, 1] < rows)
    seeds = seeds[inside]
    return _walking_distance(passable, seeds[passable[seeds[:, 1], seeds[:, 0]]]) >= 0


def _walking_distance(passable: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """int [row, col]: steps from the nearest start through `passable` cells (4-connected;
    the starts count as passable), -1 where none reaches."""
    rows, cols = passable.shape
    dist = np.full(passable.shape, -1, np.int64)
    queue: deque[tuple[int, int]] = deque()
    for c, r in np.asarray(starts, np.int64).reshape(-1, 2):
        if 0 <= r < rows and 0 <= c < cols and dist[r, c] < 0:
            dist[r, c] = 0
            queue.append((int(r), int(c)))
    while queue:
        r, c = queue.popleft()
        for nr, nc in ((r - 1, c), (r + 1, c), (r, c - 1), (r, c + 1)):
            if 0 <= nr < rows and 0 <= nc < cols and passable[nr, nc] and dist[nr, nc] < 0:
                dist[nr, nc] = dist[r, c] + 1
                queue.append((nr, nc))
    return dist


def extra_start_cells(empty: np.ndarray, passable: np.ndarray, starts: np.ndarray) -> np.ndarray:
    """(k, 2) (col, row) of the `empty` cells in the order extra agents get them: by walking
    distance from the nearest start (4-connected steps through `passable` cells, which the
    starts and empty cells are), ties in reading order; then the empty cells no start can
    walk to, in reading order. With no start at all: every empty cell in reading order.

    So a scenario's `A` cells are the seeds of a growing patch of agents, on the starts' side
    of any wall, instead of a pile in the top-left corner.
    """
    empty = np.asarray(empty, bool)
    dist = _walking_distance(np.asarray(passable, bool) | empty, starts)
    er, ec = np.nonzero(empty)  # reading order
    d = dist[er, ec]
    key = np.where(d < 0, np.iinfo(np.int64).max, d)
    order = np.argsort(key, kind="stable")  # stable: ties keep reading order
    return np.column_stack([ec[order], er[order]]).astype(np.int64)


def spread_cells(free: np.ndarray, k: int, first: tuple[int, int]) -> np.ndarray:
    """(k, 2) (col, row) of `k` `free` cells spread over the floor: `first` (a free cell,
    (col, row)), then again and again the free cell farthest (straight-line) from every
    cell chosen so far, ties in reading order (farthest-point sampling: each new start
    goes into the largest gap left, so the spacing is even and as wide as the floor
    allows). Fewer than `k` rows when there are fewer free cells."""
    free = np.asarray(free, bool)
    rows, cols = np.nonzero(free)  # reading order
    if not free[first[1], first[0]]:
        raise ValueError(f"the first cell {first} is not free")
    at = int(np.flatnonzero((cols == first[0]) & (rows == first[1]))[0])
    gap = np.full(rows.size, np.inf)
    chosen = []
    for _ in range(min(k, rows.size)):
        chosen.append(at)
        gap = np.minimum(gap, np.square(cols - cols[at]) + np.square(rows - rows[at]))
        at = int(np.argmax(gap))  # the first of equals: reading order
    return np.column_stack([cols[chosen], rows[chosen]]).astype(np.int64)

"""Can a scenario's structure be built at all? A grid model of building (no physics).

`check_buildable(scenario)` answers with a fill order that proves it, or a sentence that
says why not. The model is the layout itself, one cell a step:

* agents walk 4-connected over `.`, `A` and unfilled `+` cells (8-moves without cutting
  corners reach the same cells); `F`, `W`, `b`, `B`, `#` and the world edge block;
* a free brick is grabbable when one of its 4 neighbours is reachable; a pile is taken
  from its face, so a brick behind others is obtainable once they are gone;
* filling site S: one agent grabs a brick (its cell becomes empty, which may open a way),
  walks to S and leaves `B` there. Reachability is from ANY agent start, but a fill needs
  one agent that reaches both: agents in separate areas each serve their own area.

The starts are where the world puts the scenario's `agents`: the `A` cells in reading
order, then (more agents than `A` cells) the empty cells nearest them by walking distance;
a layout with no `A` has no start. Sites already holding `B` are obstacles like any other.

A layout is buildable if some order fills every open site. The search is the paper's
goal sequencing (§6) as a fixed priority - deepest first, where the depth of a site is
how many sites an agent must cross to reach it, and farthest from the bricks among
equals (a pocket is filled from its end, an inner ring before the outer one) - plus a
safety check after every fill: each remaining site must still be reachable, possibly
through bricks that will be taken later, and every area an agent can reach must still
hold at least as many bricks as it has open sites. Both are necessary for success, so a
fill that breaks them is never part of a solution. The brick for a fill is the nearest
one whose loss leaves its area enough bricks (bricks that dig towards sites nobody can
reach yet come first). If the greedy order gets stuck anyway, a bounded depth-first
backtracking tries other bricks, then other sites. On small layouts this agrees with an
exhaustive search (tests/test_buildability.py).

Pure numpy + numba: no world, no bus. API: `check_buildable`, `check_layout`,
`reachable`, `Buildability`.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numba import njit

from world_server.placement import extra_start_cells

Cell = tuple[int, int]  # (col, row), row 0 is the north, as Scenario.cells_col_row

# Cell codes in the kernels' padded grid (not the world's disc kinds, nor the ESM layers).
# Walkable cells are <= SITE_CELL, cells an agent can eventually clear a way through are
# <= BRICK_CELL.
EMPTY_CELL, SITE_CELL, BRICK_CELL, BLOCK_CELL = 0, 1, 2, 3
_CODE = {".": EMPTY_CELL, "A": EMPTY_CELL, "+": SITE_CELL, "b": BRICK_CELL,
         "F": BLOCK_CELL, "W": BLOCK_CELL, "B": BLOCK_CELL, "#": BLOCK_CELL}

# Search outcomes and the reasons a candidate fill is refused (kernel return codes).
_OK, _STUCK, _BUDGET = 0, 1, 2
_CUTS_SITE, _TOO_FEW, _NO_BRICK = 1, 2, 3

# Search budget in cell visits (a fill attempt visits every cell a few times): under a
# second, whatever the size - far more than the generator's layouts need, which the greedy
# order builds with few or no backtracks. A layout that needs more is hard in a way worth
# reporting.
SEARCH_WORK = 60_000_000
# Sites named in a reason beside the first that no agent can reach.
MORE_SITES_NAMED = 5
# Bricks tried per site when backtracking (the first is nearly always right; the others
# matter when a pile must be dug through in a particular way).
MAX_BRICK_CHOICES = 4


@dataclass(frozen=True)
class Buildability:
    """The verdict of `check_buildable`: ok or why not, and a fill order with its bricks that works."""

    ok: bool
    reason: str = ""                   # empty when ok; otherwise a sentence naming (col,row) cells
    order: tuple[Cell, ...] = ()       # the open sites in a fill order that works
    bricks: tuple[Cell, ...] = ()      # the free brick taken for each fill of `order`
    spare: int = 0                     # bricks the agents can reach beyond one per open site

    def __bool__(self) -> bool:
        return self.ok


# ---------------------------------------------------------------- public API


def check_buildable(scenario) -> Buildability:
    """Buildability of a parsed `Scenario` (its layout and agent count)."""
    return check_layout(scenario.layout, scenario.agents)


def check_layout(layout: Sequence[str], agents: int | None = None, work: int = SEARCH_WORK) -> Buildability:
    """Buildability of an ASCII layout (rows north first) for `agents` agents (None: one
    on every `A`). `work` bounds the backtracking, in cell visits."""
    grid, cols = _encode(layout)
    starts = _starts(layout, agents)
    if not (grid == SITE_CELL).any():
        return Buildability(False, "no open drop site: every site already holds a brick"
                            if any("B" in row for row in layout) else "no drop site")
    if not len(starts):
        return Buildability(False, "no agent start (the scenario has 0 agents)" if agents == 0 else "no agent start")
    reason, spare = _necessary(grid, cols, starts)
    if reason:
        return Buildability(False, reason)
    prio = _priority(grid, cols, starts)
    attempts = max(work // grid.size, 4 * len(prio) + 100)  # the greedy pass always fits
    status, n_done, sites, bricks, fail = _search(grid, cols + 2, prio, starts, attempts, MAX_BRICK_CHOICES)
    if status != _OK:
        return Buildability(False, _stuck_reason(status, n_done, len(prio), fail, cols))
    cell = lambda i: _cell(i, cols)  # noqa: E731
    return Buildability(True, "", tuple(map(cell, sites)), tuple(map(cell, bricks)), spare)


def reachable(layout: Sequence[Sequence[str]], starts: Sequence[Cell] | None = None) -> set[Cell]:
    """Cells an agent can walk to from any of `starts` (default: every `A`), as (col, row)."""
    grid, cols = _encode(layout)
    if starts is None:
        starts = [(c, r) for r, row in enumerate(layout) for c, ch in enumerate(row) if ch == "A"]
    idx = np.array([(r + 1) * (cols + 2) + c + 1 for c, r in starts], np.int64)
    labels, _ = _label(grid, cols + 2, SITE_CELL)
    mine = np.unique(labels[idx][labels[idx] >= 0])
    return {_cell(int(i), cols) for i in np.flatnonzero(np.isin(labels, mine) & (labels >= 0))}


# ---------------------------------------------------------------- layout <-> kernel arrays


def _encode(layout: Sequence[Sequence[str]]) -> tuple[np.ndarray, int]:
    """Flat padded code grid (a BLOCK_CELL border, so neighbours never leave the array), and cols."""
    rows, cols = len(layout), len(layout[0])
    grid = np.full((rows + 2, cols + 2), BLOCK_CELL, np.int8)
    lut = np.full(128, BLOCK_CELL, np.int8)
    for ch, code in _CODE.items():
        lut[ord(ch)] = code
    chars = np.array([[min(ord(ch), 127) for ch in row] for row in layout], np.int64).reshape(rows, cols)
    grid[1:-1, 1:-1] = lut[chars]
    return grid.ravel(), cols


def _cell(i: int, cols: int) -> Cell:
    r, c = divmod(int(i), cols + 2)
    return (c - 1, r - 1)


def _starts(layout: Sequence[str], agents: int | None) -> np.ndarray:
    """Padded indices of the agents' start cells, as the world hands them out: the `A`
    cells in reading order, then (more agents than `A` cells) the empty cells nearest them
    (`placement.extra_start_cells`)."""
    width = len(layout[0]) + 2
    chars = np.array([list(row) for row in layout])
    a_rows, a_cols = np.nonzero(chars == "A")
    cells = list((a_rows + 1) * width + a_cols + 1)
    if agents is None or not cells:
        return np.array(cells, np.int64)  # no `A` at all is a layout without a start
    extra: list[int] = []
    if agents > len(cells):
        order = extra_start_cells(chars == ".", ~np.isin(chars, list("#FWbB")), np.column_stack([a_cols, a_rows]))
        extra = [(r + 1) * width + c + 1 for c, r in order[:agents - len(cells)]]
    return np.array(cells[:max(agents, 0)] + extra, np.int64)


def _necessary(grid: np.ndarray, cols: int, starts: np.ndarray) -> tuple[str, int]:
    """Why a site can never be reached or an area has too few bricks ('' if neither), and
    how many bricks the agents can reach beyond one per open site."""
    labels, n = _label(grid, cols + 2, BRICK_CELL)
    mine = np.zeros(n, bool)
    mine[labels[starts]] = True
    sites = np.flatnonzero(grid == SITE_CELL)
    lost = sites[~mine[labels[sites]]]
    if len(lost):
        more = ""
        if len(lost) > 1:
            shown = ", ".join(_fmt(_cell(i, cols)) for i in lost[1:1 + MORE_SITES_NAMED])
            more = (f" (and {_count(len(lost) - 1, 'more site')} no agent can reach: {shown}"
                    + (", ..." if len(lost) - 1 > MORE_SITES_NAMED else "") + ")")
        return _walled_off(grid, labels, lost[0], cols) + more, 0
    bricks = np.flatnonzero(grid == BRICK_CELL)
    site_count = np.bincount(labels[sites], minlength=n)
    brick_count = np.bincount(labels[bricks], minlength=n)
    short = np.flatnonzero(mine & (brick_count < site_count))
    if not len(short):
        return "", int(brick_count[mine].sum() - len(sites))
    area = short[0]
    sites_, bricks_ = _count(site_count[area], "open site"), _count(brick_count[area], "free brick")
    if mine.sum() == 1:
        return f"{sites_} but only {bricks_} can be reached", 0
    start = _cell(starts[labels[starts] == area][0], cols)
    return f"the agent start at {_fmt(start)} can reach {sites_} but only {bricks_}", 0


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}" + ("" if n == 1 else "s")


def _walled_off(grid: np.ndarray, labels: np.ndarray, s: int, cols: int) -> str:
    held = int((grid[labels == labels[s]] == BRICK_CELL).sum())
    if held:
        return f"site {_fmt(_cell(s, cols))} is walled off from every agent start (with {_count(held, 'brick')})"
    return f"site {_fmt(_cell(s, cols))} is inside a closed ring with no brick and no way in"


def _stuck_reason(status: int, n_done: int, n_sites: int, fail: np.ndarray, cols: int) -> str:
    head = ("no fill order found within the search budget" if status == _BUDGET
            else "no fill order found")
    kind, site, other = int(fail[0]), _cell(fail[1], cols), _cell(fail[2], cols)
    why = {_CUTS_SITE: f"filling {_fmt(site)} walls off site {_fmt(other)}",
           _TOO_FEW: f"filling {_fmt(site)} leaves too few reachable bricks",
           _NO_BRICK: f"no free brick can be brought to site {_fmt(site)}"}.get(kind, "")
    return f"{head}: stuck after {n_done} of {n_sites} sites" + (f" ({why})" if why else "")


def _fmt(cell: Cell) -> str:
    return f"({cell[0]},{cell[1]})"


def _priority(grid: np.ndarray, cols: int, starts: np.ndarray) -> np.ndarray:
    """Open sites, hardest to keep open first: deepest, then farthest from the bricks."""
    depth, dist = _depth_and_brick_distance(grid, cols + 2, starts)
    sites = np.flatnonzero(grid == SITE_CELL)
    return sites[np.lexsort((sites, -dist[sites], -depth[sites]))]


# ---------------------------------------------------------------- compiled kernels


@njit(cache=True)
def _label(grid, width, top):
    """Component label of every cell whose code is <= top (4-connected), -1 elsewhere."""
    n = grid.size
    labels = np.full(n, -1, np.int32)
    stack = np.empty(n, np.int64)
    count = 0
    for seed in range(n):
        if grid[seed] > top or labels[seed] >= 0:
            continue
        labels[seed] = count
        stack[0] = seed
        sp = 1
        while sp:
            sp -= 1
            u = stack[sp]
            for v in (u - 1, u + 1, u - width, u + width):
                if grid[v] <= top and labels[v] < 0:
                    labels[v] = count
                    stack[sp] = v
                    sp += 1
        count += 1
    return labels, count


@njit(cache=True)
def _layers(grid, width, sources, costly):
    """Fewest cells of code `costly` entered on a way from any source over cells <= BRICK_CELL
    (sites are crossed by walking, bricks by taking them). Unreached cells get n + 1."""
    n = grid.size
    big = n + 1
    out = np.full(n, big, np.int64)
    cur = np.empty(n, np.int64)
    nxt = np.empty(n, np.int64)
    nc = 0
    for s in sources:
        if out[s] == big:
            out[s] = 0
            cur[nc] = s
            nc += 1
    d = 0
    while nc:
        nn = 0
        sp = nc  # flood this layer over free steps; a costly cell starts the next layer
        while sp:
            sp -= 1
            u = cur[sp]
            for v in (u - 1, u + 1, u - width, u + width):
                if grid[v] > BRICK_CELL or out[v] != big:
                    continue
                if grid[v] == costly:
                    out[v] = d + 1
                    nxt[nn] = v
                    nn += 1
                else:
                    out[v] = d
                    cur[sp] = v
                    sp += 1
        cur, nxt = nxt, cur
        nc = nn
        d += 1
    return out


@njit(cache=True)
def _depth_and_brick_distance(grid, width, starts):
    """depth: fewest sites crossed from a start (bricks are passable: they can be taken);
    dist: walking steps from the nearest free brick. Unreached cells get a large value."""
    n = grid.size
    depth = _layers(grid, width, starts, SITE_CELL)
    dist = np.full(n, n + 1, np.int64)
    queue = np.empty(n, np.int64)
    head = tail = 0
    for i in range(n):
        if grid[i] == BRICK_CELL:
            dist[i] = 0
            queue[tail] = i
            tail += 1
    while head < tail:
        u = queue[head]
        head += 1
        for v in (u - 1, u + 1, u - width, u + width):
            if grid[v] <= SITE_CELL and dist[v] == n + 1:
                dist[v] = dist[u] + 1
                queue[tail] = v
                tail += 1
    return depth, dist


@njit(cache=True)
def _try_fill(grid, width, s, rank, walk, walk_start, dig, starts, fail):
    """Fill site s if that is safe: put a BLOCK_CELL there and take the `rank`-th best usable
    brick (its cell becomes EMPTY_CELL). Return the brick, or -1 with `fail` = (kind, site, other)."""
    grid[s] = BLOCK_CELL
    part, n_parts = _label(grid, width, BRICK_CELL)
    agent_part = np.zeros(n_parts, np.bool_)
    for a in starts:
        agent_part[part[a]] = True
    n_sites = np.zeros(n_parts, np.int64)
    n_bricks = np.zeros(n_parts, np.int64)
    for i in range(grid.size):
        if grid[i] == SITE_CELL:
            if not agent_part[part[i]]:
                grid[s] = SITE_CELL
                fail[0], fail[1], fail[2] = _CUTS_SITE, s, i
                return -1
            n_sites[part[i]] += 1
        elif grid[i] == BRICK_CELL:
            n_bricks[part[i]] += 1
    for p in range(n_parts):
        if agent_part[p] and n_bricks[p] < n_sites[p]:
            grid[s] = SITE_CELL
            fail[0], fail[1], fail[2] = _TOO_FEW, s, s
            return -1
    brick = _usable_brick(grid, width, s, rank, walk, walk_start, dig, part, agent_part, n_sites, n_bricks)
    if brick < 0:
        grid[s] = SITE_CELL
        fail[0], fail[1], fail[2] = _NO_BRICK, s, s
        return -1
    grid[brick] = EMPTY_CELL
    return brick


@njit(cache=True)
def _usable_brick(grid, width, s, rank, walk, walk_start, dig, part, agent_part, n_sites, n_bricks):
    """The `rank`-th best brick an agent can grab and bring to s whose loss leaves its area
    enough bricks (or whose area is lost anyway): bricks that dig towards sites nobody can
    reach yet first, then the nearest (breadth-first from s over its walking area)."""
    own = walk[s]
    queue = np.empty(grid.size, np.int64)
    found = np.empty(grid.size, np.int64)
    seen = np.zeros(grid.size, np.bool_)
    queue[0] = s
    seen[s] = True
    head, tail, nf = 0, 1, 0
    while head < tail:
        u = queue[head]
        head += 1
        for v in (u - 1, u + 1, u - width, u + width):
            if seen[v]:
                continue
            seen[v] = True
            if walk[v] == own:
                queue[tail] = v
                tail += 1
            elif grid[v] == BRICK_CELL and (walk_start[own] or _touches_agents(v, width, walk, walk_start)):
                p = part[v]
                if not agent_part[p] or n_bricks[p] - n_sites[p] >= 1:
                    found[nf] = v
                    nf += 1
    if rank >= nf:
        return -1
    order = np.argsort(dig[found[:nf]], kind="mergesort")  # stable: nearest among equals
    return found[order[rank]]


@njit(cache=True)
def _touches_agents(v, width, walk, walk_start):
    for w in (v - 1, v + 1, v - width, v + width):  # noqa: SIM110 -- numba compiles this loop, not any() of a generator
        if walk[w] >= 0 and walk_start[walk[w]]:
            return True
    return False


@njit(cache=True)
def _search(grid, width, prio, starts, max_attempts, max_bricks):
    """Depth-first over fills (site in `prio` order, then up to `max_bricks` brick choices);
    the first complete order wins. Returns (status, fills done, sites, bricks, fail): on
    failure the deepest point reached and why its first candidate was refused."""
    grid = grid.copy()
    n = prio.size
    filled = np.zeros(n, np.bool_)
    pos = np.zeros(n, np.int64)
    rank = np.zeros(n, np.int64)
    sites = np.zeros(n, np.int64)
    bricks = np.zeros(n, np.int64)
    fail = np.zeros(3, np.int64)
    best_fail = np.zeros(3, np.int64)
    k = nxt = nxt_rank = attempts = best = 0
    while k < n:
        walk, n_walk = _label(grid, width, SITE_CELL)
        walk_start = np.zeros(n_walk, np.bool_)
        for a in starts:
            walk_start[walk[a]] = True
        dig = _dig_distance(grid, width, prio, filled, walk, walk_start)
        done = False
        for j in range(nxt, n):
            if filled[j]:
                continue
            r0 = nxt_rank if j == nxt else 0
            for r in range(r0, max_bricks):
                attempts += 1
                if attempts > max_attempts:
                    return _BUDGET, best, sites[:0], bricks[:0], best_fail
                b = _try_fill(grid, width, prio[j], r, walk, walk_start, dig, starts, fail)
                if b >= 0:
                    filled[j] = True
                    pos[k], rank[k], sites[k], bricks[k] = j, r, prio[j], b
                    k += 1
                    done = True
                    break
                if k > best or best_fail[0] == 0:  # remember the first refusal at the deepest point
                    best = k
                    for i in range(3):  # a loop: numba's slice assignment compiles for seconds
                        best_fail[i] = fail[i]
                if fail[0] != _NO_BRICK:
                    break  # the site itself is the problem, not the brick
            if done:
                break
        if done:
            nxt = nxt_rank = 0
            continue
        if k == 0:
            return _STUCK, best, sites[:0], bricks[:0], best_fail
        k -= 1  # undo the last fill; resume with its next brick, then its next site
        grid[sites[k]] = SITE_CELL
        grid[bricks[k]] = BRICK_CELL
        filled[pos[k]] = False
        nxt, nxt_rank = pos[k], rank[k] + 1
    return _OK, n, sites, bricks, best_fail


@njit(cache=True)
def _dig_distance(grid, width, prio, filled, walk, walk_start):
    """Bricks to take on the way to the nearest open site no agent can walk to yet (all 0
    when every open site is reachable): taking the low ones first opens a way in."""
    n = 0
    cut = np.empty(prio.size, np.int64)
    for j in range(prio.size):
        if not filled[j] and not walk_start[walk[prio[j]]]:
            cut[n] = prio[j]
            n += 1
    if n == 0:
        return np.zeros(grid.size, np.int64)
    return _layers(grid, width, cut[:n], BRICK_CELL)

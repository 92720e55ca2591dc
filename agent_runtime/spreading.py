"""Navigation maps: spreading activation on a grid (paper §4.2.2, Eq. 1-2; A3).

A navigation map (NM) is a grid of neurons. Goal cells start at activation 1, obstacle
cells at -1, all others at 0 (Eq. 1), and every non-goal cell repeatedly takes the best
of its eight neighbours minus a cost proportional to the step length (Eq. 2) until
nothing changes. The paper notes that this is a parallel Dijkstra: the fixed point is
`1 - decay * dist`, where `dist` is the 8-connected shortest-path distance to the
nearest goal. So the fast path computes `dist` directly with a compiled multi-source
Dijkstra and derives activations and the motor direction from it; `spread_iterative`
keeps the paper's rule, literally iterated, as the reference the tests compare against.

Movement rules shared by every function here (and by the tests' scipy reference):
orthogonal steps cost 1, diagonal steps sqrt(2); obstacle cells are never entered and
never radiate; a diagonal step from (r, c) to (r+dr, c+dc) needs both (r+dr, c) and
(r, c+dc) free, because an agent of radius 0.3 cannot squeeze between two discs that
touch diagonally. A goal cell that is also an obstacle is an obstacle. Arrays are
indexed [row, col].

API: `distance_field`, `seeded_distance_field`, `reachable`, `activation`, `gradient_step`,
`spread_iterative`, and `readonly` (the kernels' inputs, kept at one compiled signature).
Pure numpy and numba: no bus, no world.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

SQRT2 = math.sqrt(2.0)

# The 8 moves in the fixed tie-break order of `gradient_step`: orthogonal first (N, E,
# S, W with N = row - 1), then diagonal (NE, SE, SW, NW). The kernel uses the same table.
_DR = np.array([-1, 0, 1, 0, -1, 1, 1, -1], np.int64)
_DC = np.array([0, 1, 0, -1, 1, 1, -1, -1], np.int64)
_STEP = np.array([1.0, 1.0, 1.0, 1.0, SQRT2, SQRT2, SQRT2, SQRT2])
MOVES: tuple[tuple[int, int], ...] = tuple(zip(_DR.tolist(), _DC.tolist()))

# Two neighbours whose costs differ by less than this lie on equally short paths; the
# difference is rounding in sums of 1s and sqrt(2)s (~1e-14 on a 100 x 100 grid).
_TIE = 1e-9


# --- the compiled kernel: multi-source Dijkstra with a bucket queue ------------------
#
# Every step costs at least 1, so when the search reaches the cells whose tentative
# distance lies in [k, k+1) they are all final: any shorter path would come through a
# cell below k, already settled and relaxed (Dinitz's refinement of Dial's buckets).
# No heap is needed and the cost is O(cells) on any map, open or maze (chamfer sweeps
# would need many passes on a maze). Steps cost at most sqrt(2) < 2, so only buckets
# k, k+1 and k+2 are ever live: a ring of 4 suffices.

# Cell states in the kernel's padded grid.
_OPEN, _DONE, _WALL = 0, 1, 2


@njit(cache=True, inline="always")
def _settle_bucket(k, head, node, nxt, state, dist, bucket_of, off, w, used, pending):
    """Settle every cell of bucket k and relax its neighbours; returns (used, pending)."""
    e = head[k & 3]
    head[k & 3] = -1
    while e != -1:
        u = node[e]
        e = nxt[e]
        pending -= 1
        if state[u] == _DONE:
            continue  # a stale entry: the cell moved down to an earlier bucket
        state[u] = _DONE
        du = dist[u]
        for j in range(8):
            v = u + off[j]
            if state[v] != _OPEN:
                continue
            # No corner cutting: both cells flanking a diagonal step must be free.
            if j >= 4 and (state[u + _DR[j] * w] == _WALL or state[u + _DC[j]] == _WALL):
                continue
            nd = du + _STEP[j]
            if nd < dist[v]:
                dist[v] = nd
                b = int(nd)
                if b != bucket_of[v]:
                    bucket_of[v] = b
                    node[used] = v
                    nxt[used] = head[b & 3]
                    head[b & 3] = used
                    used += 1
                    pending += 1
    return used, pending


class FieldWork:
    """The kernels' buffers for one map shape, kept between calls: a field then allocates
    only its result. The grids start clean (every cell unreached, the border a wall) and
    the kernels leave them clean, resetting only the cells they reached. One owner at a
    time (an agent's field cache): never share one between threads."""

    def __init__(self, shape: tuple[int, int]):
        n, m = shape
        size = (n + 2) * (m + 2)
        self.shape = (n, m)
        self.state = np.full(size, _WALL, np.uint8)   # the interior is written by each call
        self.dist = np.full(size, np.inf)
        self.bucket_of = np.full(size, -1, np.int32)
        # Up to two queue entries per cell from relaxations, and one per source of a seeded field.
        self.node = np.empty(3 * size, np.int32)
        self.nxt = np.empty(3 * size, np.int32)


@njit(cache=True)
def _fill_state(obstacles, state):
    """The padded grid's interior from `obstacles` (its one-cell wall border is never written)."""
    n, m = obstacles.shape
    w = m + 2
    # A bool is one byte of 0 or 1, and _OPEN, _WALL are 0, 2: a shift, not a branch per
    # cell, so the loop vectorises (4x faster at 121 x 121).
    ob = obstacles.view(np.uint8)
    for r in range(n):
        base = (r + 1) * w + 1
        for c in range(m):
            state[base + c] = ob[r, c] << 1


@njit(cache=True)
def _result_and_reset(n, m, dist, bucket_of, node, used):
    """The interior of `dist` as a new (n, m) array; then every queued cell (every cell
    reached) back to unreached, so the buffers are clean for the next call.

    Only queued cells were reached, so they alone are read: a field reaches a few hundred
    cells of a large map (the world it shows), and the rest of `dist` need not pass
    through the caches."""
    w = m + 2
    out = np.full((n, m), np.inf)
    for e in range(used):
        u = node[e]
        if bucket_of[u] != -1:   # a cell queued twice is read (and reset) once
            out[u // w - 1, u % w - 1] = dist[u]
            dist[u] = np.inf
            bucket_of[u] = -1
    return out


@njit(cache=True)
def _field_into(goals, obstacles, state, dist, bucket_of, node, nxt):
    """dist[N, M] to the nearest free goal (see the comment above for the method), in the
    clean buffers of a `FieldWork`."""
    n, m = goals.shape
    w = m + 2
    _fill_state(obstacles, state)
    # Buckets are linked lists in a shared pool. A cell is queued once per bucket it
    # enters: first k+1 or k+2 (from a cell of bucket k), later only lower, never below
    # k+1; so at most 2 entries per cell, and the pool cannot overflow.
    head = np.full(4, -1, np.int32)
    off = _DR * w + _DC
    used = 0
    for r in range(n):
        for c in range(m):
            u = (r + 1) * w + c + 1
            if goals[r, c] and state[u] == _OPEN:
                dist[u] = 0.0
                bucket_of[u] = 0
                node[used] = u
                nxt[used] = head[0]
                head[0] = used
                used += 1
    pending = used
    k = 0
    while pending > 0:
        used, pending = _settle_bucket(k, head, node, nxt, state, dist, bucket_of, off, w, used, pending)
        k += 1
    return _result_and_reset(n, m, dist, bucket_of, node, used)


@njit(cache=True)
def _seeded_into(seed, obstacles, state, dist, bucket_of, node, nxt):
    """dist[N, M] to the cheapest source, a source cell starting at its own cost `seed`
    (inf: not a source), in the clean buffers of a `FieldWork`. The same bucket queue as
    `_field_into`; sources enter their bucket only when the search reaches it, so the ring
    of four buckets still suffices."""
    n, m = seed.shape
    w = m + 2
    _fill_state(obstacles, state)
    head = np.full(4, -1, np.int32)
    off = _DR * w + _DC
    count = 0
    for r in range(n):
        for c in range(m):
            if seed[r, c] < np.inf and not obstacles[r, c]:
                count += 1
    src = np.empty(count, np.int64)
    src_d = np.empty(count)
    i = 0
    for r in range(n):
        for c in range(m):
            if seed[r, c] < np.inf and not obstacles[r, c]:
                src[i] = (r + 1) * w + c + 1
                src_d[i] = seed[r, c]
                i += 1
    order = np.argsort(src_d)
    si = 0
    used = 0
    pending = 0
    k = 0
    while pending > 0 or si < count:
        if pending == 0:
            k = max(k, int(src_d[order[si]]))
        while si < count and int(src_d[order[si]]) <= k:
            u = src[order[si]]
            d = src_d[order[si]]
            si += 1
            if d < dist[u] and state[u] == _OPEN:
                dist[u] = d
                bucket_of[u] = int(d)
                node[used] = u
                nxt[used] = head[int(d) & 3]
                head[int(d) & 3] = used
                used += 1
                pending += 1
        used, pending = _settle_bucket(k, head, node, nxt, state, dist, bucket_of, off, w, used, pending)
        k += 1
    return _result_and_reset(n, m, dist, bucket_of, node, used)


@njit(cache=True)
def _field_kernel(goals, obstacles):
    """`_field_into` with buffers of its own (for a caller that keeps none)."""
    n, m = goals.shape
    size = (n + 2) * (m + 2)
    state = np.full(size, _WALL, np.uint8)
    return _field_into(goals, obstacles, state, np.full(size, np.inf), np.full(size, -1, np.int32),
                       np.empty(3 * size, np.int32), np.empty(3 * size, np.int32))


@njit(cache=True)
def _reach_kernel(sources, passable):
    """Flood fill through 4-neighbours (see `reachable`); a stack of flat indices."""
    n, m = sources.shape
    out = np.zeros((n, m), np.bool_)
    stack = np.empty(n * m, np.int64)
    top = 0
    for r in range(n):
        for c in range(m):
            if sources[r, c] and passable[r, c]:
                out[r, c] = True
                stack[top] = r * m + c
                top += 1
    while top > 0:
        top -= 1
        u = stack[top]
        r, c = u // m, u % m
        for j in range(4):
            rr, cc = r + _DR[j], c + _DC[j]
            if 0 <= rr < n and 0 <= cc < m and passable[rr, cc] and not out[rr, cc]:
                out[rr, cc] = True
                stack[top] = rr * m + cc
                top += 1
    return out


# --- public API -----------------------------------------------------------------------


def readonly(grid: np.ndarray) -> np.ndarray:
    """`grid`, or a read-only view of it. numba compiles a kernel once per signature, and
    a writable array is another type than a read-only one: inputs passed read-only always
    keep a kernel at one signature (each one more is about a second of compiling in every
    fresh checkout, test worker and process)."""
    if not grid.flags.writeable:
        return grid
    view = grid.view()
    view.flags.writeable = False
    return view


def _bool_grids(goals, obstacles) -> tuple[np.ndarray, np.ndarray]:
    # C-contiguous, read-only bool arrays keep the kernel at one compiled signature.
    goals = np.ascontiguousarray(goals, dtype=np.bool_)
    obstacles = np.ascontiguousarray(obstacles, dtype=np.bool_)
    if goals.ndim != 2 or goals.shape != obstacles.shape:
        raise ValueError(f"goals {goals.shape} and obstacles {obstacles.shape} must be equal 2-D shapes")
    return readonly(goals), readonly(obstacles)


def distance_field(goals: np.ndarray, obstacles: np.ndarray, work: FieldWork | None = None) -> np.ndarray:
    """8-connected shortest-path distance (float64, [row, col]) from every cell to its
    nearest goal; np.inf on obstacles and on cells that cannot reach a goal. `work`: kept
    buffers of this shape (`FieldWork`), to allocate only the result."""
    goals, obstacles = _bool_grids(goals, obstacles)
    if work is None or work.shape != goals.shape:
        return _field_kernel(goals, obstacles)
    return _field_into(goals, obstacles, work.state, work.dist, work.bucket_of, work.node, work.nxt)


def reachable(sources: np.ndarray, passable: np.ndarray) -> np.ndarray:
    """The cells from which a goal in `sources` can be reached through `passable` cells:
    exactly `np.isfinite(distance_field(sources, ~passable))`, without the distances.

    A diagonal step needs both flanking cells free, so it can always be made as two
    orthogonal steps: reachability is 4-connectivity, a flood fill (no bucket queue)."""
    sources, passable = _bool_grids(sources, passable)
    return _reach_kernel(sources, passable)


def seeded_distance_field(seed: np.ndarray, obstacles: np.ndarray, work: FieldWork | None = None) -> np.ndarray:
    """Like `distance_field`, but every cell with a finite `seed` is a goal that starts at
    that cost instead of 0: the distance from each cell to min over goals g of
    (path to g + seed[g]). A goal beyond the map enters at the border this way, carrying
    the distance that remains (the activation spreads in from outside, Eq. 2 unchanged)."""
    seed = np.ascontiguousarray(seed, dtype=np.float64)
    _, obstacles = _bool_grids(np.zeros(seed.shape, bool), obstacles)
    if seed.shape != obstacles.shape:
        raise ValueError(f"seed {seed.shape} and obstacles {obstacles.shape} must be equal 2-D shapes")
    if np.any(seed < 0) or np.any(np.isnan(seed)):
        raise ValueError("seed costs must be >= 0 (inf: not a goal)")
    if work is None or work.shape != seed.shape:
        work = FieldWork(seed.shape)
    return _seeded_into(seed, obstacles, work.state, work.dist, work.bucket_of, work.node, work.nxt)


def _default_decay(dist: np.ndarray) -> float:
    """1 / (2 max(N, M)): an open map's longest path is under 1.5 max(N, M), so every
    reachable cell stays at 1/4 or more. A winding maze can be far longer; then the
    decay shrinks to fit its longest path, keeping reachable cells positive (at >= 1/2)
    and thus distinct from unreachable ones (0)."""
    decay = 1.0 / (2 * max(dist.shape))
    finite = dist[np.isfinite(dist)]
    longest = float(finite.max()) if finite.size else 0.0
    if decay * longest >= 1.0:
        decay = 1.0 / (2 * longest)
    return decay


def activation(dist: np.ndarray, decay: float | None = None, *,
               obstacles: np.ndarray | None = None) -> np.ndarray:
    """Eq. 1-2 at their fixed point: goals 1, reachable cells 1 - decay * dist (floored
    at 0 as Eq. 2 requires a >= 0), unreachable 0, obstacles -1.

    `dist` alone cannot tell an obstacle from an unreachable free cell (both are inf),
    so pass `obstacles` to get their -1; without it every inf cell reads 0.
    """
    dist = np.asarray(dist, dtype=np.float64)
    if decay is None:
        decay = _default_decay(dist)
    if decay < 0:
        raise ValueError(f"decay must be >= 0, got {decay}")
    # Eq. 2 read literally lets obstacles take part in the max: an obstacle beside a goal
    # then rises to 1 - d and radiates through itself, and in a pocket cut off from every
    # goal the obstacles' -1 spreads as -1 - k*d, so the cells beside obstacles become
    # false maxima that pull the agent into them. Obstacles are therefore held at -1 and
    # excluded from every max (here: they are inf in `dist`, never a path).
    act = np.zeros(dist.shape)
    reach = np.isfinite(dist)
    act[reach] = np.maximum(0.0, 1.0 - decay * dist[reach])
    if obstacles is not None:
        act[np.asarray(obstacles, dtype=np.bool_)] = -1.0
    return act


def gradient_step(dist: np.ndarray, centre: tuple[int, int] | None = None) -> tuple[int, int] | None:
    """The move (drow, dcol) of steepest ascent of activation at `centre` (default the
    map's centre (N//2, M//2)): the neighbour minimising step length + dist. Ties go to
    orthogonal moves, then the order N, E, S, W, NE, SE, SW, NW. (0, 0) on a goal, None
    if no goal is reachable from `centre`.
    """
    dist = np.asarray(dist, dtype=np.float64)
    n, m = dist.shape
    r, c = (n // 2, m // 2) if centre is None else (int(centre[0]), int(centre[1]))
    if not (0 <= r < n and 0 <= c < m):
        raise ValueError(f"centre {(r, c)} outside a {n} x {m} map")
    here = float(dist[r, c])
    if not math.isfinite(here):
        return None
    if here == 0.0:
        return (0, 0)
    return MOVES[_gradient_kernel(readonly(dist), r, c)]


@njit(cache=True)
def _gradient_kernel(dist, r, c):
    """Index into MOVES of `gradient_step`'s move from a reachable, non-goal (r, c)."""
    n, m = dist.shape
    # From a reachable centre an orthogonal neighbour is inf only if it is an obstacle
    # (a free cell orthogonally beside a reachable one is reachable), so `dist` alone
    # carries the no-corner-cutting rule.
    costs = np.empty(8)
    for j in range(8):
        rr, cc = r + _DR[j], c + _DC[j]
        ok = 0 <= rr < n and 0 <= cc < m and math.isfinite(dist[rr, cc])
        if ok and j >= 4:
            ok = (0 <= rr < n and math.isfinite(dist[rr, c])) and (0 <= cc < m and math.isfinite(dist[r, cc]))
        costs[j] = _STEP[j] + dist[rr, cc] if ok else math.inf
    best = costs.min()
    # Two passes (minimum, then first within _TIE of it) so the tie-break is by order only.
    for j in range(8):
        if costs[j] <= best + _TIE:
            return j
    return 0  # cannot happen: the centre is reachable, so some neighbour is


# --- the paper's rule, literally iterated (test reference) ---------------------------


def _shift(a: np.ndarray, dr: int, dc: int, fill) -> np.ndarray:
    """out[r, c] = a[r + dr, c + dc], `fill` where that falls off the grid."""
    n, m = a.shape
    out = np.full(a.shape, fill, dtype=a.dtype)
    out[max(0, -dr):n - max(0, dr), max(0, -dc):m - max(0, dc)] = \
        a[max(0, dr):n - max(0, -dr), max(0, dc):m - max(0, -dc)]
    return out


def _move_masks(free: np.ndarray) -> list[np.ndarray]:
    """Per move, where a free cell may take activation from that neighbour: the neighbour
    is free and, for a diagonal, so are both flanking cells (no corner cutting)."""
    masks = []
    for dr, dc in MOVES:
        ok = free & _shift(free, dr, dc, False)
        if dr and dc:
            ok &= _shift(free, dr, 0, False) & _shift(free, 0, dc, False)
        masks.append(ok)
    return masks


def spread_iterative(goals: np.ndarray, obstacles: np.ndarray, decay: float) -> np.ndarray:
    """Eq. 1, then Eq. 2 applied to the whole grid at once until nothing changes.

    a(0) = 1 on goals, -1 on obstacles, 0 elsewhere; then every free non-goal cell takes
    max(0, max over its passable neighbours m of a_m - decay * |step|). Goals stay 1 and
    obstacles stay -1 and are excluded from the max (see `activation` for why). Starting
    from 0 the values only rise, so the loop ends; it needs about as many rounds as the
    longest path has steps, which is why the agent uses `distance_field` instead.
    """
    goals, obstacles = _bool_grids(goals, obstacles)
    free = ~obstacles
    source = goals & free
    masks = _move_masks(free)
    a = np.where(source, 1.0, np.where(obstacles, -1.0, 0.0))
    for _ in range(a.size + 1):
        best = np.zeros(a.shape)  # the a >= 0 floor of Eq. 2
        for (dr, dc), step, ok in zip(MOVES, _STEP.tolist(), masks):
            cand = np.where(ok, _shift(a, dr, dc, -np.inf) - decay * step, -np.inf)
            np.maximum(best, cand, out=best)
        new = np.where(source, 1.0, np.where(obstacles, -1.0, best))
        if np.array_equal(new, a):
            return new
        a = new
    raise RuntimeError("spreading activation did not settle")  # cannot happen: values only rise

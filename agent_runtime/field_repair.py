"""A distance field after a few cells changed, worked out from the field before (issue 31).

Most distance fields an agent computes again differ from the one its slot had a step
before by a couple of cells: another agent crossed into the next cell (agents are
obstacles on the navigation maps), or a goal came or went. Such a change moves the
values of a few percent of the cells (median 0.7-2.5% on the layouts of
`bench.bench_agent_step`), so the field is repaired where it changed, not computed again.

The field is the unique fixed point of d = 0 on free goals, inf on obstacles, and
d[v] = min over the moves u -> v of (d[u] + step) elsewhere (`spreading`'s movement rules:
no corner cutting), each sum rounded as the kernel rounds it. A repair reaches that fixed
point from the old one, bit for bit:

1. Invalidate. A cell whose old value no longer has a witness, a move from a cell still
   valid with d[u] + step == d[v] exactly, is set to inf (it may have to grow). Only the
   changed cells and their neighbours lose moves, and a witness always has the smaller
   value, so candidates are judged in order of their old value, starting there, and the
   neighbours of every cell invalidated become candidates too. A valid value is never
   below the new field's (a witness chain leads down to a goal).
2. Relax. The changed cells, their neighbours and the invalidated cells take the best of
   their moves from the values now held (0 on a goal), and a Dijkstra from them, in
   order of value, carries every decrease on. Afterwards no move can lower a value, and
   every value is that of a path: the fixed point.

When the agent has crossed into the next cell its maps' contents moved by a row or a
column: the old field is moved with them first (`repair_from_bytes`'s `moved`).

`tests/test_field_repair.py` holds repairs to fresh fields, bit for bit, through chains of
random changes. Pure numpy and numba: no bus.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from agent_runtime.spreading import _DC, _DR, _STEP, readonly

# Repaired only when at most this many cells changed, and given up once it has queued
# MAX_QUEUED cells: a repair costs about what it touches, a heap's step dearer than the
# kernel's bucket queue, and a change that moves much of the field (a goal gone, a way
# opened) is computed again (the kernel's cost). Most repairs queue a few dozen cells;
# on 001-gen-nested_rings at 41 x 41 the step's median was 3% cheaper with a budget of
# 320 than with 96, 1% dearer with 48, and no cheaper with 1,000.
MAX_CHANGED = 24
MAX_QUEUED = 320

_QUEUED, _SEEDED = 1, 2   # a cell's flags: queued in step 1, started from in step 2


def repair_distance_field(field: np.ndarray, goals_before: np.ndarray, obstacles_before: np.ndarray,
                          goals: np.ndarray, obstacles: np.ndarray) -> np.ndarray | None:
    """`spreading.distance_field(goals, obstacles)`, from `field`, the distance field of
    `goals_before` and `obstacles_before`; None when more than MAX_CHANGED cells differ or
    the repair would queue more than MAX_QUEUED (compute it afresh). The grids are bool,
    of `field`'s 2-D shape."""
    def packed(g, o):
        return np.frombuffer(np.ascontiguousarray(g, np.bool_).tobytes() + np.ascontiguousarray(o, np.bool_).tobytes(),
                             np.uint8)
    return repair_from_bytes(field, packed(goals_before, obstacles_before), packed(goals, obstacles), 0)


def repair_from_bytes(field: np.ndarray, before: np.ndarray, after: np.ndarray, offset: int,
                      moved: tuple[int, int] = (0, 0)) -> np.ndarray | None:
    """`repair_distance_field` with the grids as bytes (uint8): from `offset` on, the goals'
    bytes then the obstacles' (as `FieldCache` keys them), in `before` and in `after`,
    which are alike up to `offset`.

    `moved`: (rows, cols) by which the map's contents moved since `before` (the agent
    crossed into another cell; `esm` shifts the maps). Cell (r, c) before is then cell
    (r + rows, c + cols) now, and the cells that come onto the map were not there: it is
    repaired only when every cell that left the map was an obstacle (as beyond the
    world's edge), so that no way led through them, and the newcomers count as changed."""
    # read-only, as FieldCache keeps its fields: one compiled signature whoever calls
    done, out = _repair_kernel(readonly(field), before, after, offset, MAX_CHANGED, MAX_QUEUED, moved[0], moved[1])
    return out if done else None


@njit(cache=True, inline="always")
def _free(obstacles, r, c):
    n, m = obstacles.shape
    return 0 <= r < n and 0 <= c < m and not obstacles[r, c]


@njit(cache=True, inline="always")
def _move_allowed(obstacles, r, c, j):
    """Whether move j joins the free cell (r, c) to a free neighbour: both ways alike."""
    rr, cc = r + _DR[j], c + _DC[j]
    if not _free(obstacles, rr, cc):
        return False
    return j < 4 or (_free(obstacles, rr, c) and _free(obstacles, r, cc))


@njit(cache=True)
def _changed_cells(before, after, offset, cells, limit):
    """The cells whose goal or obstacle byte differs (sorted flat indices), and whether
    they are at most `limit`. Compared 8 bytes at a time: most words are alike."""
    n8 = before.size // 8
    wb, wa = before[:n8 * 8].view(np.uint64), after[:n8 * 8].view(np.uint64)
    found = np.empty(2 * limit, np.int64)
    k = 0
    for w in range(n8 + 1):
        if w < n8 and wb[w] == wa[w]:
            continue
        for b in range(w * 8, min(w * 8 + 8, before.size)):
            if before[b] != after[b]:
                if k == 2 * limit:
                    return found[:0], False
                found[k] = b - offset
                k += 1
    # Byte order is the goals' cells in order, then the obstacles' (cells + b): merge the
    # two sorted runs, a cell in both once.
    split = 0
    while split < k and found[split] < cells:
        split += 1
    changed = np.empty(k, np.int64)
    i, j, n = 0, split, 0
    while i < split or j < k:
        if j == k or (i < split and found[i] < found[j] - cells):
            cell = found[i]
            i += 1
        elif i == split or found[j] - cells < found[i]:
            cell = found[j] - cells
            j += 1
        else:   # the same cell in both runs
            cell = found[i]
            i += 1
            j += 1
        changed[n] = cell
        n += 1
    return changed[:n], n <= limit


@njit(cache=True)
def _moved(field, goals_before, obstacles_before, goals, obstacles, dr, dc, limit):
    """For a map whose contents moved by (dr, dc): whether it can be repaired (every cell
    that left the map was an obstacle, at most `limit` cells differ), the cells that
    differ (those come onto the map count as obstacles before), and the old field moved
    (inf where nothing was)."""
    n, m = field.shape
    # The cells that left: the rows past the edge the contents moved towards, then the
    # columns (a corner cell is looked at twice).
    for r in range(n - dr, n) if dr > 0 else range(-dr):
        for c in range(m):
            if not obstacles_before[r, c]:
                return False, np.empty(0, np.int64), np.empty((0, 0))
    for c in range(m - dc, m) if dc > 0 else range(-dc):
        for r in range(n):
            if not obstacles_before[r, c]:
                return False, np.empty(0, np.int64), np.empty((0, 0))
    d = np.full((n, m), np.inf)
    changed = np.empty(limit + 1, np.int64)
    k = 0
    for r in range(n):
        for c in range(m):
            rb, cb = r - dr, c - dc
            inside = 0 <= rb < n and 0 <= cb < m
            if inside:
                d[r, c] = field[rb, cb]
            was_goal = inside and goals_before[rb, cb]
            was_obstacle = not inside or obstacles_before[rb, cb]
            if was_goal != goals[r, c] or was_obstacle != obstacles[r, c]:
                if k == limit:
                    return False, changed[:0], d
                changed[k] = r * m + c
                k += 1
    return True, changed[:k], d


@njit(cache=True)
def _best_move_in(d, obstacles, r, c):
    """The least d[u] + step over the moves into the free cell (r, c) (inf: none)."""
    best = np.inf
    for j in range(8):
        if _move_allowed(obstacles, r, c, j):
            u = d[r + _DR[j], c + _DC[j]]
            if u < np.inf and u + _STEP[j] < best:
                best = u + _STEP[j]
    return best


@njit(cache=True)
def _has_witness(d, obstacles, r, c):
    """Whether the old value of the free cell (r, c) is d[u] + step of a move in."""
    for j in range(8):
        if _move_allowed(obstacles, r, c, j):
            u = d[r + _DR[j], c + _DC[j]]
            if u < np.inf and u + _STEP[j] == d[r, c]:
                return True
    return False


@njit(cache=True)
def _repair_kernel(field, before, after, offset, limit, budget, dr, dc):
    n, m = field.shape
    goals = after[offset:offset + n * m].reshape(n, m)
    obstacles = after[offset + n * m:offset + 2 * n * m].reshape(n, m)
    if dr == 0 and dc == 0:
        changed, few = _changed_cells(before, after, offset, n * m, limit)
        d = field.copy()
    else:
        few, changed, d = _moved(field, before[offset:offset + n * m].reshape(n, m),
                                 before[offset + n * m:offset + 2 * n * m].reshape(n, m), goals, obstacles, dr, dc,
                                 limit)
    if not few:
        return False, np.empty((0, 0))
    flags = np.zeros(n * m, np.uint8)
    # A binary heap of (value, cell) in two arrays: at most `budget` cells are queued
    # (then the repair is given up) plus what the changed cells start, in either step.
    cap = 2 * budget + 9 * changed.size + 32
    keys, cells = np.empty(cap), np.empty(cap, np.int64)
    size = 0
    invalid = np.empty(budget + 16, np.int64)
    n_invalid = 0
    # 1. invalidate, in order of old value
    for i in changed:
        r0, c0 = i // m, i % m
        for j in range(-1, 8):
            r, c = (r0, c0) if j < 0 else (r0 + _DR[j], c0 + _DC[j])
            v = r * m + c
            if 0 <= r < n and 0 <= c < m and d[r, c] < np.inf and not flags[v] & _QUEUED:
                flags[v] |= _QUEUED
                size = _push(keys, cells, size, d[r, c], v)
    queued = size
    while size:
        _, v = _pop(keys, cells, size)
        size -= 1
        r, c = v // m, v % m
        if obstacles[r, c]:
            valid = False
        elif goals[r, c]:
            valid = True    # 0 from now on, if it was not (step 2)
        else:
            valid = _has_witness(d, obstacles, r, c)
        if valid:
            continue
        d[r, c] = np.inf
        invalid[n_invalid] = v
        n_invalid += 1
        for j in range(8):
            rr, cc = r + _DR[j], c + _DC[j]
            u = rr * m + cc
            if 0 <= rr < n and 0 <= cc < m and d[rr, cc] < np.inf and not flags[u] & _QUEUED:
                flags[u] |= _QUEUED
                size = _push(keys, cells, size, d[rr, cc], u)
                queued += 1
        if queued > budget:
            return False, d
    # 2. relax from the changed cells, their neighbours and the invalidated cells
    for i in changed:
        r0, c0 = i // m, i % m
        for j in range(-1, 8):
            r, c = (r0, c0) if j < 0 else (r0 + _DR[j], c0 + _DC[j])
            if 0 <= r < n and 0 <= c < m:
                size = _seed(d, goals, obstacles, flags, keys, cells, size, r, c, m)
    for k in range(n_invalid):
        v = invalid[k]
        size = _seed(d, goals, obstacles, flags, keys, cells, size, v // m, v % m, m)
    queued += size
    while size:
        t, v = _pop(keys, cells, size)
        size -= 1
        r, c = v // m, v % m
        if t != d[r, c]:
            continue   # lowered since it was queued
        for j in range(8):
            if _move_allowed(obstacles, r, c, j):
                rr, cc = r + _DR[j], c + _DC[j]
                nd = t + _STEP[j]
                if nd < d[rr, cc]:
                    d[rr, cc] = nd
                    size = _push(keys, cells, size, nd, rr * m + cc)
                    queued += 1
        if queued > budget:
            return False, d
    return True, d


@njit(cache=True)
def _seed(d, goals, obstacles, flags, keys, cells, size, r, c, m):
    """Step 2's start at the cell (r, c): the best of its moves in, once; the heap's size."""
    v = r * m + c
    if flags[v] & _SEEDED or obstacles[r, c]:
        return size
    flags[v] |= _SEEDED
    t = 0.0 if goals[r, c] else _best_move_in(d, obstacles, r, c)
    if t < d[r, c]:
        d[r, c] = t
        size = _push(keys, cells, size, t, v)
    return size


@njit(cache=True, inline="always")
def _push(keys, cells, size, key, cell):
    """Add (key, cell) to the binary heap of `size` entries; returns the new size."""
    i = size
    while i > 0:
        parent = (i - 1) >> 1
        if keys[parent] <= key:
            break
        keys[i], cells[i] = keys[parent], cells[parent]
        i = parent
    keys[i], cells[i] = key, cell
    return size + 1


@njit(cache=True, inline="always")
def _pop(keys, cells, size):
    """The least (key, cell) of the binary heap of `size` entries, taken out (the heap
    then holds size - 1)."""
    top_key, top_cell = keys[0], cells[0]
    size -= 1
    key, cell = keys[size], cells[size]
    i = 0
    while True:
        child = 2 * i + 1
        if child >= size:
            break
        if child + 1 < size and keys[child + 1] < keys[child]:
            child += 1
        if keys[child] >= key:
            break
        keys[i], cells[i] = keys[child], cells[child]
        i = child
    keys[i], cells[i] = key, cell
    return top_key, top_cell

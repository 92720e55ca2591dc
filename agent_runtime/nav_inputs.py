"""The navigation maps' inputs, made from the ESMs' marks in one compiled pass.

`step_marks` makes the marks themselves (the ESMs thresholded at 0.5), with the two
updates of the maps that come just before them and the two masks the enclosed-sites
check reads, in one pass as well.

Every step the configuration and brick NMs (paper §4.2.3, Fig. 5) and the Matching grid
(§6) read the same few masks of the thresholded ESMs: the sites still missing a brick, the
free bricks, what is in the way, the supply, the sites not seen open lately. As numpy
expressions that is some twenty whole-grid operations, each a Python call and a new
array, around a few microseconds of actual work; one pass over the grid makes them all.
The masks are exactly the expressions' (boolean algebra, nothing rounded), so no
decision changes.

Pure functions over numpy arrays; the brain owns when they are asked for.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from numba import njit

from agent_runtime.esm import AGENT, BRICK, CONFIG, FOOD, OBSTACLE, WATER
from agent_runtime.spreading import readonly


class NavInputs(NamedTuple):
    """The masks one step's navigation maps are made from (bool grids of the map's shape)."""

    config_goals: np.ndarray   # sites still missing a brick (CONFIG and not BRICK)
    brick_goals: np.ndarray    # bricks not part of the structure (BRICK and not CONFIG)
    obstacles: np.ndarray      # food, walls, recalled discs, water and structure bricks
    supply_bricks: np.ndarray  # free bricks, and the extra supply where nothing is in the way
    closed: np.ndarray         # open sites not seen open for `site_memory` steps, off the agent's 3 x 3
    in_the_way: np.ndarray     # food, walls, recalled discs, water (and other agents, if they count)
    any_open: bool             # whether any site on the map is missing a brick


def nav_inputs(marks: np.ndarray, recalled: np.ndarray, extra_supply: np.ndarray, clear_age: np.ndarray,
               site_memory: float, agents_block: bool, closed_sites: bool, centre: int,
               previous: NavInputs | None = None) -> NavInputs:
    """The masks of `NavInputs` from `marks` (the ESMs > 0.5, one bool grid per layer),
    `recalled` (food and water remembered beyond the map, back on it), `extra_supply`
    (the held brick's source and the far bricks at the border), the ESMs' `clear_age`;
    `agents_block`: other agents are in the way; `closed_sites`: sites not seen open lately
    are closed (else none is); `centre`: the agent's cell, (centre, centre).

    `previous`: the inputs of the step before. When every mask is as it was, `previous`
    itself comes back (the same object), so the stages made from it can tell by identity
    that their inputs did not change (most steps, on layouts where others seldom pass);
    and each mask that is as it was is `previous`'s own (others moving on the map change
    `in_the_way` alone, and what the matching reads is then the same objects)."""
    masks, any_open = _inputs_kernel(readonly(marks), recalled, readonly(extra_supply), clear_age, float(site_memory),
                                     agents_block, closed_sites, centre)
    masks.setflags(write=False)   # shared by every reader of the step (and its views are read-only too)
    if previous is None or previous.config_goals.shape != marks.shape[1:]:
        return NavInputs(*_six(masks), bool(any_open))
    same = _same_masks(masks, *previous[:6])   # read-only already (views of an earlier step's masks)
    if all(same):
        return previous
    return NavInputs(*_six([old if kept else new for old, new, kept in zip(previous[:6], masks, same)]),
                     bool(any_open))


def _six(masks) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The six masks of `NavInputs`, in order, as a typed tuple."""
    a, b, c, d, e, f = masks
    return a, b, c, d, e, f


class StepMarks(NamedTuple):
    """The maps as marks for one step, and the masks the enclosed-sites check reads."""

    marks: np.ndarray        # the ESMs > 0.5, one bool grid per layer (`Brain.layers`)
    open_sites: np.ndarray   # CONFIG and not BRICK
    walls: np.ndarray        # OBSTACLE, FOOD, WATER, and bricks on sites


# Read-only, as the grids they stand for are (`spreading.readonly` says why).
_NOWHERE = np.zeros((1, 1), np.bool_)
_NO_MARKS = np.zeros((1, 1, 1), np.bool_)
_NOWHERE.flags.writeable = False
_NO_MARKS.flags.writeable = False


def step_marks(maps: np.ndarray, outside: np.ndarray | None, recalled: np.ndarray, known: np.ndarray,
               previous: np.ndarray | None = None) -> StepMarks:
    """After sensing: mark the cells beyond the world's edge (`outside`, None when its
    extent is unknown) as fixed obstacles in `maps`, forget the `recalled` discs on cells
    seen free since (`known`; both in place), then threshold the maps.

    `previous`: the marks of the step before. Most steps nothing crosses 0.5, and then
    `previous` itself is the marks: the same object, so what was worked out from it can
    be known unchanged by identity (it is read-only; a caller that must add to it copies)."""
    has_outside = outside is not None
    same_shape = previous is not None and previous.shape == maps.shape
    edge = readonly(outside) if outside is not None else _NOWHERE
    last = readonly(previous) if previous is not None and same_shape else _NO_MARKS
    marks, open_sites, walls, same = _marks_kernel(maps, edge, has_outside, recalled, known, last, same_shape)
    return StepMarks(previous if same and previous is not None else marks, open_sites, walls)


def nm_obstacles(in_the_way: np.ndarray, bricks: np.ndarray, brick_goals: np.ndarray,
                 centre: int) -> tuple[np.ndarray, np.ndarray]:
    """The obstacles of the configuration NM (what is in the way, and every brick) and of
    the brick NM (what is in the way, and the bricks that are not goals), each with the
    agent's own cell free: it may stand on a brick it just dropped and must plan a way out."""
    return _obstacles_kernel(readonly(in_the_way), readonly(bricks), readonly(brick_goals), centre)


@njit(cache=True)
def _inputs_kernel(marks, recalled, extra_supply, clear_age, site_memory, agents_block, closed_sites, centre):
    """The six masks as one (6, n, m) array, and whether any site is open."""
    # Bitwise operators on bools, not `and`/`or`: no branch per cell, so the loop vectorises.
    n, m = recalled.shape
    out = np.empty((6, n, m), np.bool_)
    config_goals, brick_goals, obstacles, supply, closed, in_the_way = out[0], out[1], out[2], out[3], out[4], out[5]
    any_open = False
    for r in range(n):
        for c in range(m):
            brick, config = marks[BRICK, r, c], marks[CONFIG, r, c]
            fixed = marks[FOOD, r, c] | marks[OBSTACLE, r, c] | recalled[r, c] | marks[WATER, r, c]
            site = config & (brick ^ True)
            free = brick & (config ^ True)
            blocked = fixed | (brick & config)
            config_goals[r, c] = site
            brick_goals[r, c] = free
            obstacles[r, c] = blocked
            supply[r, c] = free | (extra_supply[r, c] & ((blocked | config) ^ True))
            closed[r, c] = closed_sites & site & (clear_age[r, c] > site_memory)
            in_the_way[r, c] = fixed | (agents_block & marks[AGENT, r, c])
            any_open |= site
    # The cells around the agent are never in doubt: it would be touching a brick there.
    closed[max(centre - 1, 0):centre + 2, max(centre - 1, 0):centre + 2] = False
    _enter_where_free(extra_supply, obstacles, config_goals, supply)
    return out, any_open


@njit(cache=True)
def _enter_where_free(extra_supply, obstacles, sites, supply):
    """A supply beyond the map enters it at the border cell nearest it (`extra_supply`);
    where that cell is in the way (a wall, a disc) or a site, it enters at the nearest
    border cell that is neither, into `supply`. Dropped there, it was lost: an agent a
    cell off the line that puts it on a disc protected no path and filled a slot's mouth
    first, a cell farther on it protected the slot again, and it turned back there for
    ever (unseen gen-multi 11270001)."""
    n, m = obstacles.shape
    ring = 2 * (n + m) - 4 if n > 1 and m > 1 else n * m   # (a grid one cell thin is all border)
    for i in range(ring):
        r, c = _border_cell(i, n, m)
        if not extra_supply[r, c] or not (obstacles[r, c] | sites[r, c]):
            continue
        best, br, bc = n + m, -1, -1
        for j in range(ring):
            rr, cc = _border_cell(j, n, m)
            if not (obstacles[rr, cc] | sites[rr, cc]):
                d = max(abs(rr - r), abs(cc - c))
                if d < best:
                    best, br, bc = d, rr, cc
        if br >= 0:
            supply[br, bc] = True


@njit(cache=True, inline="always")
def _border_cell(i, n, m):
    """The i-th cell of an n x m grid's border: the top row, the bottom row, then the
    left and right columns between them (a grid one cell thin: every cell in turn)."""
    if n < 2 or m < 2:
        return i // m, i % m
    if i < m:
        return 0, i
    i -= m
    if i < m:
        return n - 1, i
    i -= m
    return 1 + i // 2, (0 if i % 2 == 0 else m - 1)


@njit(cache=True)
def _same_masks(masks, a, b, c, d, e, f):
    """Per mask of the (6, n, m) `masks`: whether it equals the previous one (a to f)."""
    return (_equal(masks[0], a), _equal(masks[1], b), _equal(masks[2], c), _equal(masks[3], d),
            _equal(masks[4], e), _equal(masks[5], f))


@njit(cache=True)
def _equal(a, b):
    """Whether two bool arrays of one shape hold the same values."""
    fa, fb = a.reshape(-1), b.reshape(-1)
    differ = False
    for k in range(fa.size):   # no early exit: a reduction the compiler vectorises (25x faster)
        differ |= fa[k] != fb[k]
    return not differ


@njit(cache=True)
def _marks_kernel(maps, outside, has_outside, recalled, known, previous, compare):
    layers, n, m = maps.shape
    for r in range(n):
        for c in range(m):
            if has_outside and outside[r, c]:
                maps[OBSTACLE, r, c] = 1.0
            recalled[r, c] = recalled[r, c] & (known[r, c] ^ True)
    marks = np.empty((layers, n, m), np.bool_)
    for layer in range(layers):
        for r in range(n):
            for c in range(m):
                marks[layer, r, c] = maps[layer, r, c] > 0.5
    open_sites = np.empty((n, m), np.bool_)
    walls = np.empty((n, m), np.bool_)
    for r in range(n):
        for c in range(m):
            brick, config = marks[BRICK, r, c], marks[CONFIG, r, c]
            open_sites[r, c] = config & (brick ^ True)
            walls[r, c] = marks[OBSTACLE, r, c] | marks[FOOD, r, c] | marks[WATER, r, c] | (brick & config)
    return marks, open_sites, walls, compare and _equal(marks, previous)


@njit(cache=True)
def _obstacles_kernel(in_the_way, bricks, brick_goals, centre):
    n, m = bricks.shape
    config = np.empty((n, m), np.bool_)
    brick = np.empty((n, m), np.bool_)
    for r in range(n):
        for c in range(m):
            config[r, c] = in_the_way[r, c] | bricks[r, c]
            brick[r, c] = in_the_way[r, c] | (bricks[r, c] & (brick_goals[r, c] ^ True))
    config[centre, centre] = False
    brick[centre, centre] = False
    return config, brick

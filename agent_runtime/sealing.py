"""Sealing: which sites must wait because their brick would cut another open site off.

Goal sequencing (paper §6) plans on the maps, where a cell never seen counts as empty.
Inside a corridor whose walls no sensor has seen past the nearest disc, every deep site
then seems to have a way out sideways; the mouth is filled and the rest sealed. The check
here is stricter: only ground seen free and open sites are passable, and a site near the
agent whose brick disconnects another open site from the outside (the brick supply and
open ground seen away from the agent) is no goal until that site is filled.

The grids are plain boolean arrays of any shape: the agent's map, or the whole world as
its far memory holds it (a corridor longer than the map is judged on what the agent
remembers beyond the map's border, not on the map alone). Also here: open sites that no
way reaches at all (`enclosed_sites`) and the structure bricks that wall a site in
(`walling_in`), and the pocket a brick just dropped would shut an agent into
(`pocket_beside`). Numpy and the spreading module's distance kernel, no bus.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numba import njit

from agent_runtime.spreading import reachable

SEAL_RADIUS = 2     # goal sites within this many cells (on each axis) of the agent are checked
SEAL_MEMORY = 300   # ticks a site found sealing stays no goal once the agent is farther off
MARGIN = 3          # open ground this many cells beyond the checked square counts as outside
# An open site seen empty within this many steps is a way through; one not seen that long
# may have been filled meanwhile by another agent (or before a restart), so it is not.
FRESH_SITE = 30


def around(centre: tuple[int, int], radius: int, shape: tuple[int, ...]) -> np.ndarray:
    """Mask of the square of `radius` cells on each side of `centre` (clipped to the grid)."""
    out = np.zeros(shape, bool)
    i, j = centre
    out[max(i - radius, 0):i + radius + 1, max(j - radius, 0):j + radius + 1] = True
    return out


def cut_off(candidates: np.ndarray, passable: np.ndarray, reference: np.ndarray,
            open_sites: np.ndarray, fallbacks: Sequence[np.ndarray] = ()) -> np.ndarray:
    """The `candidates` (sites) whose filling would disconnect another open site from
    `reference` through `passable` cells; one distance field per candidate.

    A candidate that `passable` does not connect to `reference` at all is judged again on
    each of `fallbacks` in turn, each counting more cells passable (open sites not seen
    lately; every cell not known to be blocked). Why: a site that cannot be shown joined
    to the outside gets no verdict at all, and no verdict is no proof of safety. The
    strict view misses ways that are real but not proven: ground beside a wall or the
    world's edge is seldom seen free (the wall's readings hide it), and an exit out of
    sight behind the agent for a while is stale. Judged on nothing, a site is filled from
    inside with the rest of its corridor open behind it (as in gen-pocket 117, where two
    agents were shut in by the world's edge, and gen-pocket 031). A candidate the strict
    view connects is judged there, so the fallbacks can only find more sites unsafe,
    never fewer."""
    unsafe = np.zeros_like(candidates)
    rest = candidates
    for tier in (passable, *fallbacks):
        if not rest.any():
            break
        reachable = connected(reference, tier)
        for i, j in zip(*np.nonzero(rest & reachable)):
            unsafe[i, j] = _cuts(i, j, tier, reference, open_sites & _reached(reachable))
        rest = rest & ~reachable
    return unsafe


def _cuts(i: int, j: int, passable: np.ndarray, reference: np.ndarray, reachable_sites: np.ndarray) -> bool:
    """Does a brick on (i, j) disconnect one of `reachable_sites` (other than itself) from `reference`?"""
    way = passable.copy()
    way[i, j] = False
    cut = reachable_sites & ~_reached(reachable(reference, way))
    cut[i, j] = False
    return bool(cut.any())


def _reached(reachable: np.ndarray) -> np.ndarray:
    """The cells a brick can be put on from `reachable` ones: those and their 4 neighbours.
    A site that is not passable itself (believed open, not seen lately) is still reached
    when an agent can stand beside it."""
    return _reached_kernel(np.ascontiguousarray(reachable, dtype=np.bool_))


@njit(cache=True)
def _reached_kernel(reachable):
    n, m = reachable.shape
    out = reachable.copy()
    for r in range(n):
        for c in range(m):
            if reachable[r, c]:
                if r > 0:
                    out[r - 1, c] = True
                if r < n - 1:
                    out[r + 1, c] = True
                if c > 0:
                    out[r, c - 1] = True
                if c < m - 1:
                    out[r, c + 1] = True
    return out


def connected(reference: np.ndarray, passable: np.ndarray) -> np.ndarray:
    """The cells that reach `reference` through `passable` cells."""
    return reachable(reference, passable)


def walling_in(enclosed: np.ndarray, structure: np.ndarray, local: np.ndarray) -> np.ndarray:
    """Structure bricks beside an `enclosed` open site, within the `local` mask.

    An open site walled in by structure bricks near the agent is a contradiction: one of
    them is likely a ghost (or the site a stale belief). Counted passable, the way the
    site would have is not filled over before the agent has seen it."""
    beside = np.zeros_like(enclosed)
    beside[1:, :] |= enclosed[:-1, :]
    beside[:-1, :] |= enclosed[1:, :]
    beside[:, 1:] |= enclosed[:, :-1]
    beside[:, :-1] |= enclosed[:, 1:]
    return beside & structure & local


def enclosed_sites(open_sites: np.ndarray, walls: np.ndarray, centre: tuple[int, int]) -> np.ndarray:
    """Open sites that no way reaches, from `centre` (the agent's cell) or from the grid's
    border (the world goes on beyond a map), round `walls`.

    Why: a site nobody can reach cannot be filled, so believing it filled loses nothing,
    while believing it open keeps a loaded agent holding its brick for a site it can
    never reach. The sensors cannot show such a site filled when its brick hides behind
    another (deep in a one-cell slot, the brick in front hides it), so the map keeps it
    open, walled in (three loaded agents wandered for it for 6,000 ticks in gen-pocket
    153). The sensors open it again if they see it empty."""
    if not open_sites.any():
        return np.zeros_like(open_sites)
    # No layout puts a wall, food or water on a drop site (nor does the world add a disc
    # there unless forced), so such a mark on an open site is a disc mapped a cell off:
    # counted, it would wall in the sites behind it.
    walls = walls & ~open_sites
    walls[centre] = False           # the agent's own cell: it may stand on a brick it dropped
    ways_in = border(walls)
    ways_in[centre] = True
    return open_sites & ~connected(ways_in, ~walls)


def pocket_beside(blocked: np.ndarray, cell: tuple[int, int]) -> np.ndarray:
    """Unblocked cells beside `cell` that no way joins to the rest of the world once `cell`
    is blocked too, with every cell joined to them: the pocket a brick on `cell` closes.
    The rest of the world is what reaches the grid's border; on a map that holds the whole
    world (its border all outside the world's edge, so blocked) it is the largest region
    beside `cell`: a guess that the outside is bigger than what one brick closes off (a
    ring's inside), which a ring holding most of its world would fool.

    Why: never shut oneself in. A dropped brick lets the agent that dropped it pass until
    the agent is off it, and then holds like any other, so the side the agent steps off
    to is the side it stays on, and cells that brick closes off are a prison (as the
    centre of nested_squares' inner ring was, 31 of 32 sites built, for an agent whose
    world was being killed and restored). Cells never seen count as unblocked: only a
    pocket walled in on the map is one."""
    walls = blocked.copy()
    walls[cell] = True
    free = ~walls
    beside = np.zeros_like(walls)
    beside[cell] = True
    beside = _reached(beside) & free
    outside = connected(border(walls), free)
    if not outside.any():
        outside = largest_region(beside, free)
    inside = free & ~outside
    return connected(beside & inside, inside)


def largest_region(starts: np.ndarray, passable: np.ndarray) -> np.ndarray:
    """The most cells any one of `starts` reaches through `passable` cells (none if no start);
    one distance field per region, not per start."""
    best, seen = np.zeros_like(passable), np.zeros_like(passable)
    for i, j in zip(*np.nonzero(starts)):
        if seen[i, j]:
            continue
        one = np.zeros_like(starts)
        one[i, j] = True
        region = connected(one, passable)
        seen |= region
        if np.count_nonzero(region) > np.count_nonzero(best):
            best = region
    return best


def border(like: np.ndarray) -> np.ndarray:
    """The grid's outermost cells: the world goes on beyond a map's border."""
    out = np.zeros_like(like)
    out[[0, -1], :] = out[:, [0, -1]] = True
    return out


def dilate(cells: np.ndarray, k: int = 1) -> np.ndarray:
    """`cells` and every cell within `k` cells of one on each axis (8-neighbours for k = 1)."""
    n, m = cells.shape
    padded = np.pad(cells, k)
    out = np.zeros_like(cells)
    for dr in range(-k, k + 1):
        for dc in range(-k, k + 1):
            out |= padded[k + dr:k + dr + n, k + dc:k + dc + m]
    return out

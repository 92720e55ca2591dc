"""The agent's guard against sealing: which goal sites near it must not be filled now.

Each step with goal sequencing on, the brain asks which of its goal sites would cut
another open site off if filled now (`judge`: the sealing module's pure judgements, on the
whole world as the agent's far memory holds it, or on its map alone while the world's
extent is unknown), and keeps each such verdict for SEAL_MEMORY ticks once the agent has
walked out of the check's reach (`remember`). It reads the agent's maps and far memory and
owns only those verdicts. Numpy and a small numba kernel, no bus.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numba import njit

from agent_runtime.esm import AGENT, BRICK, CONFIG, EgocentricMaps
from agent_runtime.far_memory import FarMemory
from agent_runtime.sealing import (
    FRESH_SITE,
    MARGIN,
    SEAL_MEMORY,
    SEAL_RADIUS,
    around,
    connected,
    cut_off,
    walling_in,
)
from agent_runtime.spreading import readonly


class SealGuard:
    """The sites an agent must not fill now, and the ones it found sealing lately."""

    def __init__(self, maps: EgocentricMaps, far: FarMemory, centre: int):
        self.maps, self.far, self.centre = maps, far, centre
        self._found: dict[tuple[int, int], int] = {}   # far-memory cell -> tick found sealing
        self._found_version = 0   # counts the changes to the cells of `_found` (for `_found_mask`)
        self._squares: dict[tuple[int, tuple[int, ...]], np.ndarray] = {}  # `_square`'s masks
        # `judge`: (inputs, verdict) of the last two: a step that falls back to the plain
        # goals (Brain.plan) judges twice, the sequenced goals then all of them.
        self._judged: list[tuple[tuple, np.ndarray]] = []
        self._step_shared: tuple | None = None   # `_shared`: (tick, its three masks, what they gave)
        self._grids: tuple[tuple, tuple[np.ndarray, ...]] | None = None  # `_remembered`: (key, grids)
        self._mask: tuple[tuple, np.ndarray] | None = None  # `_found_mask`: (key, mask)

    def _nothing(self, shape: tuple[int, ...]) -> np.ndarray:
        """An empty mask, read-only (most steps no goal is near: nothing is unsafe)."""
        return self._square(-1, shape)   # the square of radius -1 holds no cell

    def _square(self, radius: int, shape: tuple[int, ...]) -> np.ndarray:
        """`around` the agent's cell, read-only: the agent is always in the centre, so the
        few squares asked for every step are made once."""
        mask = self._squares.get((radius, shape))
        if mask is None:
            mask = self._squares[(radius, shape)] = around((self.centre, self.centre), radius, shape)
            mask.setflags(write=False)
        return mask

    def unsafe(self, goals: np.ndarray, open_sites: np.ndarray, blocked: np.ndarray,
               supply: np.ndarray, tick: int) -> np.ndarray:
        """The goal sites that are no goals this step: found sealing now or lately."""
        return self.remember(goals, self.judge(goals, open_sites, blocked, supply, tick), tick)

    def remember(self, goals: np.ndarray, unsafe: np.ndarray, tick: int) -> np.ndarray:
        """`unsafe` (this step's verdicts, within SEAL_RADIUS cells) and the sites found
        sealing in the last SEAL_MEMORY ticks that are out of that radius now.

        Why: a verdict is about the site, not about where the agent stands. The check
        runs only near the agent, so a site it found sealing would be a goal again one
        cell farther off, and the agent would turn back at that cell's edge, to and fro,
        for ever (as in a one-cell slot of water whose far end it had not seen,
        gen-pocket 11230010). A verdict lasts SEAL_MEMORY ticks at most, since what it was
        made on goes stale."""
        any_unsafe = unsafe is not self._nothing(unsafe.shape) and bool(np.count_nonzero(unsafe))
        found = self._found
        if not found and not any_unsafe:
            return unsafe   # nothing remembered, nothing new: the rest would change nothing
        if found:   # verdicts on the sites judged again now give way to the new ones
            judged = goals & self._square(SEAL_RADIUS, goals.shape)
            if judged.any():
                for cell in map(tuple, self.far.from_map(*np.nonzero(judged)).tolist()):
                    if found.pop(cell, None) is not None:
                        self._found_version += 1
        if any_unsafe:
            for cell in map(tuple, self.far.from_map(*np.nonzero(unsafe)).tolist()):
                if cell not in found:
                    self._found_version += 1
                found[cell] = tick
        if found and tick - min(found.values()) > SEAL_MEMORY:
            self._found = found = {k: t for k, t in found.items() if tick - t <= SEAL_MEMORY}
            self._found_version += 1
        if not found:
            return unsafe
        return unsafe | self._found_mask() if any_unsafe else self._found_mask()

    def _found_mask(self) -> np.ndarray:
        """The sites found sealing lately (`_found`) that lie on the map, as a mask (read-only),
        kept while they and the agent's cell stay the same (most steps both do)."""
        key = (self.far.cell, self._found_version)
        if self._mask is None or self._mask[0] != key:
            mask = self.far.map_mask(np.array(list(self._found), np.int64))
            mask.setflags(write=False)
            self._mask = (key, mask)
        return self._mask[1]

    def judge(self, goals: np.ndarray, open_sites: np.ndarray, blocked: np.ndarray,
              supply: np.ndarray, tick: int | None = None) -> np.ndarray:
        """The goal sites near the agent (within SEAL_RADIUS cells) whose brick would cut an
        open site off from the supply, on the ground the agent has seen open (see the
        sealing module). Only cells seen free and open sites are passable; a site whose
        filling disconnects another open site waits, and the agent goes deeper, seeing the
        walls as it goes.

        With the world's extent known, the check runs on the whole world as the agent
        remembers it: whether a site joins another to the supply is a fact about the
        world, and the map's border is neither a wall nor a way out. A corridor longer
        than the map, judged on the map alone, is either cut off from everything at the
        border (nothing checked: a site filled with open sites deeper in, as in gen-pocket
        153) or, with the border counted open, open at a far end that is a wall (its mouth
        filled first, as in gen-pocket 117).

        `tick`: the step's, when the maps and the far memory will not change before the
        step ends; then what two judgements of one step share is worked out once (a step
        that falls back to the plain goals judges twice)."""
        if not _any_within(readonly(goals), self.centre, SEAL_RADIUS):
            return self._nothing(goals.shape)   # no goal near: nothing to judge
        near = goals & self._square(SEAL_RADIUS, goals.shape)
        recent, structure, memory, shared = self._shared(open_sites, blocked, supply, tick)
        # Only open sites seen empty lately are ways through (a stale one may have been
        # filled since); the sites judged are, as the agent is about to fill one of them.
        fresh = recent | near
        # A verdict is a pure function of these grids and of the far memory, and half the
        # time an agent beside a site judges again exactly what it judged a step before.
        key = (near.tobytes(), shared)
        for i, (known, verdict) in enumerate(self._judged):
            if known == key:
                self._judged.insert(0, self._judged.pop(i))
                return verdict
        unsafe = self._judge(near, open_sites, blocked, supply, fresh, structure, memory)
        unsafe.setflags(write=False)
        self._judged = [(key, unsafe), *self._judged[:1]]
        return unsafe

    def _shared(self, open_sites: np.ndarray, blocked: np.ndarray, supply: np.ndarray,
                tick: int | None) -> tuple[np.ndarray, np.ndarray, tuple, tuple]:
        """What a judgement reads besides its goals: the open sites seen empty lately, the
        structure, the far memory's `_memory_key`, and all of it (with the agent's cell)
        as a comparable key; kept for the rest of step `tick` (None: not kept)."""
        kept = self._step_shared
        if (tick is not None and kept is not None and kept[0] == tick and kept[1] is open_sites
                and kept[2] is blocked and kept[3] is supply):
            return kept[4]
        # A gap another agent stands beside may be filled at this very moment, out of this
        # agent's sight: two agents closing a ring's last two gaps at once each trusted the
        # other's as the way in (faults.cutoff seed 364). Such a site is no way through.
        recent = _fresh_uncontested(readonly(open_sites), readonly(self.maps.clear_age),
                                    readonly(self.maps.maps[AGENT]), FRESH_SITE)
        structure = (self.maps.maps[BRICK] > 0.5) & (self.maps.maps[CONFIG] > 0.5)
        memory = self._memory_key()
        key = (b"".join(g.tobytes() for g in (open_sites, blocked, supply, recent, self.maps.known, structure)),
               memory, self._where())
        shared = (recent, structure, memory, key)
        self._step_shared = (tick, open_sites, blocked, supply, shared)
        return shared

    def _memory_key(self) -> tuple:
        """What the far memory's own world grids (`_remembered`) are made of, as comparable
        values: the sites and the beliefs about them, the remembered bricks, walls and discs
        (() while the world's extent is unknown: then nothing of it is read)."""
        far = self.far
        if far.ground is None or far.walls is None or far.discs is None:
            return ()
        fresh = far.site_open & (far.site_clear_age <= FRESH_SITE)
        return (far.sites.tobytes(), far.bricks.tobytes(), far.site_open.tobytes(), fresh.tobytes(),
                far.walls.tobytes(), far.discs.tobytes())

    def _where(self) -> tuple:
        """The rest of the far memory a judgement reads: the agent's cell (the map's window
        on the world) and the ground seen free."""
        far = self.far
        return () if far.ground is None else (int(far.pos[0]), int(far.pos[1]), far.ground.tobytes())

    def _judge(self, near: np.ndarray, open_sites: np.ndarray, blocked: np.ndarray, supply: np.ndarray,
               fresh: np.ndarray, structure: np.ndarray, memory: tuple) -> np.ndarray:
        """`judge`, worked out: `near` the goal sites judged, `fresh` the open sites seen
        empty lately and `near`, `structure` the map's structure bricks, `memory` the far
        memory's `_memory_key`."""
        # No layout puts a wall, food or water on a drop site (nor does the world add a
        # disc there unless forced), so such a mark on an open site is a disc mapped a cell
        # off. Counted, it would hide every site behind it from the check (no way reaches
        # them to be cut), and the sites there would be filled one in front of another (as
        # a slot between water walls looked filled in its middle, gen-pocket 120).
        blocked = blocked & ~open_sites
        # The outside: the supply, and open ground seen a few cells beyond the sites that
        # are checked (the supply itself is often beyond the map, where nothing is seen).
        on_map = _Frame(open_sites, fresh, blocked, self.maps.known & ~blocked, supply,
                        ~self._square(SEAL_RADIUS + MARGIN, near.shape), _same, _same)
        g = self._on_world(on_map, memory) or on_map
        believed = (g.ground | g.open) & ~g.blocked
        passable = believed & ~(g.open & ~g.fresh)
        reference = (g.supply | (g.outside & g.ground & ~g.open)) & passable
        if not reference.any():
            # Nothing known outside the sites yet (a brain just made, after a restart, on a
            # site with a brick in its gripper): judged only on what was seen, no site near
            # can be shown safe, so none is filled until the agent has seen more (one that
            # dropped at once walled itself in, nested_squares restored from a checkpoint).
            return near
        # Structure bricks are doubted only where nothing else explains why an open site
        # is walled in: round sites no way reaches even through stale sites. Behind a
        # stale site the staleness explains it (that site may have been filled), and
        # doubting real bricks there invents a way out: the inner column of a pocket two
        # cells wide seemed to get out through them, and the site joining it to the mouth
        # was filled (as in gen-pocket 017).
        local = self._square(SEAL_RADIUS + 1, near.shape)
        doubtful = g.from_map(walling_in(fresh & ~g.to_map(connected(reference, believed)), structure, local))
        unsafe = cut_off(g.from_map(near), passable | doubtful, reference, g.open,
                         fallbacks=(believed | doubtful, ~g.blocked))
        return g.to_map(unsafe)

    def _on_world(self, m: _Frame, memory: tuple) -> _Frame | None:
        """The map's grids `m` on the whole world as the far memory holds it, what the
        agent sees now in the map's window; None while the world's extent is unknown."""
        far = self.far
        if far.ground is None or far.walls is None or far.discs is None:
            return None
        none = np.zeros_like(far.walls)
        open_grid, fresh_grid, blocked_grid, supply_grid = self._remembered(memory)
        return _Frame(open=far.on_world(open_grid, m.open),
                      fresh=far.on_world(fresh_grid, m.fresh),
                      blocked=far.on_world(blocked_grid, m.blocked),
                      ground=far.ground | far.on_world(none, m.ground),
                      supply=far.on_world(supply_grid, m.supply),
                      outside=far.on_world(~none, m.outside),
                      to_map=far.on_map, from_map=lambda layer: far.on_world(none, layer))

    def _remembered(self, key: tuple) -> tuple[np.ndarray, ...]:
        """The far memory's own world grids for `_on_world` (open sites, fresh ones, the
        blocked cells, the bricks), kept while what they are made of (`key`, the
        `_memory_key` the judgement was asked with) stays the same."""
        far = self.far
        assert far.walls is not None and far.discs is not None
        kept = self._grids
        if kept is None or kept[0] != key:
            fresh = far.site_open & (far.site_clear_age <= FRESH_SITE)
            grids = (far.cells_grid(far.sites[far.site_open]), far.cells_grid(far.sites[fresh]),
                     far.walls | far.discs | far.cells_grid(far.sites[~far.site_open]), far.cells_grid(far.bricks))
            for g in grids:
                g.setflags(write=False)
            self._grids = kept = (key, grids)
        return kept[1]


@njit(cache=True)
def _fresh_uncontested(open_sites, clear_age, agents, fresh):
    """The open sites seen empty within `fresh` ticks with no agent's mark (> 0.5) within
    one cell (8-neighbours): `open_sites & (clear_age <= fresh) & ~dilate(agents > 0.5)`
    in one pass: a numpy dilation of the whole map on every judgement made the step 15% dearer."""
    n, m = open_sites.shape
    out = np.zeros((n, m), np.bool_)
    for r in range(n):
        for c in range(m):
            if not open_sites[r, c] or not clear_age[r, c] <= fresh:
                continue
            free = True
            for rr in range(max(r - 1, 0), min(r + 2, n)):
                for cc in range(max(c - 1, 0), min(c + 2, m)):
                    if agents[rr, cc] > 0.5:
                        free = False
            out[r, c] = free
    return out


@njit(cache=True)
def _any_within(goals, centre, radius):
    """Whether a goal lies within `radius` cells (rows and columns) of (centre, centre)."""
    n, m = goals.shape
    for r in range(max(centre - radius, 0), min(centre + radius + 1, n)):
        for c in range(max(centre - radius, 0), min(centre + radius + 1, m)):
            if goals[r, c]:
                return True
    return False


@dataclass(frozen=True)
class _Frame:
    """The grids one judgement runs on (the agent's map, or the world it remembers), and
    the ways between them and the map: `to_map` a grid's map window, `from_map` a map mask
    onto the grids (False beyond the map)."""

    open: np.ndarray      # open sites
    fresh: np.ndarray     # open sites seen empty lately, and the sites judged
    blocked: np.ndarray   # walls, food, water and filled sites
    ground: np.ndarray    # ground seen free
    supply: np.ndarray    # the bricks and their source
    outside: np.ndarray   # beyond the checked square and its margin
    to_map: Callable[[np.ndarray], np.ndarray]
    from_map: Callable[[np.ndarray], np.ndarray]


def _same(grid: np.ndarray) -> np.ndarray:
    return grid

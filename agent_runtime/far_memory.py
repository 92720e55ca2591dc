"""What lies beyond the egocentric map: the blueprint's sites and bricks seen before.

The ESMs are bounded (paper §4.2.1): whatever shifts off them is forgotten. For the
blueprint that is fatal on any world larger than the map: the far side of a ring scrolls
off while the agent fetches bricks, and a blueprint wholly beyond the map at attach is
never learned at all. So the agent keeps, beside its maps, a short list of cells in its
own odometry frame (dead reckoning: whole cells crossed since attach, aligned with the
world grid as the maps are):

- every drop site of the blueprint, with whether it was last seen holding a brick;
- free bricks that scrolled off the map (a source the agent walked away from);
- the world's extent (from the Welcome), so its edge is a wall on the maps wherever the
  agent is, not only where its sensors have just seen it.

Nothing here is a map: the ESMs and NMs stay egocentric and of fixed size. Sites on the
map are written into the CONFIG layer each step; remembered bricks that come back onto
the map are written back into the BRICK layer (the sensors clear them if they are gone).
What is still beyond the map enters the navigation maps at their border, each border
cell starting at the distance that remains to the nearest remembered cell behind it, so
spreading activation (Eq. 2) ranks far goals after near ones by the whole distance
(`border_costs`). That distance goes round the fixed walls, food and water the agent
has seen and remembers (`walls`, `discs`), counting ground never seen as open, as a
person plans a way through a half-known town; with the world's extent unknown it is the
straight (octile) distance (`border_seed`).

With `remember=False` (`AgentConfig.far_memory` off, the paper's agent) the maps forget
as the paper's do: no brick, wall, food or water that leaves them is kept or comes back,
and nothing beyond them is a goal. The agent's cell and the blueprint's sites, with what
it believes of each, are still kept: stall reports read them, and so do the seal guard's
check on the whole world and `anchor_maps` when they are on (both off in the paper's agent).

Numpy and the compiled distance kernels (`border_seed`, spreading's), no bus.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from agent_runtime.spreading import distance_field, readonly

SQRT2_M1 = math.sqrt(2.0) - 1.0
BLOCK = 5          # cells per side of the squares Explore keeps track of having seen
PATIENCE = 300     # explore steps spent on one square before it counts as seen anyway
MAX_FAR_BRICKS = 4096   # a bound on what is kept; the oldest are dropped first
_NO_CELLS = np.zeros((0, 2), np.int64)
_NO_CELLS.setflags(write=False)


class FarMemory:
    """Sites and remembered bricks, as (x east, y north) cells relative to the attach cell."""

    def __init__(self, size: int, sites: np.ndarray, bounds: tuple[int, int, int, int] | None = None,
                 remember: bool = True):
        self.size = size
        self.remember = remember                         # off: what leaves the map is forgotten
        self.centre = size // 2
        self.pos = np.zeros(2, np.int64)                 # the agent's cell, (x, y) from the attach cell
        self._cell = (0, 0)                              # `pos` as a tuple: the caches' key (`move` keeps it)
        self.sites = np.asarray(sites, np.int64).reshape(-1, 2)
        self.site_open = np.ones(len(self.sites), bool)  # belief: no brick seen on it (yet)
        # Steps since each site was last seen empty (inf: never). A site believed open but
        # not seen for a while may have been filled by another agent (`age_sites`).
        self.site_clear_age = np.full(len(self.sites), np.inf)
        self.bricks = np.zeros((0, 2), np.int64)
        # (x0, y0, x1, y1): the world's cells, relative to the attach cell, x0 <= x < x1 and
        # y0 <= y < y1; None when the world did not say. Everything outside is wall.
        self.bounds = bounds
        self.seen: np.ndarray | None = None     # per BLOCK square of the world: been near it
        self.ever_seen: np.ndarray | None = None  # the same, never reset by a new sweep
        self._target: tuple[int, int] | None = None  # the square Explore is heading for
        self._target_age = 0                          # explore steps spent on it
        # Fixed obstacles per world cell [x - x0, y - y0], as the map last showed them: a
        # wall longer than the map scrolls off it while the agent follows it, and an agent
        # that forgets the far end turns back to look for a way round there, for ever.
        self.walls: np.ndarray | None = None
        # Food and water the same way, only for the distance that remains beyond the map
        # (a food wall longer than the map sent agents along it and back, for ever).
        self.discs: np.ndarray | None = None
        # Ground seen free (no wall, food or water), for judging sealing beyond the map: a
        # corridor longer than the map is open at one end only if that end was seen open.
        self.ground: np.ndarray | None = None
        self._memory_version = 0          # bumped when walls or discs change (for the cache)
        self._costs_cache: dict[tuple[int, bytes], np.ndarray] = {}
        # What depends only on where the agent is (and the blueprint): most steps it stays
        # in its cell, so each is worked out again only when `pos` or the sites change.
        self._by_pos: dict[str, tuple[tuple[int, int], tuple, object, object]] = {}
        self._centres: np.ndarray | None = None          # the BLOCK squares' centres, fixed
        self._border_cache: dict[tuple, np.ndarray | None] = {}
        self._marked: tuple | None = None   # (cell, radius) of the last `mark_seen` that changed nothing since
        if bounds is not None:
            x0, y0, x1, y1 = bounds
            self.seen = np.zeros((-(-(x1 - x0) // BLOCK), -(-(y1 - y0) // BLOCK)), bool)
            self.walls = np.zeros((x1 - x0, y1 - y0), bool)
            self.discs = np.zeros_like(self.walls)
            self.ground = np.zeros_like(self.walls)
            self.ever_seen = self.seen.copy()

    # ------------------------------------------------------------------ frames

    @property
    def cell(self) -> tuple[int, int]:
        """The agent's cell, (x, y) from the attach cell, as a tuple (`pos`)."""
        return self._cell

    def to_map(self, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(rows, cols) on the map of cells given relative to the attach cell."""
        cells = np.asarray(cells, np.int64).reshape(-1, 2)
        return self.centre - (cells[:, 1] - self.pos[1]), self.centre + (cells[:, 0] - self.pos[0])

    def from_map(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        """Cells relative to the attach cell of map cells (rows, cols), as seen before a move."""
        return np.column_stack([np.asarray(cols) - self.centre + self.pos[0],
                                self.centre - np.asarray(rows) + self.pos[1]]).astype(np.int64)

    def _on_map(self, rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
        n = self.size
        return (rows >= 0) & (rows < n) & (cols >= 0) & (cols < n)

    def _cached(self, name: str, key: tuple, array: np.ndarray | None, compute):
        """`compute()`, kept until `key` (with the agent's cell) changes or `array` is
        replaced (compared by identity: the cache holds it, so its id is never reused)."""
        hit = self._by_pos.get(name)
        if hit is not None and hit[0] == self._cell and hit[1] == key and hit[2] is array:
            return hit[3]
        value = compute()
        self._by_pos[name] = (self._cell, key, array, value)
        return value

    def _sites_on_map(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(indices into `sites`, rows, cols) of the sites that lie on the map."""
        def compute():
            rows, cols = self.to_map(self.sites)
            on = np.flatnonzero(self._on_map(rows, cols))
            return on, rows[on], cols[on]
        return self._cached("sites_on_map", (), self.sites, compute)

    # ------------------------------------------------------------------ blueprint

    def set_sites(self, sites: np.ndarray) -> None:
        """A new blueprint: keep what was believed of sites that are still in it."""
        sites = np.asarray(sites, np.int64).reshape(-1, 2)
        old = {tuple(c): (o, a) for c, o, a in zip(self.sites.tolist(), self.site_open.tolist(),
                                                   self.site_clear_age.tolist())}
        kept = [old.get(tuple(c), (True, np.inf)) for c in sites.tolist()]
        self.site_open = np.array([o for o, _ in kept], bool).reshape(-1)
        self.site_clear_age = np.array([a for _, a in kept], float).reshape(-1)
        self.sites = sites

    def map_mask(self, cells: np.ndarray) -> np.ndarray:
        """Map mask of the `cells` (x, y from the attach cell) that fall on the map."""
        out = np.zeros((self.size, self.size), bool)
        rows, cols = self.to_map(cells)
        on = self._on_map(rows, cols)
        out[rows[on], cols[on]] = True
        return out

    def config_layer(self, out: np.ndarray) -> None:
        """Write the sites that fall on the map into `out` (the CONFIG layer), clearing it first."""
        out[:] = self.map_mask(self.sites)

    def observe_sites(self, brick_layer: np.ndarray, clear_age: np.ndarray) -> None:
        """Update beliefs from the maps: a brick on a site's cell fills it; a cell seen empty of
        bricks this step opens it again (a repair, a perturbation)."""
        on, r, c = self._sites_on_map()
        _observe_sites(on, r, c, brick_layer, clear_age, self.site_open)

    def age_sites(self, clear_age: np.ndarray) -> None:
        """One step older: each site's steps since it was last seen empty of bricks, from
        the map's `clear_age` for the sites on the map (once per step)."""
        on, r, c = self._sites_on_map()
        _age_sites(on, r, c, clear_age, self.site_clear_age)

    def fresh_sites(self, within: float) -> np.ndarray:
        """(k, 2) cells of the sites believed open and seen empty in the last `within` steps."""
        return self.sites[self.site_open & (self.site_clear_age <= within)]

    def open_sites(self) -> int:
        """How many sites of the blueprint are believed open (no brick seen on them)."""
        return int(self.site_open.sum())

    # ------------------------------------------------------------------ moving

    def move(self, kx: int, ky: int, free_bricks: np.ndarray | None) -> np.ndarray:
        """The agent crossed kx cells east and ky north; `free_bricks` is the BRICK-but-not-site
        mask as it was before the maps shifted (None when the maps forget). Bricks that
        leave the map are remembered; returns the map mask of remembered bricks that came
        back onto it (to re-mark): free bricks, and the bricks of sites believed filled.

        Why the sites: what was seen stays as it was seen until it is seen otherwise, and
        a filled site cannot always be seen filled again: a brick deep in a one-cell slot
        is hidden from every sector by the brick in front of it. Come back with the site
        shown open, the hidden one's site looks like a goal behind a filled one, and the
        agent plans round the walls to reach it, for ever (as in gen-pocket 102); the
        sensors still clear a site seen empty."""
        if kx == 0 and ky == 0:
            return np.zeros((self.size, self.size), bool)
        if not self.remember:
            self._step(kx, ky)
            return np.zeros((self.size, self.size), bool)
        assert free_bricks is not None
        rows, cols = np.nonzero(free_bricks)
        leaving = ~self._on_map(rows + ky, cols - kx)
        if leaving.any():
            self._remember(self.from_map(rows[leaving], cols[leaving]))
        was_on = self._on_map(*self.to_map(self.sites))
        self._step(kx, ky)
        back = np.zeros((self.size, self.size), bool)
        r, c = self.to_map(self.sites)
        entering = self._on_map(r, c) & ~was_on & ~self.site_open
        back[r[entering], c[entering]] = True
        if len(self.bricks):
            r, c = self.to_map(self.bricks)
            on = self._on_map(r, c)
            back[r[on], c[on]] = True
            self.bricks = self.bricks[~on]
        return back

    def _step(self, kx: int, ky: int) -> None:
        self.pos += (kx, ky)
        self._cell = (int(self.pos[0]), int(self.pos[1]))

    def _wall_window(self) -> tuple[tuple[slice, slice], tuple[slice, slice]]:
        """The map cells that lie in the world and their world-grid cells, as slices:
        `layer[map_ix].T` is the map's window in world-grid order, `grid[world_ix]` the same
        cells of a world grid. Kept until the agent moves a cell.

        The window is a rectangle (x grows with the map's column, y falls with its row), so
        slices say it; a step with a cell move reads it a few times, and slicing is a view
        where index arrays copied."""
        assert self.bounds is not None  # asked only when there are walls, i.e. a known extent
        bounds = self.bounds

        def compute():
            x0, y0, x1, y1 = bounds
            idx = np.arange(self.size)
            gx = self.pos[0] + idx - self.centre - x0       # per map column, rising
            gy = self.pos[1] + self.centre - idx - y0       # per map row, falling
            cols, rows = np.flatnonzero((gx >= 0) & (gx < x1 - x0)), np.flatnonzero((gy >= 0) & (gy < y1 - y0))
            if cols.size == 0 or rows.size == 0:
                nothing = slice(0, 0)
                return (nothing, nothing), (nothing, nothing)
            c0, c1, r0, r1 = int(cols[0]), int(cols[-1]), int(rows[0]), int(rows[-1])
            y_last = int(gy[r1])
            world_y = slice(int(gy[r0]), y_last - 1 if y_last > 0 else None, -1)
            return (slice(r0, r1 + 1), slice(c0, c1 + 1)), (slice(int(gx[c0]), int(gx[c1]) + 1), world_y)
        return self._cached("wall_window", (), None, compute)

    def save_walls(self, obstacles: np.ndarray, discs: np.ndarray | None = None,
                   ground: np.ndarray | None = None) -> None:
        """Remember the fixed obstacles of the map (a bool layer) as it is now, the food and
        water (`discs`, for planning beyond the map only) and the ground seen free; call it
        before the map shifts. Cells on the map overwrite what was remembered of them."""
        if self.walls is None or self.discs is None or not self.remember:
            return
        map_ix, window = self._wall_window()
        if ground is not None and self.ground is not None:
            # Ground once seen free stays so (walls do not grow; a disc put there later is on
            # the map as blocked, which wins). The maps forget what shifted off them and see
            # little beside a wall: the mouth of a corridor by the world's edge, walked
            # through on the way in, was unknown again when the agent came back to it.
            self.ground[window] |= ground[map_ix].T    # not in the costs' cache key
        for memory, layer in ((self.walls, obstacles), (self.discs, discs)):
            if layer is None:
                continue
            now = layer[map_ix].T
            if not np.array_equal(memory[window], now):
                memory[window] = now
                self._memory_version += 1

    def load_walls(self) -> np.ndarray:
        """The remembered fixed obstacles that lie on the map now, as a map mask."""
        if self.walls is None:
            return np.zeros((self.size, self.size), bool)
        return self.on_map(self.walls)

    def load_discs(self) -> np.ndarray:
        """The remembered food and water that lie on the map now, as a map mask."""
        if self.discs is None:
            return np.zeros((self.size, self.size), bool)
        return self.on_map(self.discs)

    def on_world(self, memory: np.ndarray, layer: np.ndarray) -> np.ndarray:
        """A world grid [x - x0, y - y0]: `memory` (a world grid) with the map's window
        replaced by the map mask `layer`, what the agent sees now."""
        out = memory.copy()
        map_ix, world_ix = self._wall_window()
        out[world_ix] = layer[map_ix].T
        return out

    def on_map(self, world: np.ndarray) -> np.ndarray:
        """The map's window of a world grid, as a map mask (False beyond the world)."""
        out = np.zeros((self.size, self.size), world.dtype)
        map_ix, world_ix = self._wall_window()
        out[map_ix] = world[world_ix].T
        return out

    def cells_grid(self, cells: np.ndarray) -> np.ndarray:
        """World grid with `cells` ((k, 2) x, y from the attach cell) marked, those inside it."""
        assert self.walls is not None
        out = np.zeros_like(self.walls)
        gx, gy, inside = self._world_cells(cells)
        out[gx[inside], gy[inside]] = True
        return out

    def _world_cells(self, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        assert self.bounds is not None
        x0, y0, x1, y1 = self.bounds
        gx, gy = (np.asarray(cells, np.int64).reshape(-1, 2) - (x0, y0)).T
        return gx, gy, (gx >= 0) & (gx < x1 - x0) & (gy >= 0) & (gy < y1 - y0)

    def _remember(self, cells: np.ndarray) -> None:
        if self.bounds is not None:
            # No brick lies outside the world: a belief that the world's known extent
            # contradicts is kept on the nearest cell that agrees with it, the edge's. A
            # brick by the edge, seen from afar, can be mapped a cell beyond it; remembered
            # there, it would come back onto the map inside the edge's wall, where it is no
            # goal, and leave again as a remembered brick, which is one, and the agent
            # would walk to and fro across a cell's edge (for 50,000 ticks in
            # gen-nested_rings 11230026).
            x0, y0, x1, y1 = self.bounds
            cells = np.clip(cells, (x0, y0), (x1 - 1, y1 - 1))
        merged = np.unique(np.vstack([self.bricks, cells]), axis=0) if len(self.bricks) else np.unique(cells, axis=0)
        self.bricks = merged[-MAX_FAR_BRICKS:]

    def hear(self, seen: np.ndarray, taken: np.ndarray) -> None:
        """Bricks another agent reports (`AgentConfig.share_bricks`), as (k, 2) cells from
        the attach cell: those `seen` beyond the map are remembered as if this agent had seen
        them leave it (on the map its own sight holds); those `taken` (taken, or claimed by
        the teller) are forgotten, and never remembered from the same news. Nothing changes,
        and the caches keep, when the news is old news."""
        if not self.remember:
            return
        gone = _rows_in(self.bricks, taken)
        if gone.any():
            self.bricks = self.bricks[~gone]
        rows, cols = self.to_map(seen)
        new = seen[~self._on_map(rows, cols) & ~_rows_in(seen, taken) & ~_rows_in(seen, self.bricks)]
        if len(new):
            self._remember(new)

    # ------------------------------------------------------------------ exploring

    def mark_seen(self, radius: float) -> int:
        """The squares whose centre lies within `radius` cells of the agent have been seen;
        returns how many had never been seen before."""
        if self.seen is None or self.ever_seen is None:
            return 0
        if self._marked == (self._cell, radius):
            return 0   # the same squares as last step, all marked already: nothing to add
        centres = self._block_centres()
        near = self._cached("near", (radius,), None, lambda: np.hypot(centres[..., 0] - self.pos[0],
                                                                      centres[..., 1] - self.pos[1]) <= radius)
        new = int(np.count_nonzero(near & ~self.ever_seen))
        self.seen |= near
        self.ever_seen |= near
        self._marked = (self._cell, radius)
        return new

    def _block_centres(self) -> np.ndarray:
        assert self.seen is not None and self.bounds is not None  # asked only when the world's extent is known
        if self._centres is None:
            x0, y0, x1, y1 = self.bounds
            bx = x0 + np.minimum(np.arange(self.seen.shape[0]) * BLOCK + BLOCK // 2, x1 - x0 - 1)
            by = y0 + np.minimum(np.arange(self.seen.shape[1]) * BLOCK + BLOCK // 2, y1 - y0 - 1)
            self._centres = np.stack(np.meshgrid(bx, by, indexing="ij"), axis=-1)
            self._centres.setflags(write=False)
        return self._centres

    def unseen_target(self, rng: np.random.Generator, others: np.ndarray | None = None) -> np.ndarray | None:
        """(row, col) on the map (possibly beyond it) of the nearest square not yet seen, a
        little randomised so agents spread out; when all are seen, start over. None when
        the world's extent is unknown. `others`: cells (x, y, as `sites`) of other agents
        in sight; a new square is then one nearer this agent than any of them, if there
        is such a square (`AgentConfig.spread_search`)."""
        if self.seen is None:
            return None
        self._target_age += 1
        if self._target is not None and self._target_age > PATIENCE:
            # Behind a long wall, with hunger pulling it away, the agent may never get
            # there: move on, as a person would, rather than circle one square for ever.
            self.seen[self._target] = True
        if self._target is None or self.seen[self._target]:
            self._target_age = 0
            if self.seen.all():
                self.seen[:] = False
                self._marked = None   # the squares round the agent are unseen again
            free = np.argwhere(~self.seen)
            centres = self._block_centres()[~self.seen]
            mine = np.hypot(centres[:, 0] - self.pos[0], centres[:, 1] - self.pos[1])
            d = mine * rng.uniform(1.0, 1.5, len(free))
            if others is not None and len(others):
                # Agents that search side by side see the same ground: leave the squares
                # nearer another to it (each draws the same line from its own side).
                theirs = np.min(np.hypot(centres[:, None, 0] - others[None, :, 0],
                                         centres[:, None, 1] - others[None, :, 1]), axis=1)
                if (mine <= theirs).any():
                    d = np.where(mine <= theirs, d, np.inf)
            self._target = tuple(free[int(np.argmin(d))])
        rows, cols = self.to_map(self._block_centres()[self._target][None])
        return np.array([rows[0], cols[0]])

    def give_up_target(self) -> None:
        """The square Explore was heading for cannot be reached from here (walls, water):
        count it as seen, so the next call picks another instead of wandering for ever."""
        if self._target is not None and self.seen is not None:
            self.seen[self._target] = True
        self._target = None

    def outside_world(self) -> np.ndarray | None:
        """Mask of the map cells beyond the world's edge (None if its extent is unknown)."""
        if self.bounds is None:
            return None
        bounds = self.bounds

        def compute():
            x0, y0, x1, y1 = bounds
            offs = np.arange(self.size) - self.centre
            xs = self.pos[0] + offs                 # per column
            ys = self.pos[1] - offs                 # per row (row 0 is the north)
            outside = ((xs < x0) | (xs >= x1))[None, :] | ((ys < y0) | (ys >= y1))[:, None]
            outside.setflags(write=False)
            return outside
        return self._cached("outside", (), None, compute)

    # ------------------------------------------------------------------ beyond the border

    def far_open_sites(self) -> np.ndarray:
        """(rows, cols) as a (k, 2) array of open sites that are beyond the map (read-only);
        none when the maps forget."""
        def compute():
            if not self.remember:
                return _NO_CELLS
            rows, cols = self.to_map(self.sites[self.site_open])
            off = ~self._on_map(rows, cols)
            far = np.column_stack([rows[off], cols[off]])
            far.setflags(write=False)
            return far
        return self._cached("far_open_sites", (self.site_open.tobytes(),), self.sites, compute)

    def far_bricks(self) -> np.ndarray:
        """(rows, cols) as a (k, 2) array of the remembered free bricks, on the map or beyond it
        (read-only)."""
        def compute():
            rows, cols = self.to_map(self.bricks)
            far = np.column_stack([rows, cols])
            far.setflags(write=False)
            return far
        return self._cached("far_bricks", (), self.bricks, compute)


    def border_costs(self, targets: np.ndarray, obstacles: np.ndarray) -> np.ndarray | None:
        """Seed costs on the map's border cells (inf: none) for `targets`, (k, 2) (row, col)
        cells beyond the map: the length of the shortest way from each free border cell to
        a target through the world, round what the agent remembers as blocked (fixed
        walls, food, water) and over everything else. None if there are no targets.

        Why not the straight distance: the distance that remains is the way round what is
        known to block, beyond the map as on it. With the straight distance, a wall longer
        than the map between the agent and its goal makes the border cell straight behind
        it the cheapest; the agent walks into the wall, along it while its end is on the
        map, and back when that end scrolls off (as in generated worlds with long walls
        and food fields)."""
        if len(targets) == 0:
            return None
        # Kept for the few (targets, border obstacles, memory, cell) asked lately: the
        # config and brick NMs ask in turn, and most steps nothing of that changed.
        edge = np.concatenate([obstacles[0], obstacles[-1], obstacles[:, 0], obstacles[:, -1]])
        key = (np.asarray(targets, np.int64).tobytes(), np.packbits(edge).tobytes(), self._memory_version,
               int(self.pos[0]), int(self.pos[1]))
        if key not in self._border_cache:
            if len(self._border_cache) >= 4:
                self._border_cache.pop(next(iter(self._border_cache)))
            self._border_cache[key] = self._border_costs(targets, obstacles)
        seed = self._border_cache[key]
        return None if seed is None else seed.copy()   # the caller writes its goals into it

    def _border_costs(self, targets: np.ndarray, obstacles: np.ndarray) -> np.ndarray | None:
        if self.bounds is None or self.walls is None or self.discs is None:
            return border_seed(targets, self.size, obstacles)
        t = np.asarray(targets, np.int64).reshape(-1, 2)
        tx, ty, inside = self._grid_of(t[:, 0], t[:, 1])
        if not inside.all():
            return border_seed(targets, self.size, obstacles)
        world = self._world_field(tx, ty)
        border = _free_border(self.size, obstacles)
        bx, by, ok = self._grid_of(border[:, 0], border[:, 1])
        seed = np.full((self.size, self.size), np.inf)
        seed[border[ok, 0], border[ok, 1]] = world[bx[ok], by[ok]]
        if not np.isfinite(seed).any():
            # Remembered as unreachable: the memory may hold a misplaced mark; the straight
            # way on is better than giving the targets up.
            return border_seed(targets, self.size, obstacles)
        return seed

    def _grid_of(self, rows: np.ndarray, cols: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """World-grid indices (x - x0, y - y0) of map cells (rows, cols), and which lie in the world."""
        return self._world_cells(self.from_map(rows, cols))

    def _world_field(self, tx: np.ndarray, ty: np.ndarray) -> np.ndarray:
        """Distance field over the world grid [x, y] to the target cells, round the
        remembered walls and discs; cached until the targets or the memory change."""
        assert self.walls is not None and self.discs is not None
        key = (self._memory_version, np.stack([tx, ty]).astype(np.int64).tobytes())
        field = self._costs_cache.get(key)
        if field is None:
            goals = np.zeros_like(self.walls)
            goals[tx, ty] = True
            field = distance_field(goals, (self.walls | self.discs) & ~goals)
            if len(self._costs_cache) >= 4:   # the config and brick NMs ask in turn
                self._costs_cache.clear()
            self._costs_cache[key] = field
        return field


def on_border(targets: np.ndarray, size: int) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cols) of the map cells nearest to `targets` (k, 2), clamped onto the map."""
    t = np.asarray(targets, np.int64).reshape(-1, 2)
    return np.clip(t[:, 0], 0, size - 1), np.clip(t[:, 1], 0, size - 1)


def border_seed(targets: np.ndarray, size: int, obstacles: np.ndarray) -> np.ndarray | None:
    """Seed costs (inf: none) on the map's border cells for `targets`, (k, 2) (row, col)
    cells beyond the map: each free border cell gets the octile distance to its nearest
    target (the straight way on, as nothing is known out there). None if no targets."""
    if len(targets) == 0:
        return None
    border = _free_border(size, obstacles)
    seed = np.full((size, size), np.inf)
    if len(border) == 0:
        return seed
    t = np.ascontiguousarray(np.asarray(targets, np.int64).reshape(-1, 2))
    # Compiled: a whole-array version (border x targets x 2) was half of a 100-agent
    # decision step on a large blueprint, whose every site beyond the map is a target.
    seed[border[:, 0], border[:, 1]] = _nearest_octile(border, readonly(t))
    return seed


def _free_border(size: int, obstacles: np.ndarray) -> np.ndarray:
    """(k, 2) (row, col) of the map's border cells that are not obstacles."""
    border = _border_cells(size)
    return border[~obstacles[border[:, 0], border[:, 1]]]


_BORDERS: dict[int, np.ndarray] = {}


def _border_cells(n: int) -> np.ndarray:
    """(k, 2) (row, col) of the cells on the edge of an n x n map, sorted; made once per size."""
    if n not in _BORDERS:
        edge = np.arange(n)
        _BORDERS[n] = np.unique(np.vstack([
            np.column_stack([np.zeros(n, np.int64), edge]), np.column_stack([np.full(n, n - 1), edge]),
            np.column_stack([edge, np.zeros(n, np.int64)]), np.column_stack([edge, np.full(n, n - 1)])]), axis=0)
    return _BORDERS[n]


@njit(cache=True)
def _nearest_octile(cells: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Per cell, the octile distance to the nearest target (both (k, 2) int64)."""
    out = np.full(cells.shape[0], np.inf)
    for i in range(cells.shape[0]):
        best = np.inf
        for j in range(targets.shape[0]):
            a = float(abs(cells[i, 0] - targets[j, 0]))
            b = float(abs(cells[i, 1] - targets[j, 1]))
            d = max(a, b) + SQRT2_M1 * min(a, b)
            if d < best:
                best = d
        out[i] = best
    return out


def _rows_in(cells: np.ndarray, among: np.ndarray) -> np.ndarray:
    """Which rows of `cells` ((k, 2) int) are rows of `among` ((j, 2) int), as a bool array."""
    def key(a: np.ndarray) -> np.ndarray:
        a = np.asarray(a, np.int64).reshape(-1, 2)
        return a[:, 0] * (1 << 32) + a[:, 1]
    return np.isin(key(cells), key(among))


@njit(cache=True)
def _observe_sites(on, rows, cols, brick_layer, clear_age, site_open):
    """`observe_sites` for the sites on the map (`on` their indices, at `rows`, `cols`):
    a brick on a site's cell fills it, a cell seen empty of bricks this step opens it."""
    for i in range(on.size):
        r, c = rows[i], cols[i]
        if brick_layer[r, c] > 0.5:
            site_open[on[i]] = False
        elif clear_age[r, c] == 0:
            site_open[on[i]] = True


@njit(cache=True)
def _age_sites(on, rows, cols, clear_age, site_clear_age):
    """`age_sites`: every site one step older, the ones on the map no older than their cell."""
    for i in range(site_clear_age.size):
        site_clear_age[i] += 1.0
    for i in range(on.size):
        site_clear_age[on[i]] = min(site_clear_age[on[i]], clear_age[rows[i], cols[i]])

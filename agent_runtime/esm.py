"""Egocentric spatial maps (paper §4.2.1, Fig. 4; A2 in docs/design.md).

One square grid per kind of thing the agent keeps track of, stacked in one float32
array `maps[layer, row, col]`: FOOD, WATER, BRICK, OBSTACLE (fixed walls and the world's
edge; all four written from the sector sensors), CONFIG (the blueprint: the sites of
`far_memory.FarMemory` that fall on the map, rewritten by the Brain) and AGENT (other
agents, rewritten from scratch each step because they move). One map cell is one world cell (one disc
diameter); row 0 is the northmost row, columns grow eastwards, and the agent is always
in the centre cell (size // 2, size // 2).

The agent is rarely at the exact centre of its cell: `frac` holds its offset from the
centre cell's centre, in cells, (x east, y north), each in [-0.5, 0.5). Odometry is
accumulated into `frac`; only when the agent crosses into another cell do all layers
shift by whole cells, opposite to the motion, so sub-cell motion is never lost and the
map stays aligned with the world grid the blueprint was given in. Whatever is shifted
off the map is forgotten.

Sensing (see `sense`) clears what a sector proves empty (nothing of its colour nearer
than its reading, or nothing at all within range) and writes each reading at the cell
holding the point at that distance along the sector's centre angle. A sector cannot
tell the angle inside it, so that point is up to d * 2 sin(pi / 2S) from the disc: a
disc sitting on a cell centre lands in its very cell while that is under half a cell
(d < 2.5 cells with 16 sectors) and at most one cell off while it is under 1.5 (all of
a 6-cell range). Cells behind a reading keep what they had: a sector reports only the
nearest object, so it says nothing about what lies beyond. That is the plain rule, the
paper's agent's (`Sensing(False, False, False, False, False)`). Four refinements, each a flag
of `agent_runtime.config.AgentConfig` and of `Sensing`, are on by default:

* `ghost_association`: a reading is attributed to a cell of its band already holding
  that colour (for bricks, else a blueprint cell), and other brick marks in the band are
  cleared as ghosts of the one brick the sector saw (`sense` says why).
* `clear_margins`: a sector clears only cells nearer than its reading - CLEAR_MARGIN, or
  with no reading, within range - RANGE_MARGIN (a disc's own cell centre can be nearer
  than the disc).
* `site_core`: a blueprint site's cell is cleared of bricks by the sectors that cover its
  core (SITE_BRICK_OFFSET) only, since a brick on a site lies at its centre.
* `obstacle_trust`: a mark that cannot be placed surely must not close a way, since a
  marked cell explains the same reading ever after and the mark stays for good. So fixed
  obstacles are written only from readings near enough to put them in their own cell
  (`obstacle_trust`), and a one-cell gap in a wall is never sealed by a misplaced mark;
  and a farther food or water reading is never written on a blueprint site: sites are
  where bricks go (no layout puts a disc on one), so the disc is the one beside it (as
  the far discs of two water walls landed in the one-cell slot of sites between them and
  shut it, gen-pocket 20261127). Near readings are written wherever they land.

One more, `occlusion_clearing`, acts only when the world's sensors occlude (a sector
reports only its nearest object of any colour, `occluding`; docs/noise.md): a colour a
sector did not report is then cleared only in front of the nearest thing it did report,
since what lies behind that is hidden, not absent. Without it a brick behind a food disc
is wiped off the map each time the disc hides it.

Pure numpy, no bus. The per-sector geometry of the cells within sensor range is
computed for a window of cell offsets fixed per sensor range, and cached per `frac`.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numba import njit

from protocol.messages import CHANNELS, NO_READING

FOOD, WATER, BRICK, OBSTACLE, CONFIG, AGENT = range(6)   # layer indices (world_server.discs has the disc kinds)
LAYERS = 6
# Map layer fed by each sensor channel, in CHANNELS order (food, water, brick, obstacle, agent).
_CHANNEL_LAYER = np.array([{"food": FOOD, "water": WATER, "brick": BRICK, "obstacle": OBSTACLE,
                            "agent": AGENT}[c] for c in CHANNELS])
_LAYER_BASE = _CHANNEL_LAYER[:, None].astype(np.float64)  # (channels, 1), broadcast over sectors
_DISC_CHANNELS = 4             # the first four channels are fixed things, cleared by their sectors
assert all(_CHANNEL_LAYER[:_DISC_CHANNELS] == np.arange(_DISC_CHANNELS))  # layer = channel for these
_FOOD_OR_WATER = np.isin(_CHANNEL_LAYER, (FOOD, WATER))[:, None]   # (channels, 1)
_BRICK_CH = CHANNELS.index("brick")
_OBSTACLE_CH = CHANNELS.index("obstacle")
CLEAR_MARGIN = 0.75            # clear only cells nearer than reading - this (a disc's cell centre
                               # can be up to 0.71 cell nearer than the disc, plus a little noise)
RANGE_MARGIN = 0.5             # with no reading, clear only cells well inside the sensor range
BAND = 0.75                    # cells this close to a reading's distance may hold what it saw
SITE_BRICK_OFFSET = 0.35       # a brick on a drop site lies this close to its cell's centre (agents
                               # drop within drop_centering = 0.3 of it; a little noise on top)


@dataclass(frozen=True)
class Sensing:
    """Which refinements of the plain sensing rule `EgocentricMaps.sense` applies (the
    module says what each does); each is the AgentConfig flag of the same name."""

    ghost_association: bool = True
    clear_margins: bool = True
    site_core: bool = True
    obstacle_trust: bool = True
    occlusion_clearing: bool = True   # acts only where the world says its sensors occlude (`EgocentricMaps`)

    @classmethod
    def of(cls, cfg: Any) -> Sensing:
        """The refinements an AgentConfig (or anything with these attributes) switches on."""
        return cls(**{f.name: bool(getattr(cfg, f.name)) for f in dataclasses.fields(cls)})


EDGE_RINGS = 2   # cells beyond the world's edge on every side of a map cut to the world (`map_extent`)


def map_extent(size: int, world: tuple[int, int, int, int] | None) -> int:
    """Cells per side an agent's maps need: `size` (the configured side, odd), or fewer
    when the world is smaller than it (`world`: its cells (x0, y0, x1, y1), None if unknown).

    The maps are centred on the agent, so a side of twice the world's longer side shows
    the whole world from wherever the agent stands; `EDGE_RINGS` cells more on each side
    hold the world's edge, which every map marks as a wall, and a reading that lands just
    beyond it. Everything a larger map adds lies farther out, where nothing is: so the
    smaller map makes the same decisions for a fraction of the work per step (a 121-cell
    map of a 21 x 21 world is 47 cells a side, under a sixth of the cells). Odometry noise
    is the exception in principle: an agent whose belief of where it is drifts more than
    `EDGE_RINGS` cells beyond the world's edge has part of the world off its map sooner
    (its far memory then holds what left it, as on any map smaller than the world). In
    the noise experiment's five worlds of 15-17 cells, cut from 41 cells to 35-39, the
    runs at 10% odometry noise were the same as on the whole map.
    """
    if world is None:
        return size
    x0, y0, x1, y1 = world
    return min(size, 2 * (max(x1 - x0, y1 - y0) + EDGE_RINGS) + 1)


class EgocentricMaps:
    """The agent's ESMs: `maps` (LAYERS, size, size) float32, the sub-cell offset `frac`
    and the refinements of the sensing rule it applies, `sensing` (default all)."""

    def __init__(self, size: int = 41, sensing: Sensing | None = None, occluding: bool = False):
        if not (isinstance(size, int) and size >= 1 and size % 2 == 1):
            raise ValueError("map size must be an odd positive integer")
        self.size = size
        self.sensing = sensing or Sensing()
        # Whether a sector reports only the nearest object of any colour (the world's
        # occlusion, stated in the Welcome): then a colour with no reading is absent only in
        # front of the nearest thing the sector saw, whatever its colour.
        self.occluding = occluding
        self.centre = size // 2
        self.maps = np.zeros((LAYERS, size, size), np.float32)
        # A flat view, valid for the map's lifetime because `maps` is only ever changed in place.
        self._all = self.maps.reshape(-1)
        self.frac = np.zeros(2)
        # Sense calls since each cell was last seen empty of bricks (inf: not since it came
        # onto the map). Other agents fill sites out of sight, so an open site is only
        # known to be open as of when it was seen (goal sequencing uses this).
        self.clear_age = np.full((size, size), np.inf, np.float32)
        # Cells seen free of food, water and fixed obstacles at least once since they came
        # onto the map. Behind the nearest disc of a wall a sector sees nothing, so a map
        # shows a food wall as a few discs with gaps; `known` tells those unseen cells from
        # cells seen open (the seal guard, seal_guard.py, trusts only the latter).
        self.known = np.zeros((size, size), bool)
        self._windows: dict[float, tuple[np.ndarray, np.ndarray, np.ndarray]] = {}
        self._sector_dirs: dict[int, np.ndarray] = {}
        self._geometry_key: tuple | None = None
        self._geometry: tuple | None = None   # `_geometry_for`'s, for `_geometry_key`
        self._geometry_buffers: dict[float, tuple[np.ndarray, ...]] = {}
        self._pair_buffers: dict[float, tuple[np.ndarray, ...]] = {}

    # ------------------------------------------------------------------ coordinates

    def cell_of(self, ox: float, oy: float) -> tuple[int, int]:
        """(row, col) of the cell holding the point at offset (ox, oy) cells from the agent.

        The result may lie outside the map (check with `contains`).
        """
        return (self.centre - math.floor(self.frac[1] + oy + 0.5),
                self.centre + math.floor(self.frac[0] + ox + 0.5))

    def offset_of(self, row: Any, col: Any) -> tuple[Any, Any]:
        """World offset (x, y), in cells, from the agent to the centre of cell (row, col)
        (ints give floats, arrays of rows and columns give arrays)."""
        return (col - self.centre - float(self.frac[0]), self.centre - row - float(self.frac[1]))

    def contains(self, row: int, col: int) -> bool:
        """Whether (row, col) is a cell of the map."""
        return 0 <= row < self.size and 0 <= col < self.size

    # ------------------------------------------------------------------ blueprint

    def seed_blueprint(self, x: float, y: float, site_xs, site_ys, cell_size: float = 1.0) -> None:
        """Start a fresh map at pose (x, y) (world units) holding the blueprint's sites.

        Called once at attach. `frac` comes from the pose, so the map grid lines up with
        the world grid (world cell (c, r) is centred on ((c + 0.5), (r + 0.5)) * cell_size,
        r counted northwards). Every layer is cleared first: anything sensed before was
        placed relative to a pose this one replaces. Sites whose cell falls outside the map
        are ignored (the configuration map only knows the blueprint near where it starts).
        """
        self.maps.fill(0.0)
        self.clear_age.fill(np.inf)
        self.known.fill(False)
        gx, gy = x / cell_size, y / cell_size
        ax, ay = math.floor(gx), math.floor(gy)
        self.frac[:] = (gx - ax - 0.5, gy - ay - 0.5)
        sx = np.floor(np.asarray(site_xs, np.float64) / cell_size).astype(np.int64) - ax
        sy = np.floor(np.asarray(site_ys, np.float64) / cell_size).astype(np.int64) - ay
        self._set_cells(CONFIG, self.centre - sy, self.centre + sx)

    # ------------------------------------------------------------------ odometry

    def crossing(self, dx: float, dy: float, cell_size: float = 1.0) -> tuple[int, int]:
        """The whole cells (east, north) that `move(dx, dy, cell_size)` will shift by; no change."""
        return _wrap(float(self.frac[0]) + dx / cell_size)[1], _wrap(float(self.frac[1]) + dy / cell_size)[1]

    def move(self, dx: float, dy: float, cell_size: float = 1.0) -> tuple[int, int]:
        """Dead reckoning: the agent moved (dx, dy) world units (x east, y north) this tick.
        Returns the whole cells (east, north) it crossed, by which the maps shifted."""
        if not (math.isfinite(dx) and math.isfinite(dy)):
            raise ValueError(f"odometry must be finite, got ({dx!r}, {dy!r})")
        fx, kx = _wrap(float(self.frac[0]) + dx / cell_size)
        fy, ky = _wrap(float(self.frac[1]) + dy / cell_size)
        self.frac[:] = (fx, fy)
        if kx or ky:
            self._shift(kx, ky)
        return kx, ky

    def _shift(self, kx: int, ky: int) -> None:
        """The agent entered the cell kx east, ky north: move all contents the other way.
        What comes in from beyond the map is unknown: empty, and never seen open."""
        _shift_in_place(self.maps, kx, ky, 0.0)
        _shift_in_place(self.clear_age, kx, ky, np.inf)
        _shift_in_place(self.known, kx, ky, False)

    # ------------------------------------------------------------------ sensing

    def sense(self, ranges, sensor_range: float, cell_size: float = 1.0) -> None:
        """Integrate one sensor frame: `ranges` is (4, S) world-unit readings (or flat, channel-major).

        Per sector of FOOD, WATER and BRICK: cells whose centre lies in the sector's wedge
        and nearer than reading - 0.75 cell are cleared (the reading is the nearest object of
        that colour), or, with no reading, every cell of the wedge within sensor_range - 0.5
        cell (without `sensing.clear_margins`: nearer than the reading, within the range).
        Then each reading is written at the cell holding the point at its distance
        along the sector's centre angle, measured from the agent's true position (the cell
        centre plus `frac`). Cells beyond a reading keep what they had. The AGENT layer is
        rebuilt from this frame alone; CONFIG is never touched. `clear_age` counts the
        calls since each cell was last cleared of bricks.

        Association (before the writing): each disc reading is attributed to one cell of its
        band. A sector cannot tell the angle inside it, so the same disc seen from two
        places lands in two cells and leaves a ghost beside the real one; a ghost brick is
        then a goal the agent keeps driving to (and the gripper takes the real brick, from
        the structure). So a reading is matched to the cells of its wedge at about its
        distance (the band): a cell already holding that colour first, then, for bricks, a
        blueprint cell (bricks are expected there), else the cell at the sector's centre
        angle (the plain rule). Other brick marks in the band are ghosts of the one brick
        the sector saw and are cleared, except on blueprint cells, where neighbouring
        structure bricks really do stand at the same distance. Without
        `sensing.ghost_association` every reading is written by the plain rule.
        """
        r = np.asarray(ranges, np.float64).reshape(len(CHANNELS), -1)
        if cell_size != 1.0 or not r.flags.c_contiguous:   # (the brain's readings are in cells already)
            r = np.ascontiguousarray(r / cell_size)
        sectors = r.shape[1]
        reach = sensor_range / cell_size
        cells, dist, (k, sector, starts), vx, vy, (_, core_sector, core_starts) = self._geometry_for(sectors, reach)
        dirs = self._dirs(sectors)
        # One compiled pass (`_sense_kernel`) does what the steps below say, in their order:
        # A cell is known empty when it is nearer than what every sector it overlaps saw;
        # of a site cell, only the sectors where a brick on it could lie (`site_core`):
        # a cell is judged by where a thing on it can lie. Else a site beside structure
        # bricks seen at about its distance (in a pocket, say) is never seen open again
        # once a ghost lands on it, and the sites in front of it are filled over it.
        # Each reading may then be explained by any cell its wedge overlaps (see above;
        # `ghost_association`). With `obstacle_trust`, a fixed obstacle is written only
        # where the sector's centre angle lands in its own cell: farther off, the mark may
        # fall in the cell beside it, and a one-cell gap in a wall (which every sector along
        # the wall keeps reporting at about the same distance, so nothing ever clears it)
        # would be sealed for good. Farther readings still clear the cells in front of them,
        # and the wall is mapped as it comes near.
        # The rest is marked at its cell, except (`obstacle_trust`) food and water read from
        # farther than the obstacle trust whose cell is a blueprint site; a wall read from
        # within it always is.
        on = self.sensing
        _sense_kernel(self._all, self.clear_age.reshape(-1), self.known.reshape(-1), cells, dist, k, sector, starts,
                      core_sector, core_starts, vx, vy, r, float(reach), self.size, self.centre,
                      float(self.frac[0]), float(self.frac[1]), dirs[0], dirs[1],
                      obstacle_trust(sectors) if on.obstacle_trust else math.inf,
                      _CHANNEL_LAYER_I64, _FOOD_OR_WATER_FLAT, CLEAR_MARGIN if on.clear_margins else 0.0,
                      RANGE_MARGIN if on.clear_margins else 0.0, on.site_core, on.ghost_association,
                      self.occluding and on.occlusion_clearing)

    def _set_cells(self, layer: int, row: np.ndarray, col: np.ndarray) -> None:
        inside = (row >= 0) & (row < self.size) & (col >= 0) & (col < self.size)
        self.maps[layer, row[inside], col[inside]] = 1.0

    # ------------------------------------------------------------------ precomputed geometry

    def _dirs(self, sectors: int) -> np.ndarray:
        """(2, S): cos and sin of each sector's centre angle."""
        dirs = self._sector_dirs.get(sectors)
        if dirs is None:
            angle = (np.arange(sectors) + 0.5) * (2.0 * np.pi / sectors)
            dirs = self._sector_dirs[sectors] = np.vstack([np.cos(angle), np.sin(angle)])
        return dirs

    def _window(self, reach: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Flat indices (per disc layer) and (east, north) offsets of every cell whose centre can be in range.

        Only these cells can be cleared, so only they need a sector and a distance each
        call; which they are does not depend on `frac` (it moves a centre by <= 0.71 cell).
        """
        win = self._windows.get(reach)
        if win is None:
            c = self.centre
            rows, cols = np.mgrid[0:self.size, 0:self.size]
            east, north = (cols - c).ravel(), (c - rows).ravel()
            # reach + BAND + the largest frac (0.71): every cell a reading can be attributed to.
            keep = np.hypot(east, north) < reach + BAND + 0.75
            # Indices into the flattened maps of these cells in each disc layer: (3, cells).
            cells = np.arange(_DISC_CHANNELS)[:, None] * (self.size * self.size) + np.flatnonzero(keep)
            win = self._windows[reach] = (cells, east[keep].astype(np.float64), north[keep].astype(np.float64))
        return win

    def _geometry_for(self, sectors: int, reach: float) -> tuple[np.ndarray, ...]:
        """(flat indices, distance, sector, east, north offsets) of the window's cells, seen from the agent now.

        Cached per (frac, sectors, reach): an agent standing still reuses it. The
        arithmetic is compiled, the arctan2, hypot and arcsin stay numpy's (numba's libm
        differs from numpy's vectorised ones by an ulp on about a tenth of the cells, which
        can move a sector edge): three numpy calls a step, into kept buffers.
        """
        key = (float(self.frac[0]), float(self.frac[1]), sectors, reach)
        if key != self._geometry_key:
            cells, east, north = self._window(reach)
            vx, vy, angle, dist, ratio, half = self._buffers_for(reach)
            _offsets(east, north, key[0], key[1], vx, vy)
            np.arctan2(vy, vx, out=angle)
            np.hypot(vx, vy, out=dist)
            # A cell has width: it overlaps every sector within half a cell of its centre's
            # direction (a disc on a sector border may be reported by either neighbour).
            # A brick on a drop site lies within SITE_BRICK_OFFSET of the cell's centre (it
            # is dropped there), so for site cells only the sectors of that core count.
            _half_angle_ratios(dist, _PAIR_RADII, ratio)
            np.arcsin(ratio, out=half)
            pairs, core = self._pairs(reach, angle, half, sectors / (2.0 * np.pi), sectors)
            self._geometry = (cells, dist, pairs, vx, vy, core)
            self._geometry_key = key
        assert self._geometry is not None
        return self._geometry

    def _pairs(self, reach: float, angle: np.ndarray, half: np.ndarray, per: float,
               sectors: int) -> tuple[tuple[np.ndarray, ...], tuple[np.ndarray, ...]]:
        """`_pairs_into`'s (cell of pair, sector, starts) of both runs (half[0]: whole cells,
        half[1]: site cores), in kept arrays (views of them): (2, k) pairs and (2, n) starts,
        grown when a step needs more pairs."""
        bufs = self._pair_buffers.get(reach)
        if bufs is None:
            n = angle.shape[0]
            bufs = self._pair_buffers[reach] = (np.empty((2, 4 * n), np.int64), np.empty((2, 4 * n), np.int64),
                                                np.empty((2, n), np.int64))
        whole, core = _both_pairs_into(angle, half, per, sectors, *bufs)
        if whole < 0 or core < 0:   # more pairs than the arrays hold: room for twice as many
            room = 2 * max(abs(whole), abs(core))
            bufs = self._pair_buffers[reach] = (np.empty((2, room), np.int64), np.empty((2, room), np.int64), bufs[2])
            whole, core = _both_pairs_into(angle, half, per, sectors, *bufs)
        of_pair, sector, starts = bufs
        return ((of_pair[0, :whole], sector[0, :whole], starts[0]),
                (of_pair[1, :core], sector[1, :core], starts[1]))

    def _buffers_for(self, reach: float) -> tuple[np.ndarray, ...]:
        """Kept arrays for `_geometry_for` (vx, vy, angle, dist, ratio, half), per window:
        each step's geometry replaces the last one's, which nothing keeps."""
        bufs = self._geometry_buffers.get(reach)
        if bufs is None:
            n = self._window(reach)[1].shape[0]
            bufs = self._geometry_buffers[reach] = (*(np.empty(n) for _ in range(4)), np.empty((2, n)),
                                                     np.empty((2, n)))
        return bufs


# The radii of `_geometry_for`'s two sector runs per cell: the whole cell, a site's core.
_PAIR_RADII = np.array([0.5, SITE_BRICK_OFFSET])


@njit(cache=True)
def _offsets(east, north, f0, f1, vx, vy):
    """(east, north) of the window's cells less the agent's offset in its cell, into vx, vy."""
    for i in range(east.shape[0]):
        vx[i] = east[i] - f0
        vy[i] = north[i] - f1


@njit(cache=True)
def _half_angle_ratios(dist, radii, out):
    """out[j, i] = min(radii[j] / max(dist[i], 1e-9), 1): the sine of the half angle a disc of
    radius radii[j] at cell i spans (its arcsin is taken by numpy, see `_geometry_for`)."""
    for j in range(radii.shape[0]):
        for i in range(dist.shape[0]):
            out[j, i] = min(radii[j] / max(dist[i], 1e-9), 1.0)


@njit(cache=True, inline="always")
def _sector_run(angle, half, per, sectors):
    """(first sector, how many) of the sectors within the half angle `half` of `angle`."""
    lo = np.int64(math.floor((angle - half) * per))
    return lo, min(np.int64(math.floor((angle + half) * per)) - lo + 1, sectors)


@njit(cache=True)
def _both_pairs_into(angle, half, per, sectors, cell_of_pair, sector, starts):
    """`_pairs_into` for both rows of `half` (the whole cells, the site cores), into the
    rows of the (2, k) and (2, n) arrays: each run's count (or minus it, see there)."""
    return (_pairs_into(angle, half[0], per, sectors, cell_of_pair[0], sector[0], starts[0]),
            _pairs_into(angle, half[1], per, sectors, cell_of_pair[1], sector[1], starts[1]))


@njit(cache=True)
def _pairs_into(angle, half, per, sectors, cell_of_pair, sector, starts):
    """Every (cell, sector) pair where the sector comes within the half angle `half` of the
    cell's centre direction `angle`, grouped by cell in window order, into `cell_of_pair`,
    `sector` and `starts` (the first pair of each cell); returns how many pairs there are,
    or minus that when `cell_of_pair` and `sector` hold fewer (nothing written)."""
    n = angle.shape[0]
    total = 0
    for i in range(n):
        total += _sector_run(angle[i], half[i], per, sectors)[1]
    if total > cell_of_pair.shape[0]:
        return -total
    p = 0
    for i in range(n):
        lo, span = _sector_run(angle[i], half[i], per, sectors)
        starts[i] = p
        for j in range(span):
            cell_of_pair[p] = i
            sector[p] = (lo + j) % sectors
            p += 1
    return total


@functools.cache
def obstacle_trust(sectors: int) -> float:
    """Distance (cells) within which a reading written at its sector's centre angle lies
    within 0.45 cell of the true direction, i.e. in the cell of an object on a cell centre."""
    return 0.45 / math.sin(min(math.pi / sectors, math.pi / 2))


def _shift_in_place(grid: np.ndarray, kx: int, ky: int, fill: float) -> None:
    """Move grid[..., row, col] to [..., row + ky, col - kx]: north motion pushes contents
    south (rows grow southwards), east motion pushes them west; vacated cells get `fill`."""
    n = grid.shape[-1]
    if abs(kx) >= n or abs(ky) >= n:
        grid.fill(fill)
        return
    dst_r, src_r = _span(ky, n)
    dst_c, src_c = _span(-kx, n)
    # numpy copes with the overlap of source and destination (it buffers), and working
    # in place keeps the array (and views of it) the same object.
    grid[..., dst_r, dst_c] = grid[..., src_r, src_c]
    if ky > 0:
        grid[..., :ky, :] = fill
    elif ky < 0:
        grid[..., n + ky:, :] = fill
    if kx > 0:
        grid[..., :, n - kx:] = fill
    elif kx < 0:
        grid[..., :, :-kx] = fill


def _wrap(f: float) -> tuple[float, int]:
    """Split an offset in cells into (rest in [-0.5, 0.5), whole cells crossed)."""
    k = math.floor(f + 0.5)
    f -= k
    # Rounding in f + 0.5 can leave f a hair outside the range; put it back.
    if f >= 0.5:
        f, k = f - 1.0, k + 1
    elif f < -0.5:
        f, k = f + 1.0, k - 1
    return f, k


def _span(shift: int, n: int) -> tuple[slice, slice]:
    """(destination, source) slices along one axis for moving contents by `shift` cells."""
    if shift >= 0:
        return slice(shift, n), slice(0, n - shift)
    return slice(0, n + shift), slice(-shift, n)


@njit(cache=True)
def _associate_kernel(flat, cells, dist, k, sector, vx, vy, disc, cos_s, sin_s, config_base, brick, band_width,
                      channels):
    """The association of `EgocentricMaps.sense` over (cell, sector) pairs, pair p being
    window cell k[p] (`cells`, `dist`, `vx`, `vy` are per window cell); returns `explained`.

    One compiled pass finds each reading's best cell; a second collects winners and
    ghosts from the same (pre-update) map, which are then applied: ghosts cleared first,
    so a cell that wins any reading ends up marked.
    """
    n_ch, sectors = disc.shape
    pairs = sector.shape[0]
    best = np.full(n_ch * sectors, np.inf)
    score = np.full((n_ch, pairs), np.inf)
    for ch in range(n_ch):
        for p in range(pairs):
            s = sector[p]
            d = disc[ch, s]
            if d < 0.0 or abs(dist[k[p]] - d) > band_width:
                continue
            err = math.hypot(vx[k[p]] - d * cos_s[s], vy[k[p]] - d * sin_s[s])
            marked = flat[cells[ch, k[p]]] > 0.5
            blueprint = ch == brick and flat[config_base + cells[0, k[p]]] > 0.5
            score[ch, p] = err - 2.0 * marked - 1.0 * blueprint
            if score[ch, p] < best[ch * sectors + s]:
                best[ch * sectors + s] = score[ch, p]
    explained = np.zeros((channels, sectors), np.bool_)
    winners = np.empty(n_ch * pairs, np.int64)
    ghosts = np.empty(n_ch * pairs, np.int64)
    n_win = 0
    n_ghost = 0
    for ch in range(n_ch):
        for p in range(pairs):
            if score[ch, p] == np.inf:
                continue
            s = sector[p]
            marked = flat[cells[ch, k[p]]] > 0.5
            blueprint = ch == brick and flat[config_base + cells[0, k[p]]] > 0.5
            if score[ch, p] <= best[ch * sectors + s] and (marked or blueprint):
                winners[n_win] = cells[ch, k[p]]
                n_win += 1
                explained[ch, s] = True
            elif ch == brick and marked and not blueprint:
                ghosts[n_ghost] = cells[ch, k[p]]
                n_ghost += 1
    for i in range(n_ghost):
        flat[ghosts[i]] = 0.0
    for i in range(n_win):
        flat[winners[i]] = 1.0
    return explained


_CHANNEL_LAYER_I64 = np.ascontiguousarray(_CHANNEL_LAYER.astype(np.int64))
_FOOD_OR_WATER_FLAT = np.ascontiguousarray(_FOOD_OR_WATER[:, 0])


@njit(cache=True)
def _min_limit(limit, ch, sector, first, end):
    m = limit[ch, sector[first]]
    for p in range(first + 1, end):
        if limit[ch, sector[p]] < m:
            m = limit[ch, sector[p]]
    return m


@njit(cache=True)
def _sense_kernel(flat, clear_age, known, cells, dist, k, sector, starts, core_sector, core_starts, vx, vy, r,
                  reach, size, centre, f0, f1, cos_s, sin_s, trust, layer_of_channel, food_or_water, clear_margin,
                  range_margin, site_core, associate, occluded):
    """`EgocentricMaps.sense` on the flat maps: clear, age, associate, write (see there);
    the last five arguments and `trust` (inf: none) are the refinements of `Sensing`."""
    nn = size * size
    n_ch, sectors = r.shape
    ncell = dist.shape[0]
    limit = np.empty((_DISC_CHANNELS, sectors))
    for s in range(sectors):
        # Occluded, a sector proves every colour absent only in front of the nearest thing
        # it saw, of any colour (agents too): behind it lies what it cannot see.
        nearest = -1.0
        if occluded:
            for ch in range(n_ch):
                if r[ch, s] >= 0.0 and (nearest < 0.0 or r[ch, s] < nearest):
                    nearest = r[ch, s]
        for ch in range(_DISC_CHANNELS):
            d = r[ch, s] if r[ch, s] >= 0.0 else nearest
            limit[ch, s] = d - clear_margin if d >= 0.0 else reach - range_margin
    clear = np.zeros((_DISC_CHANNELS, ncell), np.bool_)
    for i in range(ncell):
        end = starts[i + 1] if i + 1 < ncell else sector.shape[0]
        core_end = core_starts[i + 1] if i + 1 < ncell else core_sector.shape[0]
        site = site_core and flat[cells[0, i] - FOOD * nn + CONFIG * nn] > 0.5
        for ch in range(_DISC_CHANNELS):
            if ch == _BRICK_CH and site:
                m = _min_limit(limit, ch, core_sector, core_starts[i], core_end)
            else:
                m = _min_limit(limit, ch, sector, starts[i], end)
            clear[ch, i] = dist[i] < m
    for ch in range(_DISC_CHANNELS):
        for i in range(ncell):
            if clear[ch, i]:
                flat[cells[ch, i]] = 0.0
    for i in range(clear_age.shape[0]):
        clear_age[i] += 1.0
    for i in range(ncell):
        if clear[_BRICK_CH, i]:
            clear_age[cells[_BRICK_CH, i] - BRICK * nn] = 0.0
        if clear[FOOD, i] and clear[WATER, i] and clear[_OBSTACLE_CH, i]:
            known[cells[FOOD, i] - FOOD * nn] = True
    known[centre * size + centre] = True  # the agent stands there
    if associate:
        explained = _associate_kernel(flat, cells, dist, k, sector, vx, vy,
                                      np.ascontiguousarray(r[:_DISC_CHANNELS]), cos_s, sin_s, nn * CONFIG, BRICK,
                                      BAND, n_ch)
    else:  # the plain rule: every reading is written where its sector's centre angle puts it
        explained = np.zeros((n_ch, sectors), np.bool_)
    # A near wall reading is its own cell, never a marked wall cell beside it that only the
    # sector's width reaches: walls stand on cell centres, and within `trust` the sector's
    # centre angle lands in the right cell. Taken by a marked neighbour, a wall cell beside
    # the agent stayed off the map and a one-cell gap looked two cells wide.
    if trust < math.inf:
        for s in range(sectors):
            if r[_OBSTACLE_CH, s] <= trust:
                explained[_OBSTACLE_CH, s] = False
    for i in range(AGENT * nn, (AGENT + 1) * nn):
        flat[i] = 0.0
    hit = np.zeros((n_ch, sectors), np.bool_)
    at = np.zeros((n_ch, sectors), np.int64)
    for ch in range(n_ch):
        for s in range(sectors):
            d = NO_READING if explained[ch, s] else r[ch, s]
            if ch == _OBSTACLE_CH and d > trust:
                d = NO_READING
            col = math.floor(f0 + d * cos_s[s] + 0.5) + centre
            row = centre - math.floor(f1 + d * sin_s[s] + 0.5)
            inside = d >= 0.0 and row >= 0 and row < size and col >= 0 and col < size
            cell = np.int64(row * size + col) if inside else 0
            if inside and food_or_water[ch] and d > trust and flat[CONFIG * nn + cell] > 0.5:
                inside = False
            hit[ch, s] = inside
            at[ch, s] = cell
    for ch in range(n_ch):
        for s in range(sectors):
            if hit[ch, s]:
                flat[layer_of_channel[ch] * nn + at[ch, s]] = 1.0

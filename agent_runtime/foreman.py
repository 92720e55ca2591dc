"""The foreman's marking (issue 37 item 4; paper §6.3): where a ConAg agent puts cues for workers.

The paper's future work: "a few 'foremen' equipped with the ConAg architecture ... mark the
environment with cues for the worker agents", which build the simple parts. A foreman is a
ConAg agent (its Brain builds as any agent does) that also reads its own maps to mark, on a
tick its brain asks for no action, one cue at a time (docs/society.md):

* a `supply` cue on open ground beside free bricks, away from the structure, where workers
  may take bricks (a worker cannot tell a free brick from a structure brick: it takes bricks
  only round a supply cue);
* `site` cues on open sites it has just seen open, nearest first, while it has fewer than
  `max_site_cues` out: only a site whose filling, together with every other site marked,
  in any order, cuts no open site, free brick or the foreman itself off from the outside
  and leaves every marked site enterable. Workers fill marked sites in whatever order they
  reach them, so the marked set must be safe as a whole: filling fewer cells never
  disconnects more, so checking the whole set covers every order;
* it keeps the set safe as sites fill (by anyone, or by its own Brain, which knows nothing
  of its cues): a cue a fill made unsafe comes off, checked again before its own drops;
* it takes a cue off once its site is seen filled (a brick there), or a supply cue once no
  free brick is left beside it and no site is open on its map (a dry supply is where
  workers bring back bricks no site wants); a dry supply moves to bricks seen elsewhere.

The cues it put out are kept as points in its odometry frame (cells from where it
attached), so they stay put as the maps shift. Pure numpy over the Brain's maps; the shell
sends the Mark (agent_runtime/society_node.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from agent_runtime.esm import BRICK, CONFIG, FOOD, OBSTACLE, WATER
from agent_runtime.sealing import border, connected, dilate, largest_region


@dataclass(frozen=True)
class ForemanConfig:
    """How a foreman marks."""

    reach: float = 4.5          # cells: it marks cells this near only (inside its sight and the world's cue_reach)
    max_site_cues: int = 6      # site cues out at once
    fresh: float = 5.0          # a site is marked only if seen open within this many steps
    every: int = 4              # steps between two marking decisions
    supply_clearance: int = 2   # a supply cue keeps this many cells (each axis) from any site

    def __post_init__(self) -> None:
        if not (self.reach > 0 and self.max_site_cues >= 0 and self.fresh > 0 and self.every >= 1
                and self.supply_clearance >= 0):
            raise ValueError("foreman settings must be positive (max_site_cues, supply_clearance >= 0)")


@dataclass(frozen=True)
class Mark:
    """One marking action: put (`mark`) or take (`unmark`) a cue of `kind` on the cell whose
    centre is (dx, dy) cells from the agent, world axes."""

    action: str
    dx: float
    dy: float
    kind: str


@dataclass(frozen=True)
class MapView:
    """What marking reads of the maps, as bool grids [row, col] (the agent in `centre`):
    open sites and how fresh, cells a body cannot enter, free bricks."""

    open_sites: np.ndarray
    fresh_sites: np.ndarray
    filled_sites: np.ndarray
    blocked: np.ndarray
    free_bricks: np.ndarray
    centre: tuple[int, int]

    @classmethod
    def of(cls, marks: np.ndarray, clear_age: np.ndarray, fresh: float) -> MapView:
        """From the maps as marks (`Brain.layers()`) and the sites' ages (`maps.clear_age`)."""
        sites, bricks = marks[CONFIG], marks[BRICK]
        open_sites = sites & ~bricks
        blocked = marks[OBSTACLE] | marks[FOOD] | marks[WATER] | bricks
        n = marks.shape[1] // 2
        return cls(open_sites, open_sites & (clear_age < fresh), sites & bricks, blocked, bricks & ~sites, (n, n))


def marking_is_safe(view: MapView, marked: np.ndarray) -> bool:
    """Whether workers may fill every cell of `marked` in any order: with all of them filled,
    what the build needs of the open ground that reaches the outside now (the open sites,
    the cells beside free bricks, the foreman's own cell) still reaches it, and each marked
    cell still has a neighbour that does (so it can be entered while the others are filled).

    The outside is the map's open border (the world goes on beyond it); on a map that holds
    the whole world (its border is the world's edge), the largest open region, since the
    foreman may stand in a pocket itself. Cells never seen count as open (the maps' reading
    of them)."""
    passable = ~view.blocked
    outside = border(passable) & passable
    if outside.any():
        now = connected(outside, passable)
        after = connected(outside & ~marked, passable & ~marked)
    else:
        # The whole world is on the map: the largest open region stands for the outside,
        # and after the filling, the largest piece left of it. (The region itself is no
        # reference to reach: every cell of it reaches it, cut off or not.)
        now = largest_region(passable, passable)
        after = largest_region(now & ~marked, passable & ~marked)
    # Ground cut off with nothing on it the build needs is no loss (a ring's inside, once
    # its sites are in): what must stay reachable are the open sites, the foreman's own cell
    # and the free bricks.
    needed = view.open_sites | _beside(view.free_bricks)
    needed[view.centre] = True
    if (now & needed & ~marked & ~after).any():
        return False
    return bool(np.all(_beside(after)[marked]))


def site_candidates(view: MapView, marked: np.ndarray, reach: float) -> list[tuple[int, int]]:
    """Fresh open sites within `reach` cells not marked yet, nearest first (ties in reading order)."""
    rows, cols = np.nonzero(view.fresh_sites & ~marked)
    d = np.hypot(rows - view.centre[0], cols - view.centre[1])
    keep = d <= reach
    order = np.lexsort((cols[keep], rows[keep], d[keep]))
    return [(int(r), int(c)) for r, c in zip(rows[keep][order], cols[keep][order])]


def supply_cell(view: MapView, reach: float, clearance: int) -> tuple[int, int] | None:
    """Open ground within `reach` beside the most free bricks (8 neighbours), with no site
    (open or filled) within `clearance` cells on each axis, so a worker taking bricks round it
    cannot take a structure brick; nearest first among equals. None if there is none."""
    sites = view.open_sites | view.filled_sites
    near_site = dilate(sites, clearance)
    bricks = view.free_bricks.astype(np.int64)
    padded = np.pad(bricks, 1)
    n, m = bricks.shape
    beside = np.zeros_like(bricks)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            if dr or dc:
                beside += padded[1 + dr:1 + dr + n, 1 + dc:1 + dc + m]
    ok = ~view.blocked & ~sites & ~near_site & (beside > 0)
    rows, cols = np.nonzero(ok)
    if not len(rows):
        return None
    d = np.hypot(rows - view.centre[0], cols - view.centre[1])
    keep = d <= reach
    if not keep.any():
        return None
    order = np.lexsort((cols[keep], rows[keep], d[keep], -beside[rows[keep], cols[keep]]))
    return int(rows[keep][order[0]]), int(cols[keep][order[0]])


class Foreman:
    """One foreman's cues and its next marking decision (`decide`), over its Brain's maps."""

    def __init__(self, cfg: ForemanConfig | None = None):
        self.cfg = cfg or ForemanConfig()
        self.cues: list[tuple[float, float, str]] = []  # (x, y) in its odometry frame (cells), kind
        self._step = 0
        self.marks = self.unmarks = 0

    def due(self) -> bool:
        """Counts a step; True on every `every`-th, when it decides (marking is no reflex)."""
        self._step += 1
        return self._step % self.cfg.every == 0

    def decide(self, marks: np.ndarray, clear_age: np.ndarray, odometry: np.ndarray, offset_of, cell_of,
               ) -> Mark | None:
        """The cue to put or take now, or None. `marks`: the maps as marks; `clear_age`
        the sites' ages; `odometry` where the agent is in its odometry frame (cells);
        `offset_of(row, col)` / `cell_of(dx, dy)` the maps' coordinates (EgocentricMaps)."""
        view = MapView.of(marks, clear_age, self.cfg.fresh)
        mine = self._mine(odometry, cell_of)
        done = self._finished(view, mine, odometry)
        if done is not None:
            return done
        cued = self._cued(view, mine)
        unsafe = self._unsafe_cue(view, mine, cued, odometry)
        if unsafe is not None:
            return unsafe
        supply = self._supply(view, mine, odometry, offset_of)
        if supply is not None:
            return supply
        if sum(kind == "site" for _, _, kind in self.cues) >= self.cfg.max_site_cues:
            return None
        for cell in site_candidates(view, cued, self.cfg.reach):
            trial = cued.copy()
            trial[cell] = True
            if marking_is_safe(view, trial):
                return self._put(cell, "site", odometry, offset_of)
        return None

    def _finished(self, view: MapView, mine, odometry: np.ndarray) -> Mark | None:
        """Take off the first of its cues within reach whose job is done."""
        n = view.open_sites.shape[0]
        for k, ((r, c), kind) in enumerate(mine):
            x, y, _ = self.cues[k]
            dx, dy = x - odometry[0], y - odometry[1]
            if not (0 <= r < n and 0 <= c < n) or math.hypot(dx, dy) > self.cfg.reach:
                continue
            # A dry supply stays while sites are open: it is where workers bring back the
            # bricks no site wants (agent_runtime/worker.py), which would otherwise ride round
            # the world with them while the build waits for bricks.
            done = not view.open_sites[r, c] if kind == "site" else _dry(view, r, c) and not view.open_sites.any()
            if done:
                return self._take_off(k, odometry)
        return None

    def before_drop(self, marks: np.ndarray, clear_age: np.ndarray, odometry: np.ndarray, cell_of) -> Mark | None:
        """The foreman builds too, knowing nothing of its cues: before its brick goes down
        (under its body, on the map's centre), a cue to take off first if that fill would
        leave the marked set unsafe (an open site reachable only through marked ones), else
        None. The brain drops on a later step, once the set is safe with the fill."""
        view = MapView.of(marks, clear_age, self.cfg.fresh)
        mine = self._mine(odometry, cell_of)
        r, c = view.centre
        filled = view.blocked.copy()
        filled[r, c] = True
        open_sites = view.open_sites.copy()
        open_sites[r, c] = False
        after = MapView(open_sites, view.fresh_sites & open_sites, view.filled_sites, filled, view.free_bricks,
                        view.centre)
        return self._unsafe_cue(after, mine, self._cued(after, mine), odometry)

    def _supply(self, view: MapView, mine, odometry: np.ndarray, offset_of) -> Mark | None:
        """A supply cue where free bricks lie, if it has none out; if the one it has is dry
        (no free brick beside it on the map) and bricks lie elsewhere, the dry one comes off
        first (if within reach), so that the supply moves to them."""
        n = view.open_sites.shape[0]
        out = [k for k, (_, kind) in enumerate(mine) if kind == "supply"]
        cell = supply_cell(view, self.cfg.reach, self.cfg.supply_clearance)
        if not out:
            return None if cell is None else self._put(cell, "supply", odometry, offset_of)
        k = out[0]
        (r, c), _ = mine[k]
        if cell is None or cell == (r, c) or not (0 <= r < n and 0 <= c < n) or not _dry(view, r, c):
            return None
        x, y, _ = self.cues[k]
        if math.hypot(x - odometry[0], y - odometry[1]) > self.cfg.reach:
            return None
        return self._take_off(k, odometry)

    @staticmethod
    def _cued(view: MapView, mine) -> np.ndarray:
        """Its site cues on the map, as a grid."""
        cued = np.zeros_like(view.open_sites)
        for (r, c), kind in mine:
            if kind == "site" and 0 <= r < cued.shape[0] and 0 <= c < cued.shape[1]:
                cued[r, c] = True
        return cued

    def _unsafe_cue(self, view: MapView, mine, cued: np.ndarray, odometry: np.ndarray) -> Mark | None:
        """Take off a site cue if the marked set is no longer safe as a whole. It was when each
        cue went out, but sites filled since (by this foreman's own building, which knows
        nothing of the cues, or by anyone) can leave an open site reachable only through
        marked ones, which workers may fill first. The cue taken is the latest whose going
        makes the set safe again, else the latest: the next decisions go on until it is.
        Only a cue within reach can be taken (the world ignores a farther one): with none,
        nothing is done now."""
        if not cued.any() or marking_is_safe(view, cued):
            return None
        n = cued.shape[0]
        sites = [k for k, ((r, c), kind) in enumerate(mine) if kind == "site" and 0 <= r < n and 0 <= c < n
                 and math.hypot(self.cues[k][0] - odometry[0], self.cues[k][1] - odometry[1]) <= self.cfg.reach]
        if not sites:
            return None
        chosen = sites[-1]
        for k in reversed(sites):
            trial = cued.copy()
            trial[mine[k][0]] = False
            if marking_is_safe(view, trial):
                chosen = k
                break
        return self._take_off(chosen, odometry)

    def _mine(self, odometry: np.ndarray, cell_of) -> list[tuple[tuple[int, int], str]]:
        """Its cues as (map cell, kind), in the order they went out."""
        return [(cell_of(x - odometry[0], y - odometry[1]), kind) for x, y, kind in self.cues]

    def _take_off(self, k: int, odometry: np.ndarray) -> Mark:
        """Forget its `k`-th cue and unmark it (the caller checked it is within reach)."""
        x, y, kind = self.cues.pop(k)
        self.unmarks += 1
        return Mark("unmark", x - odometry[0], y - odometry[1], kind)

    def _put(self, cell: tuple[int, int], kind: str, odometry: np.ndarray, offset_of) -> Mark:
        dx, dy = offset_of(*cell)
        self.cues.append((float(odometry[0] + dx), float(odometry[1] + dy), kind))
        self.marks += 1
        return Mark("mark", float(dx), float(dy), kind)


def _beside(cells: np.ndarray) -> np.ndarray:
    """Cells with a 4-neighbour in `cells`."""
    out = np.zeros_like(cells)
    out[1:] |= cells[:-1]
    out[:-1] |= cells[1:]
    out[:, 1:] |= cells[:, :-1]
    out[:, :-1] |= cells[:, 1:]
    return out


def _dry(view: MapView, r: int, c: int) -> bool:
    """No free brick in the 8 cells round (r, c) (a supply cue's cell) on the map."""
    return not view.free_bricks[max(r - 1, 0):r + 2, max(c - 1, 0):c + 2].any()

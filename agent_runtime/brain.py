"""One agent's decision step (paper §4): sense, map, plan, select, act. No bus here.

Per frame: shift the ESMs by the odometry and write what the sensors report; update the
motivations; build the configuration and brick navigation maps from the ESMs (§4.2.3),
with goal sequencing (§6, ConAg-TS, unless `AgentConfig.goal_sequencing` is off) choosing
which sites and bricks excite them; read the six internal state nodes off them (§4.3, §5);
then select by fixed priority
(§4.4): eat/drink > avoid > approach food/water > the construction network of Fig. 8.
The result is a motor command and the Decision the teacher watches.

Additions for worlds nobody tuned for (each documented where it is made):
- the blueprint is never forgotten (`far_memory.FarMemory`): sites beyond the map, and
  bricks that scrolled off it, enter the navigation maps at the border with the distance
  that remains;
- fixed obstacles and the world's edge are sensed (the OBSTACLE layer) and never entered;
- Explore is the default behaviour when no construction output fires (§4.1: it "is
  always excited");
- an agent that makes no headway for `stuck_ticks` (two agents avoiding each other, a
  body pushing into something) backs off in a random direction for a random while, so
  agents that block each other separate within a bounded number of ticks;
- for big teams, off by default (issue 36): goals another agent in sight takes first are
  left to it (`claims`), an agent with nothing to fetch waits near the supply, and a
  searching agent leaves unseen ground nearer another agent to it.

With `AgentConfig.anchor_maps` (off by default) the belief of where the agent is follows
the landmarks it knows, structure bricks and the world's edge, so the maps stay true under
odometry noise (`anchoring`).
"""

from __future__ import annotations

import math
from collections import Counter, deque
from dataclasses import dataclass

import numpy as np
from numba import njit

from agent_runtime import steering
from agent_runtime.anchoring import Anchor, Landmarks, Relocaliser, edge_ring
from agent_runtime.brick_news import NEWS_EVERY, gone_cells, report, seen_cells
from agent_runtime.brick_news import cells as news_cells
from agent_runtime.claims import claimed_by_others
from agent_runtime.config import AgentConfig
from agent_runtime.esm import AGENT, BRICK, CONFIG, FOOD, OBSTACLE, WATER, EgocentricMaps, Sensing, map_extent
from agent_runtime.far_memory import FarMemory, on_border
from agent_runtime.field_cache import FieldCache
from agent_runtime.matching import Matching, calculate_matching, select_goals
from agent_runtime.motivations import Motivations
from agent_runtime.nav_inputs import NavInputs, nav_inputs, nm_obstacles, step_marks
from agent_runtime.network import NONE, STATE_NODES, ActionNetwork, engineered
from agent_runtime.seal_guard import SealGuard
from agent_runtime.sealing import dilate, enclosed_sites, pocket_beside
from agent_runtime.spreading import gradient_step, readonly
from protocol.messages import (
    BEHAVIOURS,
    CHANNELS,
    MAX_NEWS_CELLS,
    NO_READING,
    AgentState,
    BrickNews,
    Decision,
    SensorFrame,
    Welcome,
)

_CH = {name: CHANNELS.index(name) for name in CHANNELS}


@dataclass(frozen=True)
class Step:
    """What one decision step produced."""

    speed: float
    turn: float
    action: str          # for the world: none, grab, drop, eat, drink (a foreman's also mark, unmark)
    behaviour: str       # the motor behaviour that won
    decision: Decision | None  # for the teacher (None: a mind without a construction network, a worker)
    mark: tuple[float, float, str] | None = None  # mark / unmark: (dx, dy) world units from the body, cue kind


@dataclass(frozen=True)
class Plans:
    """The navigation maps of one step, as distance fields (inf: unreachable)."""

    config: np.ndarray
    brick: np.ndarray
    config_goals: np.ndarray
    brick_goals: np.ndarray
    nearest_brick: tuple[float, float, float] | None  # (dx, dy, distance) in cells, or None
    matching: Matching | None = None  # the Matching grid (goal sequencing), None when it is off
    config_obstacles: np.ndarray | None = None  # the obstacles each field was computed with
    brick_obstacles: np.ndarray | None = None


# Behaviours during which standing still is the point: eating and drinking only. Every
# other behaviour means to move, so no headway during it is a deadlock whatever caused it,
# and `_unstick` breaks it: approaching food or water too (as a source seen a cell off now
# and then flips the way to it: an agent turned back and forth beside a gap in a wall for
# 9,000 ticks, gen-letter 109).
_STILL_IS_FINE = frozenset({"eat", "drink"})
# The field cache's slots (`field_cache`) of the configuration and brick NMs, of their
# plain fallbacks and of the needs' fields (by ESM layer).
_NM_SLOTS = ("config", "brick")
_PLAIN_SLOTS = ("plain config", "plain brick")
_NEED_SLOTS = {FOOD: "food", WATER: "water"}
# Cells by which a brick must be nearer than touching to count as one the body stands on.
_OVERLAP_MARGIN = 0.2


class Brain:
    """One agent's mind: its maps, plans and action selection, stepped once per sensor frame.

    Built from the world's Welcome (pose, blueprint, sensor layout); `step(frame)` returns
    the motor command and the Decision. `set_blueprint` takes a changed blueprint;
    `state_report` says what the agent is doing and what blocks it.
    """

    def __init__(self, welcome: Welcome, cfg: AgentConfig | None = None,
                 rng: np.random.Generator | None = None, network: ActionNetwork | None = None):
        self.cfg = cfg or AgentConfig()
        self.agent_id = welcome.agent_id
        self.cell = welcome.cell_size
        self.sensor_range = welcome.sensor_range / welcome.cell_size
        self.sectors = welcome.sectors
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.network = network or engineered()
        # The attach cell, in world cells: the origin of the agent's odometry frame.
        self._origin = np.floor(np.array([welcome.x, welcome.y]) / welcome.cell_size).astype(np.int64)
        bounds = self._world_bounds(welcome)
        self.size = map_extent(self.cfg.map_size, bounds)   # cells per side of every map
        self.maps = EgocentricMaps(self.size, Sensing.of(self.cfg), occluding=welcome.occlusion)
        self.maps.seed_blueprint(welcome.x, welcome.y, welcome.site_xs, welcome.site_ys, welcome.cell_size)
        self.far = FarMemory(self.size, self._site_cells(welcome.site_xs, welcome.site_ys), bounds,
                             remember=self.cfg.far_memory)
        self.blueprint_version = welcome.blueprint_version
        self.far.config_layer(self.maps.maps[CONFIG])
        self.behaviour = NONE
        self.behaviour_ticks: Counter[str] = Counter()
        # The last `stuck_ticks` positions (a ring) and whether the agent meant to move.
        self._trail = np.zeros((max(self.cfg.stuck_ticks, 1), 2))
        self._trail_len = 0
        self._trail_next = 0
        self._moving: deque[bool] = deque(maxlen=self.cfg.stuck_ticks)
        self._still = 0   # how many of `_moving` are False (so `all` needs no pass over it)
        self._odo = np.zeros(2)            # dead-reckoned position in cells (for headway)
        self._unstick_left = 0             # ticks of backing off still to go
        self._unstick_heading = 0.0
        self._leg_heading = 0.0            # the current straight leg of Explore ...
        self._leg_left = 0                 # ... and the ticks it has to go
        self._idle = 0                     # ticks waited in a row (`idle_wait`)
        self._waited = False               # whether this step waited (`_wait`) ...
        self._standing = False             # ... and stood still doing so
        self.unsticks = 0                  # how often it had to back off
        self.searched = 0                  # squares of the world first seen while searching for bricks
        self._tick = welcome.tick
        self.motivations = Motivations()
        self.centre = self.size // 2
        self.seals = SealGuard(self.maps, self.far, self.centre)
        # Food and water remembered beyond the map that came back onto it and are not seen
        # again yet (a sector sees only the nearest disc of a wall). What was seen stays
        # until seen otherwise, so they are in the way of paths; but a need acts only on
        # what is seen (a disc remembered may be gone), so they are never a need's goal.
        # Forgotten, a water wall longer than the map is open ground again each time it
        # comes back, and agents walk to it, along it and back (as in gen-multi 025).
        self._recalled = np.zeros((self.size,) * 2, bool)
        self._attach_tick = welcome.tick
        self.plans: Plans | None = None
        self.fields = FieldCache()   # navigation maps, computed again only when their inputs change
        self._layers: np.ndarray | None = None  # the maps thresholded at 0.5, during a step
        self._marks: np.ndarray | None = None   # the same, as `perceive` left them, for the step
        # The last step's marks: `step_marks` hands them back when nothing changed, so
        # whatever is worked out from the marks alone is known unchanged by identity.
        self._last_marks: np.ndarray | None = None
        self._need_fields: dict[int, tuple[np.ndarray, np.ndarray]] = {}  # layer -> (marks, field)
        self._enclosed: tuple[bytes, np.ndarray | None] | None = None  # (inputs, result) of the last check
        self._matching: tuple[bytes, Matching] | None = None  # (inputs, result) of the last matching
        self._inputs: tuple[np.ndarray, NavInputs] | None = None  # (the step's marks, `nav_inputs` of them)
        # The last inputs made: handed back by `nav_inputs` while unchanged, so what is made
        # from them alone is kept by identity (`_sequenced_goals`, the NMs' obstacles).
        self._last_inputs: NavInputs | None = None
        self._sequenced_kept: tuple[tuple, np.ndarray, np.ndarray] | None = None
        self._obstacles_kept = _KeptForTwo()   # `nav_masks`: the NM obstacles by their inputs
        self._less_kept = _KeptForTwo()        # `_goals_less`: the result by its inputs
        self._empty: np.ndarray | None = None   # an empty map mask, read-only
        self._supply_kept: tuple[tuple[int, int] | None, np.ndarray, np.ndarray] | None = None  # `_supply`
        self._taken_from: np.ndarray | None = None  # (dx, dy) cells to where the held brick was taken
        self._dropped_at: np.ndarray | None = None  # odometry (cells) where it last dropped, until off it
        self._drop_unseen = False  # that drop was before this brain started (`_brick_underfoot`)
        self._took: list[np.ndarray] = []  # `share_bricks`: world cells of bricks taken since the last news
        # ... and the cells its sensors see now (the news is of bricks seen, not remembered)
        self._in_sight = _disc_mask(self.size, self.sensor_range - 1.0) if self.cfg.share_bricks else None
        # Centre to centre, in cells, at which the world lets a dropped brick hold this body again.
        self._release = (welcome.agent_radius + welcome.disc_radius) / welcome.cell_size
        # `anchor_maps`: the belief of where the agent is, kept true by landmarks it sees.
        self.anchor = Anchor() if self.cfg.anchor_maps else None
        self.relocaliser = (Relocaliser(self.anchor.cfg, welcome.sectors, self.sensor_range, welcome.occlusion)
                            if self.anchor is not None and self.anchor.cfg.relocalise else None)
        self._edge = edge_ring(self.far.bounds)

    @property
    def odometry(self) -> np.ndarray:
        """Where the agent is in its odometry frame: cells from where it attached (a copy)."""
        return self._odo.copy()

    # sensing and planning --------------------------------------------------------------
    def perceive(self, frame: SensorFrame) -> np.ndarray:
        """Update maps and motivations from a frame; returns its readings as (channels, sectors)."""
        # In cells from here on; without the obstacle layer the paper's ESMs map discs only,
        # so no wall reading is kept.
        ranges = _readings_in_cells(np.asarray(frame.ranges, dtype=np.float64), len(CHANNELS), self.cell,
                                    -1 if self.cfg.obstacle_layer else _CH["obstacle"])
        self._tick = frame.tick
        if frame.tick > self._attach_tick:  # the attach pose already includes the last move
            odo = self._odo   # element by element: no array made from the pair each step
            odo[0] += frame.odom_dx / self.cell
            odo[1] += frame.odom_dy / self.cell
            self._shift_belief(frame.odom_dx, frame.odom_dy)
            if self.anchor is not None:
                self.anchor.predict(math.hypot(frame.odom_dx, frame.odom_dy) / self.cell)
        self._track_source(frame)
        if self.anchor is not None:
            self._anchor_maps(ranges)
        self.maps.sense(ranges, self.sensor_range)
        # The world's edge is a wall; recalled discs on cells seen free since are gone
        # (eaten, moved); the maps as marks: what the step reads (`layers`).
        outside = self.far.outside_world() if self.cfg.obstacle_layer else None
        marks, open_sites, walls = step_marks(self.maps.maps, outside, self._recalled, self.maps.known,
                                              self._last_marks)
        self.far.observe_sites(self.maps.maps[BRICK], self.maps.clear_age)
        self.far.age_sites(self.maps.clear_age)
        enclosed = self._enclosed_sites(open_sites, walls) if self.cfg.enclosed_sites else None
        if enclosed is not None:
            self.maps.maps[BRICK][enclosed] = 1.0
            if not marks.flags.writeable:   # the last step's marks (unchanged since): read-only
                marks = marks.copy()
            marks[BRICK] |= enclosed
            self.far.observe_sites(self.maps.maps[BRICK], self.maps.clear_age)
        self._marks = self._last_marks = marks
        new = self.far.mark_seen(self.sensor_range - 1.0)
        if self.searching():
            self.searched += new
        self.motivations.update(self.cfg, frame.ate, frame.drank)
        return ranges

    def _shift_belief(self, dx: float, dy: float) -> None:
        """Dead reckoning: the agent believes it moved (dx, dy) world units. The maps shift
        by the whole cells crossed, and the far memory with them (what leaves the map is
        remembered, what comes back onto it is written in again; without `far_memory`, as
        in the paper, what shifts off the maps is gone)."""
        if not self.cfg.far_memory:
            kx, ky = self.maps.move(dx, dy, self.cell)
            self.far.move(kx, ky, None)   # only the agent's cell
            self.fields.moved(ky, -kx)   # the maps' contents move the other way
            return
        layers = self.maps.maps
        kx, ky = self.maps.crossing(dx, dy, self.cell)
        if not (kx or ky):   # 6 steps in 7 or so: the maps only slide within the cell
            self.maps.move(dx, dy, self.cell)
            return
        free = (layers[BRICK] > 0.5) & (layers[CONFIG] <= 0.5)
        walls = layers[OBSTACLE] > 0.5
        discs = (layers[FOOD] > 0.5) | (layers[WATER] > 0.5)
        ground = self.maps.known & ~walls & ~discs      # before the maps shift
        kx, ky = self.maps.move(dx, dy, self.cell)   # the cells `crossing` said
        self.fields.moved(ky, -kx)   # the maps' contents move the other way
        self.far.save_walls(walls, discs | self._recalled, ground)
        back = self.far.move(kx, ky, free)
        layers[BRICK][back] = 1.0
        layers[OBSTACLE][self.far.load_walls()] = 1.0
        self.far.config_layer(layers[CONFIG])
        self._recalled = self.far.load_discs()

    def _anchor_maps(self, ranges: np.ndarray) -> None:
        """`anchor_maps`: move the belief of where the agent is by what the landmarks it
        sees say (`anchoring`), before this frame is written into the maps, so that its
        readings land where the blueprint's sites are drawn."""
        assert self.anchor is not None
        landmarks = Landmarks(self.far.sites, ~self.far.site_open, self._edge)
        if self.relocaliser is not None:
            jump = self.relocaliser.update(ranges, self.believed_cells(), landmarks)
            if jump.any():
                self._shift_belief(float(jump[0]) * self.cell, float(jump[1]) * self.cell)
        fix = self.anchor.correct(ranges, self.believed_cells(), landmarks)
        if fix.any():
            self._shift_belief(float(fix[0]) * self.cell, float(fix[1]) * self.cell)

    def believed_cells(self) -> np.ndarray:
        """Where the agent believes it is: cells from its attach cell's centre (a new array)."""
        return self.far.pos.astype(np.float64) + self.maps.frac

    def layers(self) -> np.ndarray:
        """The maps as marks (> 0.5), one bool grid per layer: within `step`, worked out once
        after perceiving (nothing changes the maps until the step ends); outside it, anew."""
        if self._layers is not None:
            return self._layers
        return self.maps.maps > 0.5

    def _enclosed_sites(self, open_sites: np.ndarray, walls: np.ndarray) -> np.ndarray | None:
        """Open sites on the map that no way reaches (`sealing.enclosed_sites`): believed filled
        (None: none). `open_sites`, `walls`: as `step_marks` gives them. Worked out again
        only when they changed (read-only)."""
        key = open_sites.tobytes() + walls.tobytes()
        if self._enclosed is None or self._enclosed[0] != key:
            found = enclosed_sites(open_sites, walls, (self.centre, self.centre))
            found.setflags(write=False)
            self._enclosed = (key, found if np.count_nonzero(found) else None)
        return self._enclosed[1]

    # the blueprint ------------------------------------------------------------------------
    def _site_cells(self, xs, ys) -> np.ndarray:
        """World site coordinates -> cells (x, y) relative to the attach cell."""
        cells = np.floor(np.column_stack([np.asarray(xs, np.float64), np.asarray(ys, np.float64)]) / self.cell)
        return cells.astype(np.int64).reshape(-1, 2) - self._origin

    def _world_bounds(self, welcome: Welcome) -> tuple[int, int, int, int] | None:
        """The world's cells relative to the attach cell, (x0, y0, x1, y1), if it said."""
        if welcome.world_width <= 0 or welcome.world_height <= 0:
            return None
        w, h = (round(v / self.cell) for v in (welcome.world_width, welcome.world_height))
        return -int(self._origin[0]), -int(self._origin[1]), w - int(self._origin[0]), h - int(self._origin[1])

    def set_blueprint(self, version: int, site_xs, site_ys) -> bool:
        """A changed blueprint from the world (a `Blueprint` message); older versions are
        ignored. Returns whether it was taken. The agent replans from its next step."""
        if version <= self.blueprint_version:
            return False
        self.blueprint_version = version
        self.far.set_sites(self._site_cells(site_xs, site_ys))
        self.far.config_layer(self.maps.maps[CONFIG])
        self._matching = self._sequenced_kept = None
        return True

    def _track_source(self, frame: SensorFrame) -> None:
        """Remember where the held brick came from, by odometry, while it is held."""
        if not frame.holding:
            self._taken_from = None
        elif self._taken_from is None:
            near = self.plans.nearest_brick if self.plans is not None else None
            self._taken_from = np.array(near[:2] if near is not None else (0.0, 0.0))
            if self.cfg.share_bricks:
                self._took.append(self._world_cell(*self._taken_from))
        else:
            self._taken_from[0] -= frame.odom_dx / self.cell
            self._taken_from[1] -= frame.odom_dy / self.cell

    def _world_cell(self, ox: float, oy: float) -> np.ndarray:
        """The world cell (x, y) of the point at offset (ox, oy) cells from the agent."""
        row, col = self.maps.cell_of(ox, oy)
        return self.far.from_map(np.array([row]), np.array([col]))[0] + self._origin

    def brick_news(self) -> BrickNews | None:
        """`share_bricks`: this agent's report to the others, every NEWS_EVERY ticks after a
        step (else None): the free bricks in sight and those it took since its last report,
        in world cells, with the brick it heads for while it holds none
        (agent_runtime.brick_news). Only bricks in sight: a remembered one,
        or one heard of, may be gone, and told on it would go round the team for ever."""
        if not self.cfg.share_bricks or self._last_marks is None or self._tick % NEWS_EVERY:
            return None
        marks = self._last_marks
        rows, cols = np.nonzero(marks[BRICK] & ~marks[CONFIG] & self._in_sight)
        seen = self.far.from_map(rows[:MAX_NEWS_CELLS], cols[:MAX_NEWS_CELLS]) + self._origin
        taken = news_cells(self._took[-MAX_NEWS_CELLS:])
        self._took = []
        near = self.plans.nearest_brick if self.plans is not None and self._taken_from is None else None
        claimed = news_cells([] if near is None else [self._world_cell(near[0], near[1])])
        return report(self.agent_id, max(self._tick, 0), seen, taken, claimed)

    def hear_bricks(self, news: BrickNews) -> None:
        """`share_bricks`: another agent's report, remembered (agent_runtime.brick_news)."""
        if self.cfg.share_bricks and news.agent_id != self.agent_id:
            self.far.hear(seen_cells(news) - self._origin, gone_cells(news) - self._origin)

    def _supply(self) -> np.ndarray:
        """The matching's extra supply, as a read-only mask: the held brick's source
        (`_source_cell`) and the remembered bricks beyond the map (`_supply_beyond`). Kept
        until the source's cell or the remembered bricks change (most steps neither does)."""
        src = self.maps.cell_of(*self._taken_from) if self._taken_from is not None else None
        far = self.far.far_bricks()   # the far memory's array, replaced whenever it changes
        if self._supply_kept is None or self._supply_kept[0] != src or self._supply_kept[1] is not far:
            mask = self._source_cell(src) | self._supply_beyond(far)
            mask.setflags(write=False)
            self._supply_kept = (src, far, mask)
        return self._supply_kept[2]

    def _source_cell(self, cell: tuple[int, int] | None) -> np.ndarray:
        """The cell the held brick was taken from (`cell`, None when not holding), as a
        mask; when it lies beyond the map, the border cell towards it.

        The matching must protect the ways from the supply even when no free brick is in
        view, and where the held brick came from is the best-known supply: more bricks are
        likely there, and future bricks will come that way. While an agent carries a brick
        it may know no free brick at all (the last one in view is in its hand, or another
        agent took it); without a source the Matching grid protects no path, and the
        nearest site is filled even where it walls off another (as in Fig. 18 with several
        agents).
        """
        mask = np.zeros((self.size,) * 2, bool)
        if cell is not None:
            mask[on_border(np.array([cell]), self.size)] = True
        return mask

    def _supply_beyond(self, far: np.ndarray) -> np.ndarray:
        """Remembered bricks beyond the map (`far`, (k, 2) rows and cols), as the border
        cells towards them (a mask).

        The Matching grid only holds the map: with the supply 50 cells away it would hold
        no brick, protect no path, and sites would be filled nearest-first even where that
        walls off others. Bricks beyond the border enter it at the border, as they enter
        the brick NM."""
        mask = np.zeros((self.size,) * 2, bool)
        if len(far):
            mask[on_border(far, self.size)] = True
        return mask

    def nav_masks(self, sequenced: bool = True) -> tuple[tuple[np.ndarray, np.ndarray], tuple[np.ndarray, np.ndarray]]:
        """(goals, obstacles) of the configuration NM and of the brick NM (paper §4.2.3, Fig. 5).

        The configuration NM is excited by the configuration ESM and inhibited by the food,
        water and brick ESMs; the brick NM is excited by the brick ESM and inhibited by food,
        water and the bricks that are part of the structure. With goal sequencing on (and
        `sequenced`), the Matching grid also inhibits the sites that would block another
        pair's path and leaves only the matched bricks as brick goals (§6.2); the matching
        counts the held brick's source as a brick and avoids crossing sites not seen open
        for `site_memory` ticks. With goal sequencing on, sequenced or not, a site near the
        agent whose brick would seal another off (`sealing`) is no goal either. Other
        agents in sight are obstacles on both maps.
        """
        m = self.layers()
        # Plan round whatever is in the way now: fixed obstacles (walls, the world's edge)
        # exactly as food and water, and other agents in sight (`agents_as_obstacles`), since
        # a plan through a body leads into it (as two agents heading opposite ways down a
        # one-cell corridor meet, back off and meet again, for ever).
        i = self._nav_inputs(m)
        config_goals, brick_goals, obstacles = i.config_goals, i.brick_goals, i.obstacles
        open_sites = config_goals
        supply_bricks = i.supply_bricks
        # Sequencing narrows the goals only where it has pairs to protect: with no open site
        # on the map the Matching grid pairs nothing, and taking any free brick blocks no
        # one's path, so every free brick stays a goal. Left to the matching, none would be:
        # the brick NM would follow a remembered brick beyond the border and turn back each
        # time the sites came onto the map, a cell's step either side of the map's edge,
        # for ever (as in gen-polyomino 134).
        if sequenced and self.cfg.goal_sequencing and i.any_open:
            config_goals, brick_goals = self._sequenced_goals(i)
        if self.cfg.goal_sequencing and self.cfg.seal_guard:
            # Also when sequencing gives way (plan's fallback): no site that seals another.
            unsafe = self.seals.unsafe(config_goals, open_sites, obstacles, supply_bricks, self._tick)
            if np.count_nonzero(unsafe):
                config_goals = self._goals_less(config_goals, unsafe)
        if self.cfg.yield_goals:
            brick_goals = self._yield(brick_goals)
            if self._taken_from is not None:
                config_goals = self._yield(config_goals)
        # Bricks that are not goals (the structure's, and with sequencing the unmatched free
        # ones) are in the way: a path must not lead through one to a matched brick beyond.
        read = (m, i.in_the_way, brick_goals)   # kept for two: sequenced, then plain goals
        both = self._obstacles_kept.get(read)
        if both is None:
            both = nm_obstacles(i.in_the_way, m[BRICK], brick_goals, self.centre)
            for mask in both:
                mask.setflags(write=False)
            self._obstacles_kept.put(read, both)
        config_obstacles, brick_obstacles = both
        return (config_goals, config_obstacles), (brick_goals, brick_obstacles)

    def _goals_less(self, goals: np.ndarray, unsafe: np.ndarray) -> np.ndarray:
        """`goals & ~unsafe`, read-only, the same object while both are (kept for the last
        two: a plain-fallback step asks twice), so the field cache knows it by identity."""
        less = self._less_kept.get((goals, unsafe))
        if less is None:
            less = goals & ~unsafe
            less.setflags(write=False)
            self._less_kept.put((goals, unsafe), less)
        return less

    def _sequenced_goals(self, i: NavInputs) -> tuple[np.ndarray, np.ndarray]:
        """(site goals, brick goals) with goal sequencing (§6.2): the Matching grid's, less
        the sites on the mouth side of a held-open path (`mouth_side`). A function of five
        of the step's `NavInputs` masks alone (not of where other agents are), so kept
        (read-only) while those are the same objects (`nav_inputs`)."""
        read = (i.supply_bricks, i.config_goals, i.obstacles, i.closed, i.brick_goals)
        kept = self._sequenced_kept
        if kept is not None and _same_objects(kept[0], read):
            return kept[1], kept[2]
        matching = self.matching(i.supply_bricks, i.config_goals, i.obstacles, i.closed)
        config_goals, brick_goals = select_goals(matching, i.brick_goals, i.config_goals)
        held = i.config_goals & ~config_goals
        if self.cfg.mouth_side and np.count_nonzero(held):
            # Closed sites are passable for this: the depth of a site behind one must
            # stay finite, or every site would count as "no deeper" than its neighbour.
            # Asked as the matching asks for its step 1 (bricks on obstacles are no goals
            # either way), so with no site closed the cache holds it already.
            depth = self.fields.distance(i.supply_bricks & ~i.obstacles, i.obstacles, "depth")
            config_goals &= ~_mouth_side(held, config_goals, depth)
        config_goals.setflags(write=False)
        brick_goals.setflags(write=False)
        self._sequenced_kept = (read, config_goals, brick_goals)
        return config_goals, brick_goals

    def _yield(self, goals: np.ndarray) -> np.ndarray:
        """`goals` less those another agent in sight takes first (`claims`), unless that
        leaves none: two agents heading for one brick cost the loser its walk, and a
        guess about the others must never leave this one with nothing to do."""
        others = self.layers()[AGENT]
        if not goals.any() or not others.any():
            return goals
        c, frac = self.centre, self.maps.frac
        left = goals & ~claimed_by_others(goals, others, c - float(frac[1]), c + float(frac[0]))
        return left if left.any() else goals

    def _nav_inputs(self, m: np.ndarray) -> NavInputs:
        """`nav_inputs` of the marks `m`, made once per step (`m` is the step's own array)."""
        if self._inputs is None or self._inputs[0] is not m:
            extra = self._supply() if self.cfg.goal_sequencing and self.cfg.supply_beyond else self._no_supply()
            self._last_inputs = nav_inputs(m, self._recalled, extra, self.maps.clear_age, self.cfg.site_memory,
                                           self.cfg.agents_as_obstacles, self.cfg.closed_sites, self.centre,
                                           self._last_inputs)
            self._inputs = (m, self._last_inputs)
        return self._inputs[1]

    def _no_supply(self) -> np.ndarray:
        if self._empty is None:
            self._empty = np.zeros((self.size,) * 2, bool)
            self._empty.setflags(write=False)
        return self._empty

    def matching(self, bricks: np.ndarray, sites: np.ndarray, obstacles: np.ndarray,
                 closed: np.ndarray | None = None) -> Matching:
        """calculateMatching on the current maps, recomputed only when its inputs change
        (a brick moved, a site filled or went out of sight, the maps shifted by a cell)."""
        closed = np.zeros_like(sites) if closed is None else closed
        key = b"".join(np.ascontiguousarray(g, dtype=np.bool_).tobytes() for g in (bricks, sites, obstacles, closed))
        if self._matching is None or self._matching[0] != key:
            self._matching = (key, calculate_matching(bricks, sites, obstacles, closed, self.fields.distance))
        return self._matching[1]

    def plan(self) -> Plans:
        """Configuration and brick NMs from the ESMs, as distance fields.

        Goal sequencing gives way to the plain goals of §4 where that cannot block anyone:
        on the brick NM when no matched brick is reachable (taking any free brick blocks
        nothing), on the configuration NM only when it leaves no site at all (every open
        site on another's path: a loop, which must not stall the agent). A selected site
        out of reach for now (another agent in the corridor) is waited for, not replaced by
        one that would wall it off.
        """
        fields = []
        far = (self.far.far_open_sites(), self.far.far_bricks())
        m = self.layers()
        # Sequencing applies only with an open site on the map (`nav_masks`); without one
        # the plain masks are the very ones just made, so they are not made again.
        sequenced = self.cfg.goal_sequencing and self.cfg.sequencing_fallback and self._nav_inputs(m).any_open
        plain = None
        for k, (goals, obstacles) in enumerate(self.nav_masks()):
            field = self._field(goals, obstacles, far[k], _NM_SLOTS[k])
            stuck = not (np.count_nonzero(goals) or len(far[k])) if k == 0 else self._no_brick_here(goals, field)
            if sequenced and stuck:
                if plain is None:
                    plain = self.nav_masks(sequenced=False)
                goals, obstacles = plain[k]
                field = self._field(goals, obstacles, far[k], _PLAIN_SLOTS[k])
            fields.append((field, goals, obstacles))
        (config, config_goals, config_obstacles), (brick, brick_goals, brick_obstacles) = fields
        matching = self._matching[1] if self.cfg.goal_sequencing and self._matching else None
        self.plans = Plans(config, brick, config_goals, brick_goals, self._nearest(brick_goals), matching,
                           config_obstacles, brick_obstacles)
        return self.plans

    def _no_brick_here(self, goals: np.ndarray, field: np.ndarray) -> bool:
        """Whether sequencing leaves the brick NM no brick to go to: none reachable, or
        none on the map while free bricks lie on it.

        The second case: the matching holds only the map, so a free brick on it that it
        pairs with no site tells where the map ends, not that the brick is not needed; and
        taking a free brick blocks no one's path. So the bricks in view are goals before
        remembered ones far off. Left to the matching, a way from these bricks to the sites
        that leads round beyond the border pairs none of them; the brick NM follows bricks
        far away until a step brings a site back onto the map, the bricks here are paired
        again and it turns back, a cell's step either side of the map's edge (as in
        gen-nested_rings 11260025)."""
        if not np.isfinite(field[self.centre, self.centre]):
            return True
        return not np.count_nonzero(goals) and bool(np.count_nonzero(self._nav_inputs(self.layers()).brick_goals))

    def _field(self, goals: np.ndarray, obstacles: np.ndarray, beyond: np.ndarray, slot: str) -> np.ndarray:
        """Distance field to `goals` and to the remembered cells `beyond` the map, which
        enter at the border carrying the distance that remains (`slot`: the field cache's)."""
        seed = self.far.border_costs(beyond, obstacles)
        if seed is None:
            return self.fields.distance(goals, obstacles, slot)
        seed[goals & ~obstacles] = 0.0
        return self.fields.seeded(seed, obstacles, slot)

    def _nearest(self, cells: np.ndarray) -> tuple[float, float, float] | None:
        """Offset and straight-line distance (cells) to the nearest marked cell, or None
        (the first in row order on a tie)."""
        frac = self.maps.frac
        found, row, col = _nearest_cell(readonly(cells), self.centre, float(frac[0]), float(frac[1]))
        if not found:
            return None
        dx, dy = self.maps.offset_of(row, col)
        return float(dx), float(dy), float(np.hypot(dx, dy))

    def _free_centre(self, obstacles: np.ndarray) -> np.ndarray:
        # The agent stands in the centre cell, sometimes on a brick it just dropped: its
        # own cell is never an obstacle, or it could not plan a way out.
        obstacles[self.centre, self.centre] = False
        return obstacles

    def state_nodes(self, frame: SensorFrame, plans: Plans) -> np.ndarray:
        """The six internal state nodes, in STATE_NODES order (0 or 1)."""
        c = self.centre
        near_centre = math.hypot(self.maps.frac[0], self.maps.frac[1]) <= self.cfg.drop_centering
        values = {
            "holding_brick": frame.holding,
            "at_drop_site": bool(plans.config_goals[c, c]) and near_centre,
            "at_brick": self._brick_within(plans, self.cfg.reach) is not None,
            "near_brick": self._brick_within(plans, self.cfg.near_brick) is not None,
            "brick_available": plans.brick[c, c] < math.inf,
            "drop_site_available": plans.config[c, c] < math.inf,
        }
        return np.array([float(values[n]) for n in STATE_NODES])

    @staticmethod
    def _brick_within(plans: Plans, within: float) -> tuple[float, float] | None:
        """Offset (cells) to the nearest available brick if it is within `within`."""
        near = plans.nearest_brick
        return (near[0], near[1]) if near is not None and near[2] <= within else None

    # deciding ----------------------------------------------------------------------------
    def step(self, frame: SensorFrame) -> Step:
        """One decision: perceive the frame, plan, choose, and the command that carries it out."""
        ranges = self.perceive(frame)
        self._layers, self._marks = self._marks, None   # nothing changes the maps until the step ends
        self._inputs = None   # made anew each step: they also read more than the marks
        assert self._layers is not None
        self._layers.setflags(write=False)  # shared by every reader this step
        try:
            return self._decide(frame, ranges)
        finally:
            self._layers = None

    def _decide(self, frame: SensorFrame, ranges: np.ndarray) -> Step:
        self._waited = self._standing = False
        plans = self.plan()
        state = self.state_nodes(frame, plans)
        choice = self.network.choose(state)
        speed, turn, action, behaviour = self._select(frame, ranges, plans, choice.arm, choice.motor)
        if not self._waited:
            self._idle = 0
        speed, turn, action, behaviour = self._unstick(frame, speed, turn, action, behaviour)
        if self.cfg.off_own_brick:
            speed, turn = self._off_own_brick(frame, ranges[_CH["brick"]], speed, turn)
        self.behaviour = behaviour
        self.behaviour_ticks[behaviour] += 1
        decision = Decision(self.agent_id, frame.tick, tuple(state.tolist()), choice.outputs,
                            choice.arm, choice.motor)
        return Step(speed, turn, action, behaviour, decision)

    def _off_own_brick(self, frame: SensorFrame, bricks: np.ndarray, speed: float,
                       turn: float) -> tuple[float, float]:
        """Leave a brick just dropped on the side joined to the rest of the world.

        The world lets the body pass through the brick it dropped until it is off it;
        whatever the behaviour wanted (avoid_red moves away from the brick, whichever side
        that is), a move into a pocket that brick closes (`sealing.pocket_beside`) would
        shut the agent in for good. While it is still on its brick it heads for ground
        outside the pocket, back through the brick if it had already stepped in. `bricks`:
        the frame's brick readings, in cells (`perceive`)."""
        if frame.dropped:
            # Where the body stood when it let go: before this tick's move.
            self._dropped_at = self._odo - (frame.odom_dx / self.cell, frame.odom_dy / self.cell)
            self._drop_unseen = False
        elif self._dropped_at is None:
            self._dropped_at = self._brick_underfoot(bricks)
            self._drop_unseen = self._dropped_at is not None
        if self._dropped_at is None:
            return speed, turn
        dx, dy = self._dropped_at - self._odo
        # Half a cell of slack: the brick settles on its site's centre, not where the body was.
        # And once no brick overlaps the body, the world has made this one solid again: the
        # body cannot go back through it, and heading for its far side would press into it
        # for good (a body that stepped off, then came back against it from the pocket).
        if math.hypot(dx, dy) >= self._release + 0.5 or _nearest_reading(bricks) >= self._release:
            self._dropped_at = None
            return speed, turn
        cell = self.maps.cell_of(dx, dy)
        if not self.maps.contains(*cell):
            return speed, turn
        m = self.layers()
        blocked = m[OBSTACLE] | m[FOOD] | m[WATER] | m[BRICK]
        if self._drop_unseen:
            # A brain that did not see the drop has not seen the ring either (the brick
            # underfoot hides what lies behind it): the blueprint's sites stand in for it.
            blocked |= m[CONFIG]
        blocked[cell] = False
        pocket = pocket_beside(blocked, cell)
        if not pocket.any():
            return speed, turn
        blocked[self.centre, self.centre] = False
        outside = ~blocked & ~pocket
        outside[cell] = False
        field = self.fields.distance(outside, blocked, "off own brick")
        if gradient_step(field) in (None, (0, 0)):
            return speed, turn
        return self._navigate(field, frame.heading)

    def _brick_underfoot(self, bricks: np.ndarray) -> np.ndarray | None:
        """Odometry (cells) of a brick the body overlaps, if one of the brick readings (cells,
        one per sector) shows one.

        Never shut oneself in, whenever the brain started: what the body did before, a new
        brain infers from what it senses. Only the brick an agent dropped itself lets its
        body pass, so this is one it dropped before this brain knew (a process started
        again, or a world resumed from a checkpoint, while the body was still on it), and
        leaving it is guarded as after any drop. As in nested_squares under `python3 -m
        faults.chaos`: a lone agent restarted in that moment stepped off into the inner
        ring and was shut in, at 30/32. The margin keeps a brick merely touching (the
        physics lets bodies sink in a little) from counting."""
        if _nearest_reading(bricks) >= self._release - _OVERLAP_MARGIN:
            return None
        return self._odo + self._reading_offset(bricks)

    def _unstick(self, frame, speed, turn, action, behaviour):
        """Back off in a random direction for a random while after `stuck_ticks` without
        headway (the net distance covered stays under `stuck_distance` cells).

        Two agents that block each other (each avoiding, then replanning into the other)
        or a body pressed against something it cannot see would otherwise repeat the same
        moves for ever; the random heading and length (the injected generator) break the
        symmetry, so such a deadlock lasts a bounded number of ticks.
        """
        if not self.cfg.unstick:
            return speed, turn, action, behaviour
        if self._unstick_left > 0:
            self._unstick_left -= 1
            if self._unstick_left == 0:
                self._trail_len = 0
                self._moving.clear()
                self._still = 0
            return (*steering.steer_to(math.cos(self._unstick_heading), math.sin(self._unstick_heading),
                                       frame.heading, self.cfg.cruise_speed), NONE, "unstick")
        self._trail[self._trail_next] = self._odo
        self._trail_next = (self._trail_next + 1) % len(self._trail)
        self._trail_len = min(self._trail_len + 1, self.cfg.stuck_ticks)
        moving = behaviour not in _STILL_IS_FINE and not self._standing
        if len(self._moving) == self._moving.maxlen and not self._moving[0]:
            self._still -= 1   # the oldest drops out
        self._moving.append(moving)
        self._still += not moving
        full = self._trail_len == self.cfg.stuck_ticks
        # All of the ring is the trail once full; order does not matter to its extent.
        if full and self._still == 0 and _extent(self._trail) < self.cfg.stuck_distance:
            self.unsticks += 1
            self._unstick_left = int(self.rng.integers(self.cfg.stuck_ticks // 4, self.cfg.stuck_ticks // 2 + 1))
            self._unstick_heading = float(self.rng.uniform(-math.pi, math.pi))
        return speed, turn, action, behaviour

    # reporting -----------------------------------------------------------------------------
    def state_report(self, tick: int) -> AgentState:
        """What the agent is doing and, if it is not building, why (an AgentState)."""
        return AgentState(agent_id=self.agent_id, tick=max(int(tick), 0), behaviour=self.behaviour,
                          holding=self._taken_from is not None, sites_open=self.far.open_sites(),
                          blocker=self.blocker(), behaviour_ticks=tuple(self.behaviour_ticks[b] for b in BEHAVIOURS))

    def blocker(self) -> str:
        """In words, what keeps the agent from building now ("" when nothing does)."""
        p, c = self.plans, self.centre
        if p is None:
            return "has not planned yet"
        open_sites = self.far.open_sites()
        if self._unstick_left > 0:
            return f"made no headway for {self.cfg.stuck_ticks} ticks: backing off"
        if open_sites == 0:
            return "believes every site is filled"
        holding = self._taken_from is not None
        if holding and not np.isfinite(p.config[c, c]):
            return f"holds a brick but no open site is reachable ({open_sites} believed open)"
        if self.searching():
            return "knows no free brick: exploring"
        if not holding and not np.isfinite(p.brick[c, c]):
            return "no known free brick is reachable"
        return ""

    def searching(self) -> bool:
        """Is the agent looking for bricks: holding none and knowing of none?"""
        return (self.plans is not None and self._taken_from is None and not np.count_nonzero(self.plans.brick_goals)
                and not len(self.far.bricks))

    def _select(self, frame, ranges, plans, arm, motor):
        """Fixed priority by lateral inhibition: eat/drink > avoid > approach food/water > build."""
        mot, cruise = self.motivations, self.cfg.cruise_speed
        for seeking, channel, act in ((mot.seeking_water, "water", "drink"), (mot.seeking_food, "food", "eat")):
            if seeking and _nearest_reading(ranges[_CH[channel]]) <= self.cfg.touch:
                return 0.0, 0.0, act, act
        agent_near = _nearest_reading(ranges[_CH["agent"]])
        # A loaded agent gives way to an unloaded one (most likely on its way out of the
        # structure): it backs off from farther away, so in a corridor one body wide the
        # two do not back off and meet again for ever.
        give_way = self.cfg.avoid_distance * (1.0 if frame.holding or not self.cfg.give_way else 0.5)
        if agent_near < give_way:
            dx, dy = self._reading_offset(ranges[_CH["agent"]])
            return (*steering.away_from(dx, dy, frame.heading, cruise), NONE, "avoid")
        for seeking, layer, name in ((mot.seeking_water, WATER, "approach_water"),
                                     (mot.seeking_food, FOOD, "approach_food")):
            # With no source on the maps there is nothing to approach: keep building (and
            # so moving about) until one comes into view, rather than wander for ever.
            if seeking:
                field = self._need_field(layer)
                if np.isfinite(field[self.centre, self.centre]):
                    return (*self._navigate(field, frame.heading), NONE, name)
        return (*self._construct(frame, ranges, plans, motor, arm), arm, motor if motor != NONE else "explore")

    def _need_field(self, layer: int) -> np.ndarray:
        """The way to food or water (`layer`): a function of the marks alone, so kept while
        they are the same object (`step_marks`)."""
        m = self.layers()
        kept = self._need_fields.get(layer)
        if kept is not None and kept[0] is m:
            return kept[1]
        if not m[layer].any():   # none on the map (most steps): no way, and no obstacles to make
            field = self.fields.no_way(m[layer].shape)
        else:
            others = (m[FOOD] | m[WATER] | m[BRICK] | m[OBSTACLE]) & ~m[layer]
            field = self.fields.distance(m[layer], self._free_centre(others), _NEED_SLOTS[layer])
        self._need_fields[layer] = (m, field)
        return field

    def _construct(self, frame, ranges, plans, motor, arm=NONE) -> tuple[float, float]:
        cruise = self.cfg.cruise_speed
        if arm == "grab":
            # The gripper is in front: face the free brick and close in on it slowly (the
            # world stops the body at contact, well within the gripper's reach).
            target = self._brick_within(plans, self.cfg.reach)
            return steering.steer_to(*target, frame.heading, 0.5) if target else (0.0, 0.0)
        if motor == "config_nav":
            return self._navigate(plans.config, frame.heading)
        if motor == "brick_nav":
            return self._navigate(plans.brick, frame.heading)
        if motor == "approach_red":
            target = self._brick_within(plans, self.cfg.near_brick)
            return steering.steer_to(*target, frame.heading, cruise) if target else (0.0, 0.0)
        if motor == "avoid_red":
            if (self.cfg.agents_in_the_way and _nearest_reading(ranges[_CH["agent"]]) < self.sensor_range
                    and self._agents_in_the_way(plans)):
                # A queue in a dead end clears only from its mouth: when only other agents
                # keep a site out of reach (a corridor one body wide), back away from the
                # nearest, so it can come out. Else the one inside cannot leave and the rest
                # cannot enter, for good (as four agents queued in a 31-cell corridor of
                # gen-pocket 117).
                return steering.away_from(*self._reading_offset(ranges[_CH["agent"]]), frame.heading, cruise)
            if _nearest_reading(ranges[_CH["brick"]]) < self.sensor_range:
                return steering.away_from(*self._reading_offset(ranges[_CH["brick"]]), frame.heading, cruise)
            return steering.explore(self.rng, self.cfg.explore_turn, cruise)
        # Explore is always excited (§4.1): the default when no construction output fires.
        return self._explore(frame.heading)

    def _agents_in_the_way(self, plans: Plans) -> bool:
        """Is a site out of reach only because of the other agents on the maps?"""
        if plans.config_obstacles is None:
            return False
        c = self.centre
        clear = plans.config_obstacles & ~(self.maps.maps[AGENT] > 0.5)
        field = self._field(plans.config_goals, clear, self.far.far_open_sites(), "sites past agents")
        return bool(np.isfinite(field[c, c]))

    def _explore(self, heading: float) -> tuple[float, float]:
        """Head for the nearest part of the world not yet seen (its extent came with the
        Welcome), planned on the map like any goal; with the extent unknown, or no way
        there on the map, wander in straight legs.

        Searching at random for a supply out of sensor range took thousands of ticks on
        large worlds (docs/design.md, Measurements); squares of BLOCK cells marked seen
        when the agent passes near them turn that into a sweep. The choice among near
        squares is a little random so agents spread out."""
        # Sweep only while searching for the supply: an agent that holds a brick, or knows
        # of one, is waiting for a way to open (a site held open by the Matching grid), and
        # a sweep would walk it away from where it is needed.
        if not self.cfg.explore_sweep:
            # The paper's Explore (§4.1): a random walk.
            return steering.explore(self.rng, self.cfg.explore_turn, self.cfg.cruise_speed)
        target = None
        if self.searching():
            target = self.far.unseen_target(self.rng, self._others() if self.cfg.spread_search else None)
        if target is not None:
            m = self.layers()
            obstacles = self._free_centre(m[FOOD] | m[WATER] | m[BRICK] | m[OBSTACLE] | m[AGENT])
            goals = np.zeros_like(obstacles)
            if self.maps.contains(*target):
                goals[target[0], target[1]] = True
                field = self.fields.distance(goals, obstacles, "unseen")
            else:
                field = self._field(goals, obstacles, target[None], "unseen")
            if gradient_step(field) not in (None, (0, 0)):
                return self._navigate(field, heading)
            self.far.give_up_target()
        if self.cfg.idle_wait and self._taken_from is None and not self.searching():
            return self._wait(heading)
        return self._wander(heading)

    def _wait(self, heading: float) -> tuple[float, float]:
        """Knowing free bricks but nothing to fetch now (no goal site, or the bricks out of
        reach), wait: near the supply (within `idle_near` cells of a known free brick, by
        a way), off the open sites and the cells beside them, and standing still there.

        An idle agent that wanders walks for nothing, stands in the others' way and is
        far from the next brick when one becomes its goal (issue 36). An agent that knows
        no free brick searches instead (`_explore`). Beliefs go stale while standing, so
        after `idle_patience` ticks of waiting it wanders one leg, and waits again."""
        self._waited = True
        self._idle += 1
        if self._idle > self.cfg.idle_patience:
            if self._idle == self.cfg.idle_patience + 1:
                self._leg_left = 0   # a fresh leg
            move = self._wander(heading)
            if self._leg_left <= 0:
                self._idle = 0
            return move
        c = self.centre
        m = self.layers()
        fixed = m[FOOD] | m[WATER] | m[OBSTACLE] | self._recalled
        spot = ~(fixed | m[BRICK] | dilate(m[CONFIG] & ~m[BRICK]))
        goals = spot
        bricks = m[BRICK] & ~m[CONFIG]
        far = self.far.far_bricks()
        if bricks.any() or len(far):
            # The way to the supply: round fixed things and the structure, not round agents,
            # who move (the supply is often out of reach only because they crowd it).
            to_supply = self._field(bricks, self._free_centre(fixed | (m[BRICK] & m[CONFIG])), far, "supply")
            near = spot & (to_supply <= self.cfg.idle_near)
            if near.any():
                goals = near
            elif np.isfinite(to_supply[c, c]):
                return self._navigate(to_supply, heading)
        if not goals[c, c]:
            field = self.fields.distance(goals, self._free_centre(fixed | m[BRICK] | m[AGENT]), "waiting spot")
            if gradient_step(field) not in (None, (0, 0)):
                return self._navigate(field, heading)
        self._standing = True
        return 0.0, 0.0

    def _others(self) -> np.ndarray:
        """The cells of the other agents in sight, as the far memory holds cells (x, y)."""
        rows, cols = np.nonzero(self.layers()[AGENT])
        return self.far.from_map(rows, cols)

    def _wander(self, heading: float) -> tuple[float, float]:
        """Wander in straight legs of random heading and length, a new leg when something
        fixed lies just ahead.

        A heading that drifts a little every tick (a plain random walk) covers ground in
        proportion to the square root of the time: on a large world an agent with no brick
        in view could take tens of thousands of ticks to find the supply. Legs of 40-160
        ticks cover it in proportion to the time, and stay random (the injected generator).
        """
        if self._leg_left <= 0 or self._blocked_ahead(self._leg_heading):
            self._leg_heading = float(self.rng.uniform(-math.pi, math.pi))
            self._leg_left = int(self.rng.integers(40, 161))
        self._leg_left -= 1
        speed, turn = steering.steer_to(math.cos(self._leg_heading), math.sin(self._leg_heading), heading,
                                        self.cfg.cruise_speed)
        # Wobble a little, as the paper's random Explore does, so two legs never retrace exactly.
        return speed, turn + float(self.rng.uniform(-0.1, 0.1)) * self.cfg.explore_turn

    def _blocked_ahead(self, angle: float) -> bool:
        """Is the cell 1.5 cells along `angle` held by something that never moves?"""
        r, c = self.maps.cell_of(1.5 * math.cos(angle), 1.5 * math.sin(angle))
        if not self.maps.contains(r, c):
            return True
        m = self.maps.maps
        return bool(max(m[OBSTACLE, r, c], m[FOOD, r, c], m[WATER, r, c]) > 0.5)

    def _navigate(self, field: np.ndarray, heading: float) -> tuple[float, float]:
        """Follow the steepest gradient: steer for the centre of the best neighbouring cell."""
        move = gradient_step(field)
        if move is None:  # nothing reachable on this map: look around
            return self._explore(heading)
        dr, dc = move
        dx, dy = self.maps.offset_of(self.centre + dr, self.centre + dc)
        return steering.steer_to(float(dx), float(dy), heading, self.cfg.cruise_speed)

    def _reading_offset(self, readings: np.ndarray) -> tuple[float, float]:
        """Offset (cells) of the nearest reading, at its sector's centre angle."""
        k = int(np.argmin(np.where(readings >= 0, readings, np.inf)))
        angle = (k + 0.5) * 2 * math.pi / len(readings)
        return readings[k] * math.cos(angle), readings[k] * math.sin(angle)


class _KeptForTwo:
    """A value kept for each of the last two sets of inputs, known by identity (a step that
    falls back to the plain goals asks for two in turn, and one kept would miss on both)."""

    def __init__(self) -> None:
        self._kept: list[tuple[tuple, object]] = []

    def get(self, inputs: tuple):
        """The value kept for these very objects, or None."""
        for known, value in self._kept:
            if _same_objects(known, inputs):
                return value
        return None

    def put(self, inputs: tuple, value) -> None:
        self._kept = [(inputs, value), *self._kept[:1]]


def _same_objects(a: tuple, b: tuple) -> bool:
    """Whether the two tuples hold the very same objects, place by place (a loop: a
    generator in `all` costs more than the few comparisons)."""
    for x, y in zip(a, b):  # noqa: SIM110 (see above)
        if x is not y:
            return False
    return True


def _mouth_side(held: np.ndarray, sites: np.ndarray, depth: np.ndarray) -> np.ndarray:
    """Sites of `sites` beside a site the Matching grid holds open (`held`, match = 1) and
    no farther from the supply (`depth`, path distance from the bricks) than it.

    In a corridor two or more cells wide the matched path runs down one side; two agents,
    each with its own view, would otherwise fill the two cells of its mouth together and
    seal the far end (docs/design.md, Measurements). Sites
    deeper than the held one (Fig. 18's D2 beside D1) stay goals: they are what the path
    is kept open for."""
    return _mouth_side_kernel(*(readonly(np.ascontiguousarray(g)) for g in (held, sites, depth)))


def _disc_mask(size: int, radius: float) -> np.ndarray:
    """The cells of a size x size map within `radius` cells of its centre cell."""
    r = np.arange(size) - size // 2
    return r[:, None] ** 2 + r[None, :] ** 2 <= radius * radius


@njit(cache=True)
def _mouth_side_kernel(held, sites, depth):
    """A site beside (4-neighbour) a held site, reachable and no deeper than it (+1e-9).
    Walked from the held sites (a few), not from every cell."""
    n, m = sites.shape
    out = np.zeros((n, m), np.bool_)
    flat = held.ravel()
    for i in range(flat.size):
        if not flat[i]:
            continue
        rr, cc = i // m, i % m
        for dr, dc in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            r, c = rr + dr, cc + dc
            # a site no path reaches (depth inf) is on no side of a mouth
            if (0 <= r < n and 0 <= c < m and sites[r, c] and np.isfinite(depth[r, c])
                    and depth[r, c] <= depth[rr, cc] + 1e-9):
                out[r, c] = True
    return out


@njit(cache=True)
def _nearest_cell(cells, centre, fx, fy):
    """(found, row, col) of the marked cell nearest the point (fx, fy) cells from the
    centre cell's centre; the first in row order on a tie. Distances are compared as
    `offset_of` and `np.hypot` give them, so the choice is the one numpy made.

    Searched ring by ring outwards from the centre (the cells k rows or columns away,
    whichever more): a cell of ring k is at least k - max(|fx|, |fy|) from the point, so
    once the best found is nearer than the next ring can be, no farther cell can win or
    tie. A brick in sight ends the search after a few rings of a large map; with none
    marked there is no search (the rings would visit every cell), and no ring lies wholly
    off the grid."""
    n, m = cells.shape
    if not _any_marked(cells):
        return False, -1, -1
    slack = max(abs(fx), abs(fy))
    best, br, bc = np.inf, -1, -1
    for k in range(max(centre, n - 1 - centre, m - 1 - centre) + 1):
        if best < k - slack:
            break
        for r in range(max(centre - k, 0), min(centre + k, n - 1) + 1):
            edge = r == centre - k or r == centre + k   # a whole row of the ring, else its two ends
            step = 1 if edge else 2 * k
            c = centre - k
            while c <= centre + k:
                if 0 <= c < m and cells[r, c]:
                    d = np.hypot(c - centre - fx, centre - r - fy)
                    if d < best or (d == best and (r < br or (r == br and c < bc))):
                        best, br, bc = d, r, c
                c += step
    return br >= 0, br, bc


@njit(cache=True)
def _any_marked(cells):
    """Whether any cell of the bool grid `cells` is marked: its bytes OR-ed 8 at a time
    (a loop that vectorises, where a scan that stops at the first mark does not)."""
    flat = np.ascontiguousarray(cells).reshape(-1).view(np.uint8)
    n8 = flat.size // 8
    acc = np.uint64(0)
    words = flat[:n8 * 8].view(np.uint64)
    for i in range(n8):
        acc |= words[i]
    for i in range(n8 * 8, flat.size):
        acc |= np.uint64(flat[i])
    return acc != 0


@njit(cache=True)
def _readings_in_cells(raw, channels, cell, dropped):
    """A frame's readings (flat, channel-major, world units) as (channels, sectors) in
    cells; NO_READING stays, and so does every reading of channel `dropped` (-1: none)."""
    sectors = raw.size // channels
    out = np.empty((channels, sectors))
    for ch in range(channels):
        for k in range(sectors):
            v = raw[ch * sectors + k]
            out[ch, k] = NO_READING if (v == NO_READING or ch == dropped) else v / cell
    return out


@njit(cache=True)
def _nearest_reading(readings):
    """The nearest of one channel's sector readings (inf when no sector senses anything)."""
    best = np.inf
    for value in readings:
        if value != NO_READING and value < best:
            best = value
    return best


@njit(cache=True)
def _extent(points):
    """The diagonal of the box round `points` ((k, 2)): how far apart they lie at most."""
    lo0 = hi0 = points[0, 0]
    lo1 = hi1 = points[0, 1]
    for i in range(1, points.shape[0]):
        lo0, hi0 = min(lo0, points[i, 0]), max(hi0, points[i, 0])
        lo1, hi1 = min(lo1, points[i, 1]), max(hi1, points[i, 1])
    return np.hypot(hi0 - lo0, hi1 - lo1)

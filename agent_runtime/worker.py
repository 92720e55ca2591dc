"""The reactive worker (issue 37 item 4; paper §5.2, §6.3): a small rule set, no maps.

In the spirit of Jones & Matarić's builders (conag/baselines/lattice.py) and of the paper's
reactive agents, a worker keeps no map and no blueprint: each step reads only the frame
(the range sectors, the cue channel, the floor sensor, its gripper) and a few counters.
It builds what foremen mark (docs/society.md). The rules, first that applies wins:

1. leaving: after a drop, or when stuck, go on along a set heading for a set while;
2. drop: holding a brick on a `site` cue (the floor sensor says so); with another body
   within a cell, only at random, so two on one cue seldom drop on the same tick;
3. grab: not holding, a brick within the gripper's reach in front, lying within
   `take_radius` of a `supply` cue (a worker cannot tell a free brick from a structure
   brick: it takes bricks only where a foreman says bricks are to be taken);
4. to a site: holding, head for the nearest `site` cue in sight;
5. take it back: holding, no site cue seen for `return_ticks`: drop the brick beside a
   `supply` cue in sight (else wander), so bricks nobody places return to where they are
   taken instead of riding round the world with idle workers;
6. to the supply: not holding, a site cue seen within `demand_ticks` (a new worker counts
   as having seen one), head for the nearest brick by a `supply` cue, else the cue (a
   worker that knows of no site wanting a brick takes none: thirty idle workers would
   otherwise hold thirty of the bricks the build needs);
7. wander: straight legs of random heading and length; an idle worker (no brick, no site
   cue seen for `demand_ticks`) parks: it goes to the nearest wall in sight and stands
   beside it, out of everyone's way (the open floor is where foremen walk).

Heading for something avoids obstacles reactively: of the sectors whose nearest reading
(disc, wall, agent) is clear of the way, the one nearest the goal's bearing; the last cell
of an approach goes straight (the goal's own neighbours would otherwise keep it out of a
gap). Stuck (no headway for `stuck_ticks` while moving): leave at a random heading.
Randomness is injected; a step costs a few dozen numpy operations on 7 x 16 numbers.
"""

from __future__ import annotations

import math
from collections import Counter, deque
from dataclasses import dataclass

import numpy as np

from protocol.messages import BEHAVIOURS, CHANNELS, CUE_KINDS, NO_READING, AgentState, SensorFrame, Welcome

_OBSTACLES = [CHANNELS.index(c) for c in ("food", "water", "brick", "obstacle", "agent")]
_BRICK, _AGENT, _WALL = CHANNELS.index("brick"), CHANNELS.index("agent"), CHANNELS.index("obstacle")
_SITE, _SUPPLY = CUE_KINDS.index("site"), CUE_KINDS.index("supply")


@dataclass(frozen=True)
class WorkerConfig:
    """A worker's few settings (distances in cells, times in ticks)."""

    cruise_speed: float = 2.0     # world units per second
    clearance: float = 1.1        # a sector is clear when nothing is nearer than this
    take_radius: float = 2.4      # it takes bricks lying this near a supply cue
    leave_ticks: int = 8          # how long it backs off a brick just dropped
    stuck_ticks: int = 60         # no headway for this long ...
    stuck_distance: float = 0.6   # ... (net cells moved) makes it leave at a random heading
    leg: tuple[int, int] = (20, 60)  # wander: ticks per straight leg, at least and at most
    crowded_drop: float = 0.2     # with another body this near, drop with this probability per tick
    demand_ticks: int = 300       # it takes a brick only this soon after it last saw a site cue
    return_ticks: int = 200       # loaded, with no site cue seen for this long, it takes the brick back
    # ... and drops it this near a supply cue's centre: beyond the corner of the cue's cell
    # (0.71), so the brick, which lands under the body, does not cover the cue; in a cell
    # beside it, within take_radius of it for the next taker.
    return_at: tuple[float, float] = (0.8, 1.3)
    park_at: float = 1.2          # idle, it stands once the nearest wall in sight is this near

    def __post_init__(self) -> None:
        if not (self.cruise_speed > 0 and self.clearance > 0 and self.take_radius > 0 and self.leave_ticks >= 1
                and self.stuck_ticks >= 1 and 1 <= self.leg[0] <= self.leg[1] and 0 < self.crowded_drop <= 1
                and self.demand_ticks >= 1 and self.return_ticks >= 1 and self.park_at > 0.2
                and 0.71 < self.return_at[0] < self.return_at[1] <= min(1.5, self.take_radius)):
            raise ValueError("worker settings must be positive (leg: 1 <= least <= most; return_at: beside "
                             "the supply cue's cell, not in it, within take_radius)")


@dataclass(frozen=True)
class WorkerStep:
    """One step's command and the rule that gave it (a behaviour name of BEHAVIOURS)."""

    speed: float
    turn: float
    action: str
    behaviour: str
    decision: None = None
    mark: None = None


class Worker:
    """One worker's rules and counters, stepped once per frame (see the module)."""

    def __init__(self, welcome: Welcome, cfg: WorkerConfig | None = None, rng: np.random.Generator | None = None):
        self.cfg = cfg or WorkerConfig()
        self.agent_id = welcome.agent_id
        self.rng = rng if rng is not None else np.random.default_rng(0)
        self.cell = welcome.cell_size
        self.reach = welcome.grab_reach / welcome.cell_size
        self.cone = welcome.grab_cone
        self.max_turn = welcome.max_turn or math.pi / 2
        self.sectors = welcome.sectors
        self.bearings = (np.arange(self.sectors) + 0.5) * 2 * math.pi / self.sectors
        self._leave = 0
        self._leave_heading = 0.0
        self._leg = 0
        self._leg_heading = 0.0
        self._trail: deque[np.ndarray] = deque(maxlen=self.cfg.stuck_ticks)
        self._pos = np.zeros(2)
        self.behaviour = "none"
        self.behaviour_ticks: Counter[str] = Counter()
        self.searched = 0  # (the stall clock's count of squares searched: a worker keeps no map)
        self.drops = 0
        self.returns = 0   # bricks taken back to a supply
        self._since_site = 0  # steps since a site cue was last in sight (a new worker takes a brick)

    # the step ------------------------------------------------------------------------------
    def step(self, frame: SensorFrame) -> WorkerStep:
        """Read the frame, apply the first rule that holds, return the command."""
        ranges = _cells(np.asarray(frame.ranges).reshape(len(CHANNELS), frame.sectors), self.cell)
        cues = (_cells(np.asarray(frame.cues).reshape(len(CUE_KINDS), frame.sectors), self.cell) if frame.cues
                else np.full((len(CUE_KINDS), frame.sectors), NO_READING))
        self._pos += (frame.odom_dx / self.cell, frame.odom_dy / self.cell)
        self._trail.append(self._pos.copy())
        self._since_site = 0 if (cues[_SITE] >= 0).any() else self._since_site + 1
        s = self._rules(frame, ranges, cues)
        if s.speed > 0 and self._stuck():
            self._leave_at(float(self.rng.uniform(-math.pi, math.pi)), self.cfg.stuck_ticks // 2)
            self._trail.clear()
            s = self._leaving(frame, ranges, "unstick")
        self.behaviour = s.behaviour
        self.behaviour_ticks[s.behaviour] += 1
        return s

    def _rules(self, frame: SensorFrame, ranges: np.ndarray, cues: np.ndarray) -> WorkerStep:
        if self._leave > 0:
            return self._leaving(frame, ranges, "avoid")
        if frame.holding and frame.cue_under == "site":
            if self._crowded(ranges) and self.rng.random() >= self.cfg.crowded_drop:
                return WorkerStep(0.0, 0.0, "none", "drop")
            self.drops += 1
            self._leave_at(frame.heading + math.pi, self.cfg.leave_ticks)
            return WorkerStep(0.0, 0.0, "drop", "drop")
        if frame.holding:
            site = _nearest(cues[_SITE])
            if site is not None:
                return self._head(frame, ranges, self.bearings[site], cues[_SITE, site], "config_nav")
            if self._since_site >= self.cfg.return_ticks:
                return self._take_back(frame, ranges, cues[_SUPPLY])
            return self._wander(frame, ranges)
        if self._since_site >= self.cfg.demand_ticks:
            return self._wander(frame, ranges)  # no site wants a brick that it knows of: take none
        brick = self._brick_by_supply(ranges[_BRICK], cues[_SUPPLY])
        if brick is not None:
            d, bearing = ranges[_BRICK, brick], self.bearings[brick]
            off = _angle(bearing - frame.heading)
            if d <= self.reach - 0.1:
                if abs(off) < self.cone - 0.2:
                    return WorkerStep(0.0, 0.0, "grab", "grab")
                return WorkerStep(0.0, float(np.clip(off, -self.max_turn, self.max_turn)), "none", "grab")
            return self._head(frame, ranges, bearing, d, "brick_nav", stop_at=self.reach - 0.3)
        supply = _nearest(cues[_SUPPLY])
        if supply is not None:
            return self._head(frame, ranges, self.bearings[supply], cues[_SUPPLY, supply], "brick_nav")
        return self._wander(frame, ranges)

    # the rules' parts ----------------------------------------------------------------------
    def _take_back(self, frame: SensorFrame, ranges: np.ndarray, supply: np.ndarray) -> WorkerStep:
        """A brick no site it knows of wants goes back where bricks are taken: dropped in a
        cell beside a supply cue, not on it (the brick lands under the body, and a covered
        cue is seen by nobody). A foreman keeps a supply cue 3 cells from every site, so the
        brick lies 2 cells from the structure at least, within reach of the next taker."""
        cue = _nearest(supply)
        if cue is None:
            return self._wander(frame, ranges)
        near, far = self.cfg.return_at
        if near <= supply[cue] <= far:
            self.returns += 1
            self._leave_at(frame.heading + math.pi, self.cfg.leave_ticks)
            return WorkerStep(0.0, 0.0, "drop", "drop")
        if supply[cue] < near:  # on the cue: step off it first
            return self._head(frame, ranges, self.bearings[cue] + math.pi, math.inf, "config_nav")
        return self._head(frame, ranges, self.bearings[cue], supply[cue], "config_nav", stop_at=near)

    @staticmethod
    def _crowded(ranges: np.ndarray) -> bool:
        """Another body within a cell: it may stand on the same cue and drop on the same tick
        (two bricks for one site). Both then drop only now and then, at random, until one has:
        its brick covers the cue and the other sees none."""
        agents = ranges[_AGENT]
        return bool(((agents >= 0) & (agents < 1.0)).any())

    def _brick_by_supply(self, bricks: np.ndarray, supply: np.ndarray) -> int | None:
        """The sector of the nearest brick lying within take_radius of a supply cue in sight."""
        cue = _nearest(supply)
        if cue is None:
            return None
        cue_xy = supply[cue] * np.array([math.cos(self.bearings[cue]), math.sin(self.bearings[cue])])
        seen = np.flatnonzero(bricks >= 0)
        if not len(seen):
            return None
        xy = bricks[seen, None] * np.column_stack([np.cos(self.bearings[seen]), np.sin(self.bearings[seen])])
        near = np.hypot(xy[:, 0] - cue_xy[0], xy[:, 1] - cue_xy[1]) <= self.cfg.take_radius
        if not near.any():
            return None
        return int(seen[near][np.argmin(bricks[seen[near]])])

    def _head(self, frame: SensorFrame, ranges: np.ndarray, bearing: float, distance: float, behaviour: str,
              stop_at: float = 0.0) -> WorkerStep:
        """Towards `bearing`, round what is in the way; straight on for the last cell."""
        if distance > 1.5:
            bearing = self._free_bearing(ranges, bearing)
        off = _angle(bearing - frame.heading)
        turn = float(np.clip(off, -self.max_turn, self.max_turn))
        speed = self.cfg.cruise_speed * max(math.cos(off), 0.0) * min(1.0, max(distance - stop_at, 0.0) + 0.3)
        return WorkerStep(speed if abs(off) < math.pi / 2 else 0.0, turn, "none", behaviour)

    def _free_bearing(self, ranges: np.ndarray, bearing: float) -> float:
        """The centre of the clear sector nearest `bearing` (itself if its sector is clear)."""
        near = ranges[_OBSTACLES]
        near = np.where(near < 0, np.inf, near).min(axis=0)
        clear = near > self.cfg.clearance
        if not clear.any():
            return bearing
        want = int(bearing // (2 * math.pi / self.sectors)) % self.sectors
        if clear[want]:
            return bearing
        gaps = np.abs(np.vectorize(_angle)(self.bearings - bearing))
        return float(self.bearings[np.argmin(np.where(clear, gaps, np.inf))])

    def _wander(self, frame: SensorFrame, ranges: np.ndarray) -> WorkerStep:
        if self._leg <= 0:
            self._leg_heading = float(self.rng.uniform(-math.pi, math.pi))
            self._leg = int(self.rng.integers(self.cfg.leg[0], self.cfg.leg[1] + 1))
        self._leg -= 1
        idle = not frame.holding and self._since_site >= self.cfg.demand_ticks
        parked = self._park(frame, ranges) if idle else None
        return parked or self._head(frame, ranges, self._leg_heading, math.inf, "explore")

    def _park(self, frame: SensorFrame, ranges: np.ndarray) -> WorkerStep | None:
        """An idle worker gets out of the way: to the nearest wall in sight, and stands there.

        Thirty idle bodies on the open floor stand where the foremen walk, and every one is
        a detour for them; beside a wall nobody's way runs. Parked, it still sees a site cue
        come within sensor range, and goes back to work. With no wall in sight (None) it
        walks its legs until one is (2 foremen and 30 workers on the sample: 0.94-0.98x the ticks of 2
        ConAg agents alone; resting in the open 3 legs in 4, 1.07-1.10x; docs/society.md)."""
        walls = ranges[_WALL]
        wall = _nearest(walls)
        if wall is None:
            return None
        if walls[wall] <= self.cfg.park_at:
            return WorkerStep(0.0, 0.0, "none", "none")
        return self._head(frame, ranges, self.bearings[wall], walls[wall], "explore",
                          stop_at=self.cfg.park_at - 0.2)  # slowing to a stop short of it

    def _leave_at(self, heading: float, ticks: int) -> None:
        self._leave_heading, self._leave = heading, ticks

    def _leaving(self, frame: SensorFrame, ranges: np.ndarray, behaviour: str) -> WorkerStep:
        self._leave -= 1
        return self._head(frame, ranges, self._leave_heading, math.inf, behaviour)

    def _stuck(self) -> bool:
        if len(self._trail) < self.cfg.stuck_ticks:
            return False
        return float(np.hypot(*(self._trail[-1] - self._trail[0]))) < self.cfg.stuck_distance

    # what it reports -----------------------------------------------------------------------
    def set_blueprint(self, version: int, site_xs, site_ys) -> bool:  # noqa: ARG002 -- Brain's signature
        """A worker has no blueprint: a changed one changes nothing."""
        return False

    def state_report(self, tick: int) -> AgentState:
        """What it is doing (no sites believed open: it keeps no map)."""
        return AgentState(self.agent_id, tick, self.behaviour if self.behaviour in BEHAVIOURS else "none",
                          False, 0, "", tuple(self.behaviour_ticks[b] for b in BEHAVIOURS))

    def blocker(self) -> str:
        """Nothing it could say: it keeps no plan."""
        return ""


def _cells(readings: np.ndarray, cell: float) -> np.ndarray:
    return np.where(readings >= 0, readings / cell, NO_READING)


def _nearest(readings: np.ndarray) -> int | None:
    seen = np.flatnonzero(readings >= 0)
    return int(seen[np.argmin(readings[seen])]) if len(seen) else None


def _angle(a: float) -> float:
    """`a` wrapped to [-pi, pi)."""
    return (a + math.pi) % (2 * math.pi) - math.pi

"""The world core (paper §3): discs, agent bodies, sensors, gripper, eat/drink, perturbation.

No bus here: the server decodes commands, calls `set_command`, `step`, `frames`, and
encodes what comes back. One tick: apply each agent's one-shot action (grab, drop, eat,
drink) where it stands, turn, close part of the gap to the commanded speed (inertia),
step the physics, measure odometry, sense. Randomness (sensor and odometry noise, odometry
slip, perceptual aliasing: docs/noise.md) comes from the injected generator, so the same
seed and the same commands give the same run.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass

import numpy as np

from protocol.codec import encode, encode_checked_fields
from protocol.messages import (
    ACTIONS,
    CHANNELS,
    CUE_KINDS,
    DISC_KINDS,
    NO_READING,
    SITE_OPS,
    WELCOME_CONSTANTS,
    Blueprint,
    Perturbation,
    PerturbResult,
    SensorFrame,
    Welcome,
    WorldStatus,
    WorldView,
)
from world_server.cues import CueBoard, sense_cues
from world_server.discs import BRICK_DISC, FOOD_DISC, IN_WORLD, WATER_DISC, DiscStore
from world_server.physics import Physics, motor_update
from world_server.placement import body_cell, brick_drop_cell, extra_start_cells, reachable_cells
from world_server.scenario import Scenario
from world_server.sensors import sense, warm_up

GRAB, DROP, EAT, DRINK, MARK, UNMARK = (ACTIONS.index(a) for a in ("grab", "drop", "eat", "drink", "mark", "unmark"))
OBSTACLE_CHANNEL = CHANNELS.index("obstacle")
FLAGS = ("grabbed", "dropped", "ate", "drank")
_LAYOUT_KINDS = {"F": FOOD_DISC, "W": WATER_DISC, "b": BRICK_DISC, "B": BRICK_DISC}


@dataclass
class AgentRecord:
    """One agent body's bookkeeping: its index in the arrays, alive, carried brick, counters."""

    agent_id: str
    index: int
    alive: bool = True
    holding: int = -1       # disc index of the carried brick, or -1
    restarts: int = 0
    grabs: int = 0
    drops: int = 0
    pid: int | None = None  # the process that attached last, if it said
    gone_at: int = -1       # the tick its process was seen gone (detach), while it is gone


class World:
    """The world of paper §3 as arrays and a pymunk space, stepped one tick at a time.

    Built from a scenario (discs, walls, drop sites, agent starts) and a random generator
    (the noise). Agents `attach` by id (getting a body and the Welcome) and `detach`; each
    tick the caller gives every live agent's command (`set_command`), calls `step`, and
    hands out the `frames`. A detached agent's brick is put down where nothing needs it
    (`world_server.placement.brick_drop_cell`); its body stays, stopped, for
    `body_grace_ticks`, then leaves the world (it no longer collides and is not sensed)
    until the same id attaches again and gets it back at the free cell nearest where it
    was that the open world reaches (`placement.body_cell`). `status`, `sites_filled`,
    `completed` and `blueprint` report the build; `perturb` removes, adds or moves a disc or changes the blueprint.
    """

    def __init__(self, scenario: Scenario, rng: np.random.Generator | None = None, world_id: str = "w0",
                 epoch: int | None = None):
        self.scenario = scenario
        self.cfg = scenario.world
        self.world_id = world_id
        self.rng = rng if rng is not None else np.random.default_rng(scenario.seed)
        # Which run of the world this is, in the Welcome and every frame (an agent refuses
        # frames of another epoch). By default a digest of the world's id and its generator's
        # initial state, drawing nothing from it: the same seed gives the same run, frames
        # included; another seed or world id, another epoch. Not a secret.
        self.epoch = epoch if epoch is not None else int.from_bytes(hashlib.blake2b(
            f"{world_id}|{self.rng.bit_generator.state}".encode(), digest_size=8).digest(), "little") >> 1
        self.tick = 0
        self.size = scenario.size
        cells = {ch: scenario.cells_col_row(ch) for ch in "FWbB#A+"}
        disc_cells = np.vstack([cells[ch] for ch in "FWbB"])
        kinds = np.concatenate([np.full(len(cells[ch]), _LAYOUT_KINDS[ch]) for ch in "FWbB"])
        self.discs = DiscStore(scenario.to_world(disc_cells), kinds)
        self.physics = Physics(self.cfg, self.size, scenario.to_world(cells["#"]))
        for i in range(len(self.discs)):
            self.physics.add_disc(i, self.discs.xy[i])
        self._obstacle_xy = _obstacle_points(scenario, cells["#"])
        self._walls_xy = scenario.to_world(cells["#"]).reshape(-1, 2)  # fixed `#` cells, for views
        self._sense_inputs: tuple | None = None  # (present discs, xy, channels) with obstacles appended
        warm_up()  # the sensor kernel, now rather than at the first attach
        self.sites_xy = scenario.to_world(np.vstack([cells["+"], cells["B"]]))
        self._site_codes = self._cell_code(self.sites_xy)
        self.blueprint_version = 0  # +1 per site added or removed (a Blueprint message each time)
        self._starts = scenario.to_world(cells["A"])
        self._extra_start_xy: np.ndarray | None = None  # `_extra_starts`, once needed
        self.agents: dict[str, AgentRecord] = {}
        self._order: list[AgentRecord] = []
        n = 0
        self.heading = np.zeros(n)
        self.speed = np.zeros(n)
        self.turn = np.zeros(n)
        self.action = np.zeros(n, np.int64)
        self.alive = np.zeros(n, bool)
        self.solid = np.zeros(n, bool)  # the body collides and is sensed (alive, or dead within its grace)
        self.odometry = np.zeros((n, 2))
        self.distance = np.zeros(n)
        self.flags = np.zeros((n, len(FLAGS)), bool)
        self._ranges = np.zeros((n, len(CHANNELS), self.cfg.sensor_sectors))
        self._pending_release: dict[int, int] = {}  # dropped brick -> agent index
        # Cues (world_server/cues.py), when cue_reach > 0: the marks lying on the floor, the
        # mark offsets of this tick's mark / unmark commands, and the last readings.
        self.cues = CueBoard()
        self._mark_at: dict[int, tuple[float, float, str]] = {}
        self._cue_ranges = np.zeros((0, len(CUE_KINDS), self.cfg.sensor_sectors))
        self._cue_under: list[str] = []
        self._cue_inputs: tuple | None = None  # (cue arrays, present discs, `_uncovered_cues`) of the last change
        # Body positions as of the last step or attach, for status(): reading them from the
        # physics there would share its read buffer with a step (tests read status from
        # another thread while the server steps).
        self._positions = np.zeros((0, 2))
        self.bad_messages = 0

    def _cell_code(self, xy: np.ndarray) -> np.ndarray:
        cells = self.scenario.to_cell(xy)
        return cells[:, 0] * (self.scenario.rows + 1) + cells[:, 1]

    # agents come and go --------------------------------------------------------------
    def attach(self, agent_id: str, pid: int | None = None) -> Welcome:
        """Give `agent_id` its body: the same one as before, or a new one at a start.

        A repeated request from the live process that attached last (`pid`; it retries
        when the world is slow to answer, e.g. while compiling on a first run) is answered
        again and is not a restart.
        """
        rec = self.agents.get(agent_id)
        if rec is None:
            index = self.physics.add_agent(self._free_start())
            rec = AgentRecord(agent_id, index)
            self.agents[agent_id] = rec
            self._order.append(rec)
            self._grow_arrays()
            self.solid[index] = True
        elif not (rec.alive and pid is not None and rec.pid == pid):
            rec.restarts += 1
            rec.alive = True
        rec.pid = pid
        rec.gone_at = -1
        if not self.solid[rec.index]:
            self._bring_back(rec)
        self.alive[rec.index] = True
        self.speed[rec.index] = self.turn[rec.index] = 0.0
        self.action[rec.index] = 0
        pos, _ = self.physics.state()
        self._positions = pos
        self._sense()
        return Welcome(
            world_id=self.world_id, agent_id=agent_id, body=rec.index, tick=self.tick,
            x=float(pos[rec.index, 0]), y=float(pos[rec.index, 1]), heading=float(self.heading[rec.index]),
            holding=rec.holding >= 0, restarts=rec.restarts, sectors=self.cfg.sensor_sectors,
            sensor_range=self.cfg.sensor_range, cell_size=self.cfg.cell_size,
            site_xs=tuple(self.sites_xy[:, 0].tolist()), site_ys=tuple(self.sites_xy[:, 1].tolist()),
            world_width=float(self.size[0]), world_height=float(self.size[1]),
            blueprint_version=self.blueprint_version, epoch=self.epoch, occlusion=bool(self.cfg.occlusion),
            **{name: float(getattr(self.cfg, name)) for name in WELCOME_CONSTANTS})

    def halt(self, agent_id: str) -> None:
        """Stop a live agent's body where it is (speed set point and velocity to 0): the
        world no longer waits for its commands, and its last one must not drive it on."""
        rec = self.agents.get(agent_id)
        if rec is None or not rec.alive:
            return
        self.speed[rec.index] = self.turn[rec.index] = 0.0
        self.action[rec.index] = 0
        self.physics.set_velocity(rec.index, (0.0, 0.0))

    def detach(self, agent_id: str) -> None:
        """The agent's process is gone: its body stops, and a brick it held is put down where
        nothing needs it (`brick_drop_cell`: not on a site, not beside one, not in a gap).
        After `body_grace_ticks` ticks the body leaves the world (`step`)."""
        rec = self.agents.get(agent_id)
        if rec is None or not rec.alive:
            return
        if rec.holding >= 0:
            pos, _ = self.physics.state()
            self._put_down(rec, pos[rec.index])
        self.speed[rec.index] = self.turn[rec.index] = 0.0
        self.action[rec.index] = 0
        self.alive[rec.index] = False
        rec.alive = False
        rec.gone_at = self.tick
        if self.cfg.body_grace_ticks == 0:
            self._remove_body(rec)

    def _fractional_cell(self, xy: np.ndarray) -> tuple[float, float]:
        """World (x, y) -> fractional (col, row) for `world_server.placement` (row 0 north)."""
        size = self.cfg.cell_size
        return float(xy[0]) / size, self.scenario.rows - float(xy[1]) / size

    def _open_cells(self) -> np.ndarray:
        """bool [row, col]: the cells a body can walk to from the scenario's `A` starts (from
        the bodies in the world where no start is open, e.g. a layout without `A`), through
        cells a body fits in when no other body is in the way (bodies move; walls and discs
        do not): the open world, not a pocket sealed off from it."""
        passable = self._free_cells(self.cfg.agent_radius, bodies=False)
        starts = self.scenario.cells_col_row("A")
        reach = reachable_cells(passable, starts)
        if not reach.any():
            reach = reachable_cells(passable, self.scenario.to_cell(self.physics.state()[0][self.solid]))
        return reach

    def _free_cells(self, radius: float, body_margin: float = 0.0, bodies: bool = True) -> np.ndarray:
        """bool [row, col]: a circle of `radius` at the cell's centre overlaps no wall, no disc
        in the world and (with `bodies`) no solid body (kept `body_margin` further from bodies)."""
        sc = self.scenario
        free = ~sc.grid("#")
        rows, cols = free.shape
        size = self.cfg.cell_size
        pos, _ = self.physics.state()
        objects = [(self.discs.present_arrays()[1], radius + self.cfg.disc_radius)]
        if bodies:
            objects.append((pos[self.solid], radius + self.cfg.agent_radius + body_margin))
        for xy, reach in objects:
            if not len(xy):
                continue
            cells = np.floor(np.column_stack([xy[:, 0] / size, rows - xy[:, 1] / size])).astype(np.int64)
            k = int(np.ceil(reach / size)) + 1
            for dc in range(-k, k + 1):
                for dr in range(-k, k + 1):
                    c, r = cells[:, 0] + dc, cells[:, 1] + dr
                    inside = (c >= 0) & (c < cols) & (r >= 0) & (r < rows)
                    cx, cy = (c + 0.5) * size, (rows - r - 0.5) * size
                    hit = inside & (np.hypot(xy[:, 0] - cx, xy[:, 1] - cy) < reach - 1e-9)
                    free[r[hit], c[hit]] = False
        return free

    def _put_down(self, rec: AgentRecord, xy: np.ndarray) -> None:
        """A dead agent's brick, put where nothing needs it (where the body stands if there is
        no such cell). It is not the agent's drop: its drop count stays."""
        site = np.zeros(self.scenario.grid("#").shape, bool)
        cells = self.scenario.to_cell(self.sites_xy)
        site[cells[:, 1], cells[:, 0]] = True
        cell = brick_drop_cell(self._free_cells(self.cfg.disc_radius), site, self._fractional_cell(xy))
        where = xy if cell is None else self.scenario.to_world(cell)[0]
        brick, rec.holding = rec.holding, -1
        self.discs.place(brick, where)
        self.physics.add_disc(brick, where)

    def _remove_body(self, rec: AgentRecord) -> None:
        """The body leaves the world: it collides with nothing and no sensor sees it."""
        self.solid[rec.index] = False
        self.physics.set_solid(rec.index, False)
        for brick, agent in list(self._pending_release.items()):
            if agent == rec.index:
                self.physics.release_disc(brick)
                del self._pending_release[brick]

    def _bring_back(self, rec: AgentRecord) -> None:
        """A body that had left the world comes back at the free cell nearest where it was
        that the open world reaches (`_open_cells`): bricks laid while it was away may have
        sealed where it stood into a pocket."""
        pos, _ = self.physics.state()
        free = self._free_cells(self.cfg.agent_radius, body_margin=0.1)
        cell = body_cell(free, self._fractional_cell(pos[rec.index]), self._open_cells())
        if cell is None:
            raise RuntimeError("no free cell left for a returning agent body")
        self.physics.place_body(rec.index, self.scenario.to_world(cell)[0])
        self.physics.set_solid(rec.index, True)
        self.solid[rec.index] = True

    def rebuild_physics(self, positions: np.ndarray | None = None, velocities: np.ndarray | None = None) -> None:
        """A fresh pymunk space holding what the world holds now, built in one fixed order.

        pymunk keeps caches between steps (contact impulses for warm starting, the
        spatial index's history) that no copy carries, so a space restored from a
        checkpoint would drift from one that never stopped. A checkpointing world
        therefore rebuilds its space at every checkpoint from the same plain state the
        checkpoint holds (`positions`, `velocities` of every body, agent order; default:
        the current ones), and a resumed world rebuilds from the file the same way: both
        runs step on from identical spaces (`world_server/checkpoint.py`).
        """
        old_pos, old_vel = self.physics.state()
        pos = old_pos if positions is None else np.asarray(positions, np.float64).reshape(-1, 2)
        vel = old_vel if velocities is None else np.asarray(velocities, np.float64).reshape(-1, 2)
        physics = Physics(self.cfg, self.size, self.scenario.to_world(self.scenario.cells_col_row("#")))
        for i in np.flatnonzero(self.discs.state == IN_WORLD).tolist():
            owner = self._pending_release.get(i)
            physics.add_disc(i, self.discs.xy[i], group=0 if owner is None else owner + 1)
        for index in physics.add_agents(pos[[rec.index for rec in self._order]]):
            physics.set_velocity(index, vel[index])
            physics.set_solid(index, bool(self.solid[index]))
        self.physics = physics
        self._positions = pos.copy()

    def live_agents(self) -> list[str]:
        """Ids of the attached, live agents, in attach order."""
        return [r.agent_id for r in self._order if r.alive]

    def _grow_arrays(self) -> None:
        for name in ("heading", "speed", "turn", "action", "alive", "solid", "distance"):
            arr = getattr(self, name)
            setattr(self, name, np.append(arr, np.zeros(1, arr.dtype)))
        self.odometry = np.vstack([self.odometry, np.zeros((1, 2))])
        self.flags = np.vstack([self.flags, np.zeros((1, len(FLAGS)), bool)])
        self._ranges = np.vstack([self._ranges, np.zeros((1, *self._ranges.shape[1:]))])

    def _free_start(self) -> np.ndarray:
        """First `A` start not taken by a body, else the clear empty cell nearest the starts
        (by walking distance, `placement.extra_start_cells`; ties in reading order)."""
        taken = self.physics.state()[0][self.solid]
        clear = self.cfg.agent_radius * 2 + 0.1
        present = self.discs.xy[self.discs.present()]
        for group in (self._starts, self._extra_starts()):
            # In chunks, vectorised: with 100 agents and thousands of cells a loop over the
            # candidates in Python would be the slowest part of start-up.
            for at in range(0, len(group), 256):
                chunk = group[at:at + 256]
                ok = np.ones(len(chunk), bool)
                for xy, reach in ((taken, clear), (present, self.cfg.disc_radius + self.cfg.agent_radius)):
                    if len(xy):
                        near = np.hypot(chunk[:, None, 0] - xy[None, :, 0], chunk[:, None, 1] - xy[None, :, 1])
                        ok &= near.min(axis=1) >= reach
                if ok.any():
                    return chunk[int(np.argmax(ok))]
        raise RuntimeError("no free cell left for a new agent body")

    def _extra_starts(self) -> np.ndarray:
        """World centres of the empty cells, in the order agents beyond the `A` cells get them
        (worked out once: the layout does not change)."""
        if self._extra_start_xy is None:
            sc = self.scenario
            cells = extra_start_cells(sc.grid("."), ~sc.grid("#FWbB"), sc.cells_col_row("A"))
            self._extra_start_xy = sc.to_world(cells)
        return self._extra_start_xy

    # commands and ticks ----------------------------------------------------------------
    def set_command(self, agent_id: str, speed: float, turn: float, action: str,
                    mark: tuple[float, float, str] | None = None) -> bool:
        """Record the latest command of a live agent; False if the agent is not attached.
        `mark`: (dx, dy, kind) of a mark / unmark action (AgentCommand.mark_*)."""
        rec = self.agents.get(agent_id)
        if rec is None or not rec.alive:
            return False
        i = rec.index
        if action in ("mark", "unmark"):
            self._mark_at[i] = mark if mark is not None else (0.0, 0.0, CUE_KINDS[0])
        # set_commands' clips, on scalars: the world server takes a command at a time, and
        # four arrays and two np.clip calls each cost it more than the rest of the command.
        self.speed[i] = min(max(speed, 0.0), self.cfg.max_speed)
        self.turn[i] = min(max(turn, -self.cfg.max_turn), self.cfg.max_turn)
        self.action[i] = ACTIONS.index(action)
        return True

    def set_commands(self, index: np.ndarray, speed: np.ndarray, turn: np.ndarray, action: np.ndarray) -> None:
        """Record commands for many bodies at once (body indices, action codes into ACTIONS)."""
        self.speed[index] = np.clip(speed, 0.0, self.cfg.max_speed)
        self.turn[index] = np.clip(turn, -self.cfg.max_turn, self.cfg.max_turn)
        self.action[index] = action

    def step(self) -> None:
        """Advance one tick."""
        self.flags[:] = False
        pos, vel = self.physics.state()
        for i in np.flatnonzero(self.action):
            self._act(self._order[i], pos[i])
        desired = motor_update(self.heading, self.turn, self.speed, self.alive, vel, self.cfg.inertia)
        # The turn and the action are one-shot; the speed is a set point that persists.
        self.turn[:] = 0.0
        self.action[:] = 0
        self._mark_at.clear()
        self.physics.drive(vel, desired)
        self.physics.step()
        new_pos, _ = self.physics.state()
        self._positions = new_pos
        moved = new_pos - pos
        self.distance += np.hypot(moved[:, 0], moved[:, 1])
        self.odometry = moved
        if (self.cfg.odometry_distance_slip > 0 or self.cfg.odometry_heading_slip > 0) and len(moved):
            self.odometry = self._slipped(moved)
        if self.cfg.odometry_noise > 0 and len(moved):
            step_len = np.hypot(moved[:, 0], moved[:, 1])[:, None]
            self.odometry = self.odometry + self.rng.standard_normal(moved.shape) * self.cfg.odometry_noise * step_len
        self._release_dropped(new_pos)
        self.tick += 1
        self._remove_expired()
        self._sense(new_pos)

    def _slipped(self, moved: np.ndarray) -> np.ndarray:
        """What the wheels report of each body's step `moved`: its length off by a relative
        error of std `odometry_distance_slip`, its direction turned by an angle of std
        `odometry_heading_slip` radians (both normal, zero mean, drawn per step), so the
        error along and across the motion grows with the distance moved."""
        e = self.rng.standard_normal(moved.shape)
        stretch = 1.0 + self.cfg.odometry_distance_slip * e[:, 0]
        angle = self.cfg.odometry_heading_slip * e[:, 1]
        c, s = np.cos(angle), np.sin(angle)
        turned = np.column_stack([c * moved[:, 0] - s * moved[:, 1], s * moved[:, 0] + c * moved[:, 1]])
        return turned * stretch[:, None]

    def _remove_expired(self) -> None:
        """Dead bodies whose grace period is over leave the world."""
        for rec in self._order:
            if self.solid[rec.index] and not rec.alive and self.tick - rec.gone_at >= self.cfg.body_grace_ticks:
                self._remove_body(rec)

    def _sense(self, pos: np.ndarray | None = None) -> None:
        if pos is None:
            pos, _ = self.physics.state()
        disc_xy, disc_kind = self._sensed_objects()
        seed = int(self.rng.integers(2**63)) if self.cfg.sensor_noise > 0 else 0
        alias_seed = int(self.rng.integers(2**63)) if self.cfg.aliasing > 0 else 0
        if not self.solid.all():
            # A body that has left the world is out of every sensor's range.
            pos = np.where(self.solid[:, None], pos, -1e9)
        self._ranges = sense(pos, self.alive, disc_xy, disc_kind, self.cfg.sensor_sectors,
                             self.cfg.sensor_range, self.size, noise=self.cfg.sensor_noise, seed=seed,
                             occlusion=self.cfg.occlusion, aliasing=self.cfg.aliasing, alias_seed=alias_seed)
        if self.cfg.cue_reach > 0:
            self._sense_cues(pos, seed)

    def _sense_cues(self, pos: np.ndarray, seed: int) -> None:
        """Cue readings and the cue under each body (world_server/cues.py): a cue whose cell
        holds a disc is covered, neither sensed nor under anyone."""
        xy, kinds, uncovered = self._uncovered_cues()
        self._cue_ranges = sense_cues(pos, self.alive & self.solid, xy, kinds, self.cfg.sensor_sectors,
                                      self.cfg.sensor_range, noise=self.cfg.sensor_noise, seed=seed)
        under = self.scenario.to_cell(pos) if len(pos) else np.zeros((0, 2), np.int64)
        self._cue_under = [uncovered.get((c, r), "") for c, r in under.tolist()] if uncovered else [""] * len(pos)

    def _uncovered_cues(self) -> tuple[np.ndarray, np.ndarray, dict[tuple[int, int], str]]:
        """World centres and kinds of the cues no disc covers, and their kinds by (col, row):
        worked out again only when the cues or the discs lying in the world change."""
        cues, present = self.cues.arrays(), self.discs.present_arrays()
        if self._cue_inputs is None or self._cue_inputs[0] is not cues or self._cue_inputs[1] is not present:
            cells, kinds = cues
            if len(cells):
                covered = np.isin(self._cell_code(self.scenario.to_world(cells)), self._cell_code(present[1]))
                cells, kinds = cells[~covered], kinds[~covered]
            by_cell = {(c, r): CUE_KINDS[k] for (c, r), k in zip(cells.tolist(), kinds.tolist())}
            self._cue_inputs = (cues, present, (self.scenario.to_world(cells), kinds, by_cell))
        return self._cue_inputs[2]

    def _sensed_objects(self) -> tuple[np.ndarray, np.ndarray]:
        """Positions and sensor channels of the present discs and the fixed obstacle points.

        Rebuilt only when the discs change (the store hands out a new tuple then)."""
        present = self.discs.present_arrays()
        if self._sense_inputs is None or self._sense_inputs[0] is not present:
            _, xy, kind = present
            self._sense_inputs = (present, np.vstack([xy, self._obstacle_xy]),
                                  np.concatenate([kind, np.full(len(self._obstacle_xy), OBSTACLE_CHANNEL)]))
        return self._sense_inputs[1], self._sense_inputs[2]

    def _act(self, rec: AgentRecord, xy: np.ndarray) -> None:
        action = self.action[rec.index]
        touch = self.cfg.agent_radius + self.cfg.disc_radius + self.cfg.touch_margin
        if action == GRAB and rec.holding < 0:
            # The gripper is in front: it takes the nearest brick within reach there, so an
            # agent facing a free brick does not pick up the structure brick beside it.
            brick = self.discs.nearest_in_front(xy, self.heading[rec.index], self.cfg.grab_reach,
                                                self.cfg.grab_cone, BRICK_DISC)
            if brick >= 0:
                self.discs.carry(brick)
                self.physics.remove_disc(brick)
                self._pending_release.pop(brick, None)
                rec.holding, rec.grabs = brick, rec.grabs + 1
                self.flags[rec.index, 0] = True
        elif action == DROP and rec.holding >= 0:
            self._drop(rec, xy)
            self.flags[rec.index, 1] = True
        elif action == EAT:
            self.flags[rec.index, 2] = self.discs.nearest(xy, touch, FOOD_DISC) >= 0
        elif action == DRINK:
            self.flags[rec.index, 3] = self.discs.nearest(xy, touch, WATER_DISC) >= 0
        elif action in (MARK, UNMARK):
            self._mark(rec, xy, action == MARK)

    def _mark(self, rec: AgentRecord, xy: np.ndarray, put: bool) -> None:
        """Put a cue on, or take one off, the cell at the command's mark offset from the body:
        only in a world with cues, within `cue_reach`, inside the world and off `#` cells."""
        dx, dy, kind = self._mark_at.get(rec.index, (0.0, 0.0, CUE_KINDS[0]))
        if self.cfg.cue_reach <= 0 or np.hypot(dx, dy) > self.cfg.cue_reach:
            return
        col, row = (int(v) for v in self.scenario.to_cell((xy[0] + dx, xy[1] + dy))[0])
        if not (0 <= col < self.scenario.cols and 0 <= row < self.scenario.rows):
            return
        if put and self.scenario.layout[row][col] != "#":
            self.cues.place((col, row), kind)
        elif not put:
            self.cues.remove((col, row))

    def _drop(self, rec: AgentRecord, xy: np.ndarray) -> None:
        # The brick lands under the agent (paper §3); it ignores that agent until the agent
        # has moved off it, instead of the physics kicking the two apart.
        brick = rec.holding
        xy = self._settled(xy)
        self.discs.place(brick, xy)
        self.physics.add_disc(brick, xy, group=rec.index + 1)
        self._pending_release[brick] = rec.index
        rec.holding, rec.drops = -1, rec.drops + 1

    def _settled(self, xy: np.ndarray) -> np.ndarray:
        """Where a brick dropped at `xy` comes to rest: on the centre of the empty drop site
        it fell in (a site is a slot in the structure), else where it fell.

        Why: bricks dropped up to a third of a cell off their sites' centres narrowed the
        one-cell gaps between sites below a body's width; an agent then wedged itself in
        the structure for good (gen-polyomino 026). A brick that would overlap another disc
        on the centre stays where it fell."""
        at = np.flatnonzero(self._site_codes == self._cell_code(xy[None])[0])
        if not at.size:
            return xy
        centre = self.sites_xy[at[0]]
        if self.discs.nearest(centre, 2 * self.cfg.disc_radius * (1 - 1e-6)) >= 0:
            return xy
        return centre.copy()

    def _release_dropped(self, pos: np.ndarray) -> None:
        clear = self.cfg.agent_radius + self.cfg.disc_radius
        for brick, agent in list(self._pending_release.items()):
            if np.hypot(*(pos[agent] - self.discs.xy[brick])) >= clear:
                self.physics.release_disc(brick)
                del self._pending_release[brick]

    # what the world reports ------------------------------------------------------------------
    def frame(self, agent_id: str) -> SensorFrame:
        """What the agent senses after the last tick: heading, odometry, range sectors, action results."""
        rec = self.agents[agent_id]
        i = rec.index
        flags = dict(zip(FLAGS, self.flags[i].tolist()))
        if self.cfg.cue_reach > 0 and i < len(self._cue_under):
            flags["cues"] = tuple(self._cue_ranges[i].ravel().tolist())
            flags["cue_under"] = self._cue_under[i]
        return SensorFrame(agent_id=agent_id, tick=self.tick, heading=float(self.heading[i]),
                           odom_dx=float(self.odometry[i, 0]), odom_dy=float(self.odometry[i, 1]),
                           sectors=self.cfg.sensor_sectors, ranges=tuple(self._ranges[i].ravel().tolist()),
                           holding=rec.holding >= 0, epoch=self.epoch, **flags)

    def frames(self) -> list[SensorFrame]:
        """One frame per live agent, describing the world after the last tick."""
        return [self.frame(r.agent_id) for r in self._order if r.alive]

    def encoded_frames(self) -> list[tuple[str, bytes]]:
        """(agent id, `encode(frame)`) for each frame of `frames()`, in its order: the same
        bytes, built straight from the world's arrays with one check of them all (the world
        server's per-tick path: building and checking a SensorFrame per agent was most of
        the world's time to publish a tick). Should a value fail that check, every frame is
        built as `frames()` builds it, which raises SensorFrame's own error."""
        live = [r for r in self._order if r.alive]
        rows = np.array([r.index for r in live], dtype=np.intp)
        n_cued = len(self._cue_under) if self.cfg.cue_reach > 0 else 0  # as `frame` has it
        sectors = self.cfg.sensor_sectors
        ranges, odometry = self._ranges[rows].reshape(len(rows), len(CHANNELS) * sectors), self.odometry[rows]
        cue_rows = rows[rows < n_cued]
        cues = self._cue_ranges[cue_rows].reshape(len(cue_rows), len(CUE_KINDS) * sectors)
        if not (_readings_valid(ranges) and _readings_valid(cues) and np.isfinite(odometry).all()
                and np.isfinite(self.heading[rows]).all()):
            return [(f.agent_id, encode(f)) for f in self.frames()]
        headings, odom, flags = self.heading[rows].tolist(), odometry.tolist(), self.flags[rows].tolist()
        ranges, cues = ranges.astype("<f8", copy=False), cues.astype("<f8", copy=False)
        out, k_cue = [], 0
        for k, rec in enumerate(live):
            cue_bytes, under = b"", ""
            if rec.index < n_cued:
                cue_bytes, under = cues[k_cue].tobytes(), self._cue_under[rec.index]
                k_cue += 1
            out.append((rec.agent_id, encode_checked_fields(SensorFrame, [
                rec.agent_id, self.tick, headings[k], odom[k][0], odom[k][1], sectors,
                ranges[k].tobytes(), rec.holding >= 0, *flags[k], self.epoch, cue_bytes, under])))
        return out

    def sites_filled(self) -> np.ndarray:
        """Per drop site (world order), whether a brick lies on it."""
        return self.discs.filled_sites(self._site_codes, self._cell_code)

    def completed(self) -> bool:
        """Every drop site holds a brick (and there is one): status().completed, cheaply."""
        return len(self.sites_xy) > 0 and bool(self.sites_filled().all())

    def blueprint(self) -> Blueprint:
        """The drop sites now, as the Blueprint message agents replace their site list with."""
        return Blueprint(world_id=self.world_id, tick=self.tick, version=self.blueprint_version,
                         site_xs=tuple(self.sites_xy[:, 0].tolist()), site_ys=tuple(self.sites_xy[:, 1].tolist()))

    def status(self, seq: int = 0) -> WorldStatus:
        """The build's progress and per-agent counters, as the server publishes them (`seq`:
        the server's count of publications)."""
        filled = int(self.sites_filled().sum())
        total = len(self.sites_xy)
        pos = self._positions
        return WorldStatus(
            world_id=self.world_id, scenario=self.scenario.name, seed=self.scenario.seed,
            mode=self.scenario.tick_mode, tick=self.tick, sites_filled=filled, sites_total=total,
            bricks_total=self.discs.bricks_total(), agents_alive=int(self.alive.sum()),
            bad_messages=self.bad_messages, completed=total > 0 and filled == total,
            agent_ids=tuple(r.agent_id for r in self._order), agent_alive=tuple(r.alive for r in self._order),
            agent_distance=tuple(float(self.distance[r.index]) for r in self._order),
            agent_grabs=tuple(r.grabs for r in self._order), agent_drops=tuple(r.drops for r in self._order),
            agent_restarts=tuple(r.restarts for r in self._order),
            agent_x=tuple(float(pos[r.index, 0]) for r in self._order),
            agent_y=tuple(float(pos[r.index, 1]) for r in self._order), seq=seq,
            agent_present=tuple(bool(self.solid[r.index]) for r in self._order))

    def view(self) -> WorldView:
        """What there is to draw now: discs lying in the world, sites and whether each is
        filled, bodies with headings and held bricks, wall cells, and the cues lying on the
        floor, covered or not (the WorldView message; a world without cues builds no cue list).
        Raises ValueError when the world holds more than MAX_VIEW_ITEMS discs, walls or cues."""
        _, xy, kind = self.discs.present_arrays()
        cues = self._cue_view() if self.cfg.cue_reach > 0 else {}
        filled = self.sites_filled()
        pos, order = self._positions, self._order
        return WorldView(
            world_id=self.world_id, tick=self.tick, width=float(self.size[0]), height=float(self.size[1]),
            disc_xs=tuple(xy[:, 0].tolist()), disc_ys=tuple(xy[:, 1].tolist()),
            disc_kinds=tuple(DISC_KINDS[k] for k in kind.tolist()),
            site_xs=tuple(self.sites_xy[:, 0].tolist()), site_ys=tuple(self.sites_xy[:, 1].tolist()),
            site_filled=tuple(bool(f) for f in filled.tolist()),
            agent_ids=tuple(r.agent_id for r in order), agent_alive=tuple(r.alive for r in order),
            agent_x=tuple(float(pos[r.index, 0]) for r in order), agent_y=tuple(float(pos[r.index, 1]) for r in order),
            agent_heading=tuple(float(self.heading[r.index]) for r in order),
            agent_holding=tuple(r.holding >= 0 for r in order),
            wall_xs=tuple(self._walls_xy[:, 0].tolist()), wall_ys=tuple(self._walls_xy[:, 1].tolist()), **cues)

    def _cue_view(self) -> dict[str, tuple]:
        """The WorldView's cue fields: every cue's cell centre and kind, in the board's order."""
        cells, kinds = self.cues.arrays()
        xy = self.scenario.to_world(cells)
        return {"cue_xs": tuple(xy[:, 0].tolist()), "cue_ys": tuple(xy[:, 1].tolist()),
                "cue_kinds": tuple(CUE_KINDS[k] for k in kinds.tolist())}

    def agent_poses(self) -> np.ndarray:
        """(n, 3) x, y, heading of every body, in attach order (for pictures and tests)."""
        pos, _ = self.physics.state()
        return np.column_stack([pos, self.heading]) if len(pos) else np.zeros((0, 3))

    # perturbation (paper §4.5, Fig. 6b/6c, Fig. 12) -------------------------------------------
    def perturb(self, p: Perturbation) -> PerturbResult:
        """Apply a perturbation (remove, add or move a disc; add or remove a site); says if it worked."""
        def inside(x: float, y: float) -> bool:
            return 0 <= x <= self.size[0] and 0 <= y <= self.size[1]

        if p.op in SITE_OPS:
            return self._perturb_site(p)
        if p.op == "add":
            if not inside(p.x, p.y):
                return PerturbResult(False, f"({p.x:g}, {p.y:g}) is outside the world", self.tick)
            refusal = None if p.force else self._add_refusal(p.x, p.y)
            if refusal:
                return PerturbResult(False, f"{refusal}; force to add it anyway", self.tick)
            i = self.discs.add((p.x, p.y), DISC_KINDS.index(p.kind))
            self.physics.add_disc(i, self.discs.xy[i])
            return PerturbResult(True, f"added {p.kind} #{i} at ({p.x:g}, {p.y:g})", self.tick)
        i = self.discs.nearest((p.x, p.y), self.cfg.cell_size * 0.75)
        if i < 0:
            return PerturbResult(False, f"no disc within {self.cfg.cell_size * 0.75:g} of ({p.x:g}, {p.y:g})",
                                 self.tick)
        kind = DISC_KINDS[self.discs.kind[i]]
        if p.op == "move" and not inside(p.to_x, p.to_y):
            return PerturbResult(False, f"({p.to_x:g}, {p.to_y:g}) is outside the world", self.tick)
        self.physics.remove_disc(i)
        self._pending_release.pop(i, None)
        if p.op == "remove":
            self.discs.remove(i)
            return PerturbResult(True, f"removed {kind} #{i} from ({p.x:g}, {p.y:g})", self.tick)
        self.discs.place(i, (p.to_x, p.to_y))
        self.physics.add_disc(i, self.discs.xy[i])
        return PerturbResult(True, f"moved {kind} #{i} to ({p.to_x:g}, {p.to_y:g})", self.tick)

    def _add_refusal(self, x: float, y: float) -> str | None:
        """Why a disc should not be added at (x, y) (None: nothing against it): the point is in
        a drop site's cell (a brick would fill the site), or a disc there would overlap a body."""
        if np.any(self._site_codes == self._cell_code(np.array([[x, y]]))[0]):
            col, row = (int(v) for v in self.scenario.to_cell((x, y))[0])
            return f"({x:g}, {y:g}) is in the drop site of cell ({col}, {row})"
        pos, _ = self.physics.state()
        if self.solid.any():
            d = np.where(self.solid, np.hypot(pos[:, 0] - x, pos[:, 1] - y), np.inf)
            i = int(np.argmin(d))
            if d[i] < self.cfg.disc_radius + self.cfg.agent_radius:
                return f"a disc at ({x:g}, {y:g}) would overlap the body of agent {self._order[i].agent_id}"
        return None

    def _perturb_site(self, p: Perturbation) -> PerturbResult:
        """add_site / remove_site: the cell holding (x, y) joins or leaves the blueprint.

        Only the site list changes: no disc is made or moved, so bricks_total stays, and a
        brick on a removed site is from then on a free brick like any other.
        """
        col, row = (int(v) for v in self.scenario.to_cell((p.x, p.y))[0])
        where = f"({p.x:g}, {p.y:g})"
        if not (0 <= col < self.scenario.cols and 0 <= row < self.scenario.rows):
            return PerturbResult(False, f"{where} is outside the world", self.tick)
        centre = self.scenario.to_world((col, row))
        code = self._cell_code(centre)[0]
        at = np.flatnonzero(self._site_codes == code)
        cell = f"cell ({col}, {row}) at ({centre[0, 0]:g}, {centre[0, 1]:g})"
        if p.op == "add_site":
            if self.scenario.layout[row][col] == "#":
                return PerturbResult(False, f"{cell} is a fixed obstacle (#): no drop site there", self.tick)
            held = self._food_or_water_in(code)
            if held:
                # A brick could never be dropped there (and agents take such marks for misplaced walls).
                return PerturbResult(False, f"{cell} holds {held}: no drop site there", self.tick)
            if at.size:
                return PerturbResult(False, f"{cell} is already a drop site", self.tick)
            self._set_sites(np.vstack([self.sites_xy, centre]))
            done = "added a drop site in"
        else:
            if not at.size:
                return PerturbResult(False, f"no drop site in {cell}", self.tick)
            self._set_sites(np.delete(self.sites_xy, at, axis=0))
            done = "removed the drop site of"
        return PerturbResult(True, f"{done} {cell}: {len(self.sites_xy)} sites, blueprint version "
                                   f"{self.blueprint_version}", self.tick)

    def _food_or_water_in(self, code: int) -> str:
        """"food" or "water" if such a disc lies in the cell of `code` (`_cell_code`) now, else ""."""
        _, xy, kind = self.discs.present_arrays()
        there = kind[self._cell_code(xy) == code] if len(xy) else kind[:0]
        for k, name in ((FOOD_DISC, "food"), (WATER_DISC, "water")):
            if np.any(there == k):
                return name
        return ""

    def _set_sites(self, sites_xy: np.ndarray) -> None:
        # The cell codes are what filling and completion are computed from: always together.
        self.sites_xy = sites_xy
        self._site_codes = self._cell_code(sites_xy)
        self.blueprint_version += 1


def _obstacle_points(scenario: Scenario, walls: np.ndarray) -> np.ndarray:
    """World positions the obstacle sensors report: every `#` cell's centre, and the
    centre of every cell of a one-cell ring just outside the world (its edge is a wall
    too, and an agent that cannot see it pushes into it)."""
    cols, rows = scenario.cols, scenario.rows
    ring = [(c, r) for c in range(-1, cols + 1) for r in (-1, rows)]
    ring += [(c, r) for r in range(rows) for c in (-1, cols)]
    return scenario.to_world(np.vstack([np.asarray(walls, np.int64).reshape(-1, 2), np.array(ring, np.int64)]))


def _readings_valid(readings: np.ndarray) -> bool:
    """Whether every range reading is finite and either >= 0 or NO_READING (SensorFrame's rule)."""
    return bool(np.isfinite(readings).all() and ((readings >= 0.0) | (readings == NO_READING)).all())

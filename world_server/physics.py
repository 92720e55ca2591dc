"""The pymunk side of the world: static discs and obstacles, agent bodies with inertia.

Discs are static circles (agents bump into them, never push them: a structure must not
drift). Agents are dynamic round bodies that cannot spin. All per-tick body access is
batched through `pymunk.batch`, one call to read every agent and one to write them.
"""

from __future__ import annotations

import math

import numpy as np
import pymunk
import pymunk.batch as batch
from numba import njit

from world_server.config import WorldConfig

_READ = batch.BodyFields.BODY_ID | batch.BodyFields.POSITION | batch.BodyFields.VELOCITY


class Physics:
    """The pymunk space: static discs and obstacle walls, and one round body per agent."""

    def __init__(self, cfg: WorldConfig, size: tuple[float, float], obstacles_xy: np.ndarray):
        self.cfg = cfg
        self.space = pymunk.Space()
        self.space.gravity = (0.0, 0.0)
        self.space.collision_slop = 0.01  # contacts as tight as the map cares about
        self._bodies: list[pymunk.Body] = []
        self._shapes: list[pymunk.Circle] = []
        self._discs: dict[int, pymunk.Circle] = {}
        self._rows = np.zeros(0, np.int64)  # batch row of each agent body
        self._nrows = 0
        self._state: tuple[np.ndarray, np.ndarray] | None = None  # read once per step
        self._read = batch.Buffer()
        self._write = batch.Buffer()
        self._add_boundary(*size)
        half = cfg.cell_size / 2
        for x, y in np.asarray(obstacles_xy).reshape(-1, 2):
            box = pymunk.Poly(self.space.static_body, [(x - half, y - half), (x + half, y - half),
                                                       (x + half, y + half), (x - half, y + half)])
            self.space.add(box)

    def _add_boundary(self, width: float, height: float) -> None:
        corners = [(0, 0), (width, 0), (width, height), (0, height)]
        for a, b in zip(corners, corners[1:] + corners[:1]):
            self.space.add(pymunk.Segment(self.space.static_body, a, b, 0.05))

    # discs -------------------------------------------------------------------------
    def add_disc(self, index: int, xy: tuple[float, float] | np.ndarray, group: int = 0) -> None:
        """A static circle for disc `index` at `xy`; `group` (an agent's index + 1) lets that agent
        pass through it (a brick it has just dropped).
        """
        shape = pymunk.Circle(self.space.static_body, self.cfg.disc_radius, (float(xy[0]), float(xy[1])))
        shape.filter = pymunk.ShapeFilter(group=group)
        self.space.add(shape)
        self._discs[index] = shape

    def remove_disc(self, index: int) -> None:
        """Take disc `index` out of the space (grabbed or removed)."""
        self.space.remove(self._discs.pop(index))

    def release_disc(self, index: int) -> None:
        """Let a just-dropped brick collide with the agent that dropped it again."""
        self._discs[index].filter = pymunk.ShapeFilter(group=0)

    # agents ------------------------------------------------------------------------
    def add_agent(self, xy: tuple[float, float] | np.ndarray) -> int:
        """Add a round agent body; returns its index. Its collision group is index + 1,
        which a brick it drops shares until the agent has moved off it."""
        return self.add_agents(np.asarray(xy, np.float64).reshape(1, 2))[0]

    def add_agents(self, positions: np.ndarray) -> range:
        """Add one body per row of `positions` (as `add_agent`, mapping the batch rows once:
        a space rebuilt with many bodies would otherwise take quadratic time); their indices."""
        first = len(self._bodies)
        for xy in np.asarray(positions, np.float64).reshape(-1, 2):
            body = pymunk.Body(self.cfg.agent_mass, math.inf)
            body.position = (float(xy[0]), float(xy[1]))
            shape = pymunk.Circle(body, self.cfg.agent_radius)
            shape.filter = pymunk.ShapeFilter(group=len(self._bodies) + 1)
            self.space.add(body, shape)
            self._bodies.append(body)
            self._shapes.append(shape)
        self._map_rows()
        self._state = None
        return range(first, len(self._bodies))

    def set_solid(self, index: int, solid: bool) -> None:
        """Whether agent body `index` collides with anything: a dead agent's body stops
        colliding once its grace period is over (it stays in the space, where the batch
        reads it, but its shape filter matches nothing)."""
        group = index + 1
        self._shapes[index].filter = (pymunk.ShapeFilter(group=group) if solid
                                      else pymunk.ShapeFilter(group=group, categories=0, mask=0))

    def place_body(self, index: int, xy: tuple[float, float] | np.ndarray) -> None:
        """Put agent body `index` at `xy`, at rest (a restarted agent's body comes back)."""
        body = self._bodies[index]
        body.position = (float(xy[0]), float(xy[1]))
        body.velocity = (0.0, 0.0)
        self.space.reindex_shapes_for_body(body)
        self._state = None

    def set_velocity(self, index: int, velocity: tuple[float, float] | np.ndarray) -> None:
        """Give agent body `index` this velocity (a space rebuilt from a checkpoint)."""
        self._bodies[index].velocity = (float(velocity[0]), float(velocity[1]))
        self._state = None

    def _map_rows(self) -> None:
        # The batch iterates every body of the space (the static one too) in the space's
        # own order; map each agent to its row once, whenever a body is added.
        self._read.clear()
        batch.get_space_bodies(self.space, batch.BodyFields.BODY_ID, self._read)
        ids = np.frombuffer(self._read.int_buf(), dtype=np.uintp)
        row_of = {int(i): r for r, i in enumerate(ids)}
        self._rows = np.array([row_of[b.id] for b in self._bodies], dtype=np.int64)
        self._nrows = len(ids)
        self._force_rows = np.zeros((self._nrows, 2))

    @property
    def agent_count(self) -> int:
        """How many agent bodies there are (dead ones included)."""
        return len(self._bodies)

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        """(positions, velocities) of every agent body, each (n, 2), in agent order.

        Read from pymunk once per change (a step, a new body); treat as read-only.
        """
        if self._state is None:
            if not self._bodies:
                return np.zeros((0, 2)), np.zeros((0, 2))
            self._read.clear()
            batch.get_space_bodies(self.space, _READ, self._read)
            rows = np.frombuffer(self._read.float_buf()).reshape(self._nrows, 4)[self._rows]
            self._state = (rows[:, :2].copy(), rows[:, 2:].copy())
        return self._state

    def drive(self, velocity: np.ndarray, desired: np.ndarray) -> None:
        """Make each body reach `desired` velocity during the next step, contacts permitting.

        Chipmunk moves bodies with their current velocity *before* it solves contacts,
        so writing velocities directly would push bodies into discs every tick. A force
        enters after contact detection instead, and the solver keeps it out of obstacles.
        """
        if not self._bodies:
            return
        force = (desired - velocity) * (self.cfg.agent_mass / self.cfg.dt)
        self._force_rows[self._rows] = force
        self._write.set_float_buf(np.ascontiguousarray(self._force_rows.ravel()))
        batch.set_space_bodies(self.space, batch.BodyFields.FORCE, self._write)

    def step(self) -> None:
        """Advance the space by one tick (`dt` simulated seconds)."""
        self.space.step(self.cfg.dt)
        self._state = None


@njit(cache=True)
def motor_update(heading, turn, speed, alive, velocity, inertia):
    """Turn every live body and return the velocities it should have after this tick.

    Heading += turn (wrapped to [-pi, pi)); the velocity closes `inertia` of the gap to
    `speed` along the new heading. The current velocity already includes what contacts
    did to it, so a blocked body does not build up speed it never had. Dead bodies stop.
    One compiled pass instead of a dozen small array operations per tick.
    """
    desired = np.zeros_like(velocity)
    for i in range(heading.shape[0]):
        if not alive[i]:
            continue
        h = (heading[i] + turn[i] + np.pi) % (2.0 * np.pi) - np.pi
        heading[i] = h
        desired[i, 0] = velocity[i, 0] + inertia * (speed[i] * np.cos(h) - velocity[i, 0])
        desired[i, 1] = velocity[i, 1] + inertia * (speed[i] * np.sin(h) - velocity[i, 1])
    return desired

"""World configuration: a frozen dataclass, loaded from a TOML table.

Units: one world unit is one map cell, which is one disc diameter (paper §3; W1). Time
advances in ticks of `dt` simulated seconds.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass


@dataclass(frozen=True)
class WorldConfig:
    """The world's physical settings (sizes, speeds, sensors, gripper, noise); frozen."""

    cell_size: float = 1.0          # one disc diameter; layout cells are this wide
    disc_radius: float = 0.5
    agent_radius: float = 0.3       # < disc_radius so an agent fits through a one-cell gap
    agent_mass: float = 1.0
    dt: float = 0.1                 # simulated seconds per tick
    max_speed: float = 3.0          # world units per simulated second
    max_turn: float = math.pi / 2   # radians per tick
    inertia: float = 0.5            # fraction of the speed error closed per tick (1 = no inertia)
    sensor_sectors: int = 16
    sensor_range: float = 6.0
    sensor_noise: float = 0.02      # noise std per unit of distance (uniform, zero mean): far readings are worse
    odometry_noise: float = 0.0     # noise std per unit of distance moved (normal, the same in every direction)
    # Noise and occlusion (docs/noise.md); all off by default.
    odometry_distance_slip: float = 0.0  # std of the relative error of each step's reported length
    odometry_heading_slip: float = 0.0   # std (radians) of the error of each step's reported direction
    occlusion: bool = False         # a sector reports only the nearest object of any channel in it
    aliasing: float = 0.0           # probability a sector reports the second nearest disc of its colour
    cue_reach: float = 0.0          # cues (world_server/cues.py): a body marks cells within this distance
                                    # of its centre; 0: the world has no cues (frames carry no cue channel)
    grab_reach: float = 1.2         # agent centre to brick centre
    grab_cone: float = math.pi / 3  # the gripper takes bricks within this angle of the heading
    touch_margin: float = 0.25      # eat/drink: surfaces closer than this count as touching (an
                                    # agent on the centre of the next cell touches the disc)
    lockstep_timeout: float = 1.0   # wall seconds the world waits for a live agent's command
    tick_rate: float = 50.0         # ticks per wall second in realtime mode
    status_period: float = 0.5      # wall seconds between status publications
    body_grace_ticks: int = 100     # ticks a dead agent's body stays solid before it leaves the world
    lockstep_miss_limit: int = 3    # lockstep deadlines missed in a row before the world stops waiting

    @property
    def drop_tolerance(self) -> float:
        """How far from a site cell's centre (along x and along y) a dropped brick still fills
        the site: the brick lands at the agent's centre, and a site is filled by a brick whose
        centre lies in its cell."""
        return self.cell_size / 2

    def __post_init__(self) -> None:
        positive = ("cell_size", "disc_radius", "agent_radius", "agent_mass", "dt", "max_speed",
                    "max_turn", "sensor_range", "grab_reach", "grab_cone", "lockstep_timeout", "tick_rate",
                    "status_period")
        for name in positive:
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"world.{name} must be a finite number > 0, got {value!r}")
        for name in ("sensor_noise", "odometry_noise", "touch_margin"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"world.{name} must be >= 0")
        for name in ("odometry_distance_slip", "odometry_heading_slip", "cue_reach"):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0):
                raise ValueError(f"world.{name} must be a finite number >= 0, got {value!r}")
        if not (isinstance(self.aliasing, (int, float)) and 0 <= self.aliasing <= 1):
            raise ValueError(f"world.aliasing must be a probability from 0 to 1, got {self.aliasing!r}")
        if not isinstance(self.occlusion, bool):
            raise ValueError(f"world.occlusion must be true or false, got {self.occlusion!r}")
        if self.max_speed * self.dt > self.agent_radius * (1 + 1e-9):
            # The physics has no continuous collision detection: a body that moves further
            # than its radius in one tick can jump through the world's boundary.
            raise ValueError("world.max_speed * world.dt must be <= world.agent_radius "
                             "(a body may move at most its radius per tick)")
        if not 0 < self.inertia <= 1:
            raise ValueError("world.inertia must be in (0, 1]")
        if not (isinstance(self.body_grace_ticks, int) and self.body_grace_ticks >= 0):
            raise ValueError("world.body_grace_ticks must be an integer >= 0")
        if not (isinstance(self.lockstep_miss_limit, int) and self.lockstep_miss_limit >= 1):
            raise ValueError("world.lockstep_miss_limit must be an integer >= 1")
        if not (isinstance(self.sensor_sectors, int) and 1 <= self.sensor_sectors <= 64):
            raise ValueError("world.sensor_sectors must be an integer from 1 to 64")

    @classmethod
    def from_mapping(cls, table: dict) -> WorldConfig:
        """Build from a TOML table, rejecting unknown keys (a typo must not pass silently)."""
        known = {f.name: f.type for f in dataclasses.fields(cls)}
        unknown = sorted(set(table) - set(known))
        if unknown:
            raise ValueError(f"unknown world setting(s): {', '.join(unknown)}; "
                             f"known: {', '.join(known)}")
        values = {}
        for key, value in table.items():
            default = getattr(cls, key)
            if isinstance(default, bool):
                if not isinstance(value, bool):
                    raise ValueError(f"world.{key} must be true or false")
            elif isinstance(default, int):
                if not isinstance(value, int) or isinstance(value, bool):
                    raise ValueError(f"world.{key} must be an integer")
            elif isinstance(default, float):
                if not isinstance(value, (int, float)) or isinstance(value, bool):
                    raise ValueError(f"world.{key} must be a number")
                value = float(value)
            values[key] = value
        return cls(**values)

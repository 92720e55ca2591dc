"""Noise and occlusion settings a run puts on top of its scenario's world (docs/noise.md).

The world's noise is part of its `WorldConfig` (a scenario's `[world]` table): sensor
noise, odometry noise and slip, occlusion and perceptual aliasing. `NoiseSettings` is
the typed set of overrides the command line (`conag run`, `conag world`) and the
experiments hand on: each field left at None keeps the scenario's value, and
`sensor_noise_scale` multiplies the scenario's sensor noise. `apply` gives the scenario
with the overrides in its world (validated as a scenario file's are); `to_args` gives the
command-line flags that ask for the same, for a process started by another.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

from world_server.scenario import Scenario

# NoiseSettings field -> the WorldConfig field it overrides (sensor_noise_scale multiplies).
_OVERRIDES = ("odometry_noise", "odometry_distance_slip", "odometry_heading_slip", "occlusion", "aliasing")


@dataclass(frozen=True)
class NoiseSettings:
    """Overrides of a scenario's noise settings; the defaults change nothing."""

    odometry_noise: float | None = None          # std per unit moved, the same in every direction
    odometry_distance_slip: float | None = None  # std of each step's relative length error
    odometry_heading_slip: float | None = None   # std (radians) of each step's direction error
    sensor_noise_scale: float = 1.0              # times the scenario's sensor_noise
    occlusion: bool | None = None                # a sector reports only its nearest object of any colour
    aliasing: float | None = None                # probability a sector reports the second nearest disc

    def __post_init__(self) -> None:
        if not self.sensor_noise_scale >= 0:
            raise ValueError(f"the sensor noise scale must be >= 0, got {self.sensor_noise_scale!r}")

    @property
    def changes_nothing(self) -> bool:
        """True when `apply` returns the scenario as it is."""
        return self == NoiseSettings()

    def apply(self, scenario: Scenario) -> Scenario:
        """`scenario` with these overrides in its world; ValueError for a bad value (a
        negative noise, a probability outside [0, 1]), as a scenario file's [world] gets."""
        if self.changes_nothing:
            return scenario
        world = scenario.world
        values = {name: getattr(self, name) for name in _OVERRIDES if getattr(self, name) is not None}
        if self.sensor_noise_scale != 1.0:
            values["sensor_noise"] = world.sensor_noise * self.sensor_noise_scale
        return dataclasses.replace(scenario, world=dataclasses.replace(world, **values))

    def to_args(self) -> list[str]:
        """The `conag world` flags that ask for these overrides (none for the defaults)."""
        args: list[str] = []
        for name in _OVERRIDES:
            value = getattr(self, name)
            if value is None:
                continue
            flag = "--" + name.replace("_", "-")
            args += ([flag] if value else [f"--no-{name}"]) if isinstance(value, bool) else [flag, repr(value)]
        if self.sensor_noise_scale != 1.0:
            args += ["--sensor-noise-scale", repr(self.sensor_noise_scale)]
        return args

    def label(self) -> str:
        """A short description of the overrides, e.g. "odometry slip 0.05, occlusion"."""
        parts = [f"{name.replace('_', ' ')} {value:g}" for name in _OVERRIDES
                 if (value := getattr(self, name)) is not None and not isinstance(value, bool)]
        if self.occlusion is not None:
            parts.append("occlusion" if self.occlusion else "no occlusion")
        if self.sensor_noise_scale != 1.0:
            parts.append(f"sensor noise x{self.sensor_noise_scale:g}")
        return ", ".join(parts) or "as the scenario says"

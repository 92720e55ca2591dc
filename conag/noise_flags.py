"""The noise and occlusion flags of `conag world` and `conag run` (docs/noise.md).

`add_noise_args` adds them to a subcommand's parser; `noise_settings` reads them back as
a `world_server.noise.NoiseSettings`, the typed overrides the world applies to its
scenario (`conag run` hands them on to its world process with `NoiseSettings.to_args`).
Left out, a flag keeps what the scenario file says.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math

from world_server.noise import NoiseSettings


def _non_negative(text: str) -> float:
    value = float(text)
    if not (math.isfinite(value) and value >= 0):
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, got {text!r}")
    return value


def _probability(text: str) -> float:
    value = float(text)
    if not 0 <= value <= 1:
        raise argparse.ArgumentTypeError(f"must be a probability from 0 to 1, got {text!r}")
    return value


def add_noise_args(p: argparse.ArgumentParser) -> None:
    """The flags that override the scenario's noise settings (its [world] table)."""
    g = p.add_argument_group("noise and occlusion (docs/noise.md; default: as the scenario file says)")
    g.add_argument("--odometry-noise", type=_non_negative, metavar="S",
                   help="odometry error std per unit moved, in every direction (world.odometry_noise)")
    g.add_argument("--odometry-distance-slip", type=_non_negative, metavar="S",
                   help="std of each step's relative length error, e.g. 0.05 (world.odometry_distance_slip)")
    g.add_argument("--odometry-heading-slip", type=_non_negative, metavar="RAD",
                   help="std of each step's direction error, radians (world.odometry_heading_slip)")
    g.add_argument("--sensor-noise-scale", type=_non_negative, default=1.0, metavar="K",
                   help="multiply the scenario's sensor noise (world.sensor_noise, 0.02 per unit distance "
                        "unless the file says otherwise) by K")
    g.add_argument("--occlusion", action=argparse.BooleanOptionalAction, default=None,
                   help="a sector reports only its nearest object of any colour (world.occlusion)")
    g.add_argument("--aliasing", type=_probability, metavar="P",
                   help="probability a sector reports the second nearest disc of a colour (world.aliasing)")


def noise_settings(args: argparse.Namespace) -> NoiseSettings:
    """The NoiseSettings the flags of `add_noise_args` ask for."""
    return NoiseSettings(odometry_noise=args.odometry_noise, odometry_distance_slip=args.odometry_distance_slip,
                         odometry_heading_slip=args.odometry_heading_slip,
                         sensor_noise_scale=args.sensor_noise_scale, occlusion=args.occlusion,
                         aliasing=args.aliasing)


def to_note(settings: NoiseSettings) -> str:
    """The settings as a recording's metadata note (JSON), for `from_note`."""
    return json.dumps(dataclasses.asdict(settings), sort_keys=True)


def from_note(text: str) -> NoiseSettings:
    """The settings a `to_note` text holds."""
    return NoiseSettings(**json.loads(text))

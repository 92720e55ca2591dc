"""Turning a chosen behaviour into a motor command (speed, turn) for the world.

Navigation picks one of the 8 neighbouring cells (the steepest gradient of a navigation
map); the agent then steers for that cell's centre rather than along a bare compass
direction, which keeps it on the grid the maps are made of and lets inertia smooth the
path (paper §4.2.2). Speeds are in world units per second, turns in radians per tick.
"""

from __future__ import annotations

import math

import numpy as np


def wrap(angle: float) -> float:
    """The angle in [-pi, pi)."""
    return (angle + math.pi) % (2 * math.pi) - math.pi


def steer_to(dx: float, dy: float, heading: float, cruise: float) -> tuple[float, float]:
    """Head for the point (dx, dy) (cells, x east, y north) and slow down near it.

    Speed drops with the heading error (turn first, then go) and with the distance, so
    inertia does not carry the body past a target one cell away.
    """
    dist = math.hypot(dx, dy)
    if dist < 1e-6:
        return 0.0, 0.0
    err = wrap(math.atan2(dy, dx) - heading)
    alignment = max(0.0, math.cos(err))
    speed = min(cruise, 1.5 * dist) * alignment ** 4
    return speed, err


def away_from(dx: float, dy: float, heading: float, cruise: float) -> tuple[float, float]:
    """Steer directly away from the point (dx, dy)."""
    return steer_to(-dx, -dy, heading, cruise)


def explore(rng: np.random.Generator, max_turn: float, cruise: float) -> tuple[float, float]:
    """A random walk: keep going, with a random turn each tick (the injected generator)."""
    return 0.6 * cruise, float(rng.uniform(-max_turn, max_turn))

"""Failure cases of the reactive baseline (R4, Fig. 12 and Fig. 14).

Fig. 12: one brick placed by an agent is moved to a neighbouring cell while
the square is being built; the rules, which only see local patterns, keep
growing walls from the displaced brick and a different structure results.

Fig. 14: a square enclosing a smaller square, both grown from corner seeds
with the same rule set.  Agents enter from outside, so once the outer ring
closes no new agent can reach the inner one, which stays unfinished.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .lattice import LATTICE_BRICK, LATTICE_EMPTY, World, make_world, rule_policy, simulate, step
from .rules import corner_rules, corner_seeds, square_target

STEPS = {"out": 1, "in": -1}


def outward(pos, target_origin, n) -> tuple[int, int]:
    """The unit step from a ring cell away from the ring's centre (one axis)."""
    r0, c0 = target_origin
    r, c = pos
    if r == r0:
        return (-1, 0)
    if r == r0 + n - 1:
        return (1, 0)
    return (0, -1) if c == c0 else (0, 1)


def placed_bricks(world: World, seeds: dict) -> list[tuple[int, int]]:
    """Bricks laid by agents (not seeds), in a deterministic order."""
    rows, cols = np.nonzero(world.grid == LATTICE_BRICK)
    return sorted(p for p in zip(rows.tolist(), cols.tolist()) if p not in seeds)


def move_brick(world: World, src, dst) -> bool:
    """Move one brick (with its state) to a free cell; False if not possible."""
    if world.grid[dst] != LATTICE_EMPTY or dst in world.agents:
        return False
    world.grid[dst], world.brick_state[dst] = LATTICE_BRICK, world.brick_state[src]
    world.grid[src], world.brick_state[src] = LATTICE_EMPTY, 0
    return True


class BrickMover:
    """An `on_step` hook: from `at_step` on, move the first placed brick once.

    The brick moves one cell away from ("out") or towards ("in") the centre.
    `moved` records (src, dst) once done.
    """

    def __init__(self, at_step: int, seeds: dict, origin, n: int, direction: str = "out"):
        self.at_step, self.seeds, self.origin, self.n = at_step, seeds, origin, n
        self.sign = STEPS[direction]
        self.moved: tuple[tuple[int, int], tuple[int, int]] | None = None

    def __call__(self, world: World, t: int) -> None:
        """Once `at_step` is reached, move the first placed brick that can move (once only)."""
        if self.moved or t < self.at_step:
            return
        for src in placed_bricks(world, self.seeds):
            dr, dc = outward(src, self.origin, self.n)
            dst = (src[0] + self.sign * dr, src[1] + self.sign * dc)
            if move_brick(world, src, dst):
                self.moved = (src, dst)
                return


def run_perturbed(rule_set, seeds, shape, n, origin, at_step, direction, n_agents,
                  max_steps, rng):
    """Simulate with one brick moved at `at_step`; returns (result, move)."""
    hook = BrickMover(at_step, seeds, origin, n, direction)
    result = simulate(rule_set, seeds, shape, n_agents, max_steps, rng, on_step=hook)
    return result, hook.moved


def ring_done(world: World, ring: np.ndarray) -> bool:
    """Whether every cell of the ring mask holds a brick."""
    return bool(np.all(world.grid[ring == LATTICE_BRICK] == LATTICE_BRICK))


def inside(pos, origin, n) -> bool:
    """Whether `pos` lies strictly inside the n x n square at `origin`."""
    return all(o < p < o + n - 1 for p, o in zip(pos, origin))


@dataclass(frozen=True)
class NestedResult:
    """How the nested squares went (Fig. 14), and the final lattice."""

    outer: int | None     # the step the outer ring was finished at, None if never
    inner: int | None     # the same for the inner ring
    enclosed: int | None  # agents inside the outer ring when it closed, None if it never did
    world: World


def nested_squares(outer_n: int, inner_n: int, n_agents: int, max_steps: int,
                   rng: np.random.Generator, margin: int = 3) -> NestedResult:
    """Build a ring inside a ring with the corner rules (Fig. 14)."""
    shape = (outer_n + 2 * margin,) * 2
    outer_o = (margin, margin)
    inner_o = (margin + (outer_n - inner_n) // 2,) * 2
    outer = square_target(outer_n, outer_o, shape)
    inner = square_target(inner_n, inner_o, shape)
    world = make_world(shape, {**corner_seeds(outer_n, outer_o),
                               **corner_seeds(inner_n, inner_o)})
    rules = corner_rules(outer | inner)
    outer_at: int | None = None
    inner_at: int | None = None
    enclosed: int | None = None
    for t in range(1, max_steps + 1):
        step(world, rule_policy(rules), n_agents, rng)
        if inner_at is None and ring_done(world, inner):
            inner_at = t
        if outer_at is None and ring_done(world, outer):
            outer_at = t
            enclosed = sum(inside(p, outer_o, outer_n) for p in world.agents)
        if inner_at and outer_at:
            break
    return NestedResult(outer_at, inner_at, enclosed, world)

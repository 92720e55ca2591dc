"""Transition rule sets for square rings, after Jones & Mataric (R2, Fig. 10).

Design.  A wall is grown by agents that attach behind a brick: an agent
whose neighbour *behind* it (opposite the growth direction) is a brick in
state k becomes a brick in state k' — the state variable is how the
structure remembers which wall, and how far along it, a brick belongs to.

Corner seeds (Fig. 10b): 4 states, one per corner (TL, TR, BR, BL), and 8
rules: each corner grows its two walls towards the neighbouring corners
(TL east and south, TR west and south, BR west and north, BL east and north);
each new brick copies the corner's state.  The walls of one corner meet the
walls of the next corner half way, so no counting is needed.  Because one
state grows in two directions, a brick of the left wall in state TL would
also make the interior cell east of it look like "the top wall, growing
east".  Each rule therefore also requires the corner's own outer diagonal
(NW for TL, NE for TR, ...) to hold no brick: on the true wall that cell is
outside the square (never built), whereas for an interior cell it is the
previous brick of the contiguous wall.

Side seeds (Fig. 10c): a seed in the middle of a side must grow both ways
and stop exactly at the corners, which a local pattern cannot see (every
straight wall cell looks alike).  So the state counts the distance from the
seed: one state and one rule per wall cell, k -> k+1, with no rule for the
corner state.  That gives 4 + 4(n-1) states and 4(n-1) rules: they grow with
the side n.  The same outer-diagonal guard is kept (it is harmless there).
"""
from __future__ import annotations

import numpy as np

from .lattice import BLANK, LATTICE_BRICK, NE, NO_BRICK, NW, SE, SW, E, N, Rule, RuleSet, S, W

TL, TR, BR, BL = 1, 2, 3, 4

# (corner state, behind neighbour, outer diagonal) for each growth direction.
CORNER_GROWTH = (
    (TL, W, NW), (TL, N, NW),  # top wall east, left wall south
    (TR, E, NE), (TR, N, NE),  # top wall west, right wall south
    (BR, E, SE), (BR, S, SE),  # bottom wall west, right wall north
    (BL, W, SW), (BL, S, SW),  # bottom wall east, left wall north
)


def grow(behind: int, from_state: int, guard: int, new_state: int) -> Rule:
    """A wandering agent attaches behind a `from_state` brick."""
    return Rule(BLANK, ((behind, from_state), (guard, NO_BRICK)), "brick", new_state)


def square_target(n: int, origin: tuple[int, int], shape) -> np.ndarray:
    """The ring of side n whose top-left corner is `origin`."""
    grid = np.zeros(shape, dtype=int)
    r, c = origin
    grid[r:r + n, c:c + n] = LATTICE_BRICK
    grid[r + 1:r + n - 1, c + 1:c + n - 1] = 0
    return grid


def corner_seeds(n: int, origin) -> dict:
    """The four corner seeds of an n x n square at `origin`: {cell: corner state}."""
    r, c = origin
    return {(r, c): TL, (r, c + n - 1): TR, (r + n - 1, c + n - 1): BR, (r + n - 1, c): BL}


def corner_rules(target: np.ndarray | None = None) -> RuleSet:
    """4 states, 8 rules; independent of the side of the square."""
    rules = tuple(grow(behind, s, guard, s) for s, behind, guard in CORNER_GROWTH)
    return RuleSet(rules, target)


def side_layout(n: int, origin):
    """Seed position and its two growth arms (behind, guard, length) per side."""
    r, c = origin
    m = n // 2
    return (
        ((r, c + m), ((W, NW, n - 1 - m), (E, NE, m))),          # top: east, west
        ((r + m, c + n - 1), ((N, NE, n - 1 - m), (S, SE, m))),  # right: south, north
        ((r + n - 1, c + m), ((W, SW, n - 1 - m), (E, SE, m))),  # bottom: east, west
        ((r + m, c), ((N, NW, n - 1 - m), (S, SW, m))),          # left: south, north
    )


def side_seeded(n: int, origin, shape) -> tuple[RuleSet, dict]:
    """Rule set and seeds for a ring of side n seeded at the middle of each side."""
    seeds, rules, next_state = {}, [], 1
    for pos, arms in side_layout(n, origin):
        seed_state, next_state = next_state, next_state + 1
        seeds[pos] = seed_state
        for behind, guard, length in arms:
            prev = seed_state
            for _ in range(length):  # one counting state per wall cell
                rules.append(grow(behind, prev, guard, next_state))
                prev, next_state = next_state, next_state + 1
    return RuleSet(tuple(rules), square_target(n, origin, shape)), seeds


def corner_seeded(n: int, origin, shape) -> tuple[RuleSet, dict]:
    """Rule set and seeds for a ring of side n seeded at its 4 corners."""
    return corner_rules(square_target(n, origin, shape)), corner_seeds(n, origin)


def square_rules(n: int, seeding: str, margin: int = 3):
    """(rule set, seeds, shape) for a ring of side n centred with a margin."""
    shape = (n + 2 * margin, n + 2 * margin)
    build = {"corners": corner_seeded, "sides": side_seeded}[seeding]
    rule_set, seeds = build(n, (margin, margin), shape)
    return rule_set, seeds, shape

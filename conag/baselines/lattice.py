"""Jones & Mataric (2003)-style reactive construction on a square lattice (R1).

The world is a numpy int grid (0 empty, 1 brick) plus the visible state of
every brick (a brick is an agent that stopped, and keeps its state variable).
Agents occupy cells, move one cell at a time in the 4-neighbourhood, and sense
only their 8 neighbours: for each one its occupancy kind and visible state.
Every step each agent, in a seeded random order, looks its (state, pattern)
up in the transition rule set; the first matching rule gives (action, new
state).  Actions: become a brick, or wait.  With no matching rule the agent
explores: it moves to a random free 4-neighbour (the implicit default that
Jones & Mataric also use, so it is not counted as a rule).  Agents enter at
free cells of the grid border, outside the structure, up to a population.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

LATTICE_EMPTY, LATTICE_BRICK = 0, 1  # the grid's cell values
BLANK = 0  # state of a wandering agent; construction states are >= 1

# 8-neighbourhood, clockwise from north; index constants name the directions.
OFFSETS = ((-1, 0), (-1, 1), (0, 1), (1, 1), (1, 0), (1, -1), (0, -1), (-1, -1))
N, NE, E, SE, S, SW, W, NW = range(8)
MOVES = (N, E, S, W)

# Occupancy kinds in a sensed pattern entry (kind, visible state): what an agent sees of a neighbour.
SEEN_FREE, SEEN_WALL, SEEN_AGENT, SEEN_EDGE = 0, 1, 2, 3
NO_BRICK = -1  # rule condition: the neighbour is not a brick


@dataclass(frozen=True)
class Rule:
    """If own state is `state` and every (neighbour, condition) holds, act.

    A condition is a brick state (the neighbour is a brick in that state)
    or NO_BRICK.  Neighbours not named are "don't care".
    """

    state: int
    require: tuple[tuple[int, int], ...]
    action: str  # "brick" or "wait"
    new_state: int


@dataclass(eq=False)
class RuleSet:
    """A transition rule set, optionally with the target it should build."""

    rules: tuple[Rule, ...]
    target: np.ndarray | None = None

    @property
    def states(self) -> set[int]:
        """Distinct construction states used by the rules (BLANK excluded)."""
        found = set()
        for rule in self.rules:
            found.update({rule.state, rule.new_state})
            found.update(c for _, c in rule.require)
        return found - {BLANK, NO_BRICK}


@dataclass(eq=False)
class World:
    """Bricks (grid), their visible states, and agents (position -> state)."""

    grid: np.ndarray
    brick_state: np.ndarray
    agents: dict[tuple[int, int], int] = field(default_factory=dict)


@dataclass(eq=False)
class Result:
    """How a lattice run ended: the final grid and brick states, the steps taken, built or not."""

    grid: np.ndarray
    brick_state: np.ndarray
    steps: int
    built: bool


def make_world(shape: tuple[int, int], seeds: dict[tuple[int, int], int]) -> World:
    """An empty lattice holding the seed bricks (position -> state)."""
    grid = np.zeros(shape, dtype=int)
    states = np.zeros(shape, dtype=int)
    for pos, state in seeds.items():
        grid[pos], states[pos] = LATTICE_BRICK, state
    return World(grid, states)


def neighbour(pos: tuple[int, int], index: int) -> tuple[int, int]:
    """The cell next to `pos` in direction `index` (N, NE, ... NW)."""
    dr, dc = OFFSETS[index]
    return pos[0] + dr, pos[1] + dc


def cell_view(world: World, pos: tuple[int, int]) -> tuple[int, int]:
    """What a neighbour sees of one cell: (kind, visible state)."""
    rows, cols = world.grid.shape
    if not (0 <= pos[0] < rows and 0 <= pos[1] < cols):
        return SEEN_EDGE, BLANK
    if world.grid[pos] == LATTICE_BRICK:
        return SEEN_WALL, int(world.brick_state[pos])
    if pos in world.agents:
        return SEEN_AGENT, world.agents[pos]
    return SEEN_FREE, BLANK


def sense(world: World, pos: tuple[int, int]) -> tuple[tuple[int, int], ...]:
    """The agent's whole percept: its 8 neighbours, nothing else."""
    return tuple(cell_view(world, neighbour(pos, i)) for i in range(8))


def holds(condition: int, seen: tuple[int, int]) -> bool:
    """Whether a sensed neighbour (kind, state) meets a rule condition (a brick state or NO_BRICK)."""
    kind, state = seen
    if condition == NO_BRICK:
        return kind != SEEN_WALL
    return kind == SEEN_WALL and state == condition


def matches(rule: Rule, state: int, pattern) -> bool:
    """Whether `rule` fires for an agent in `state` sensing `pattern` (8 neighbours)."""
    return rule.state == state and all(holds(c, pattern[i]) for i, c in rule.require)


def decide(rule_set: RuleSet, state: int, pattern, rng: np.random.Generator):
    """(action, argument): ("brick", new state), ("wait", state) or ("move", dir)."""
    for rule in rule_set.rules:
        if matches(rule, state, pattern):
            return rule.action, rule.new_state
    free = [d for d in MOVES if pattern[d][0] == SEEN_FREE]
    if not free:
        return "wait", state
    return "move", free[int(rng.integers(len(free)))]


# A policy maps (own state, 8-neighbour pattern, rng) to a decision, as `decide` does
# for a rule set; a learned network (conag/baselines/learned.py) is another policy.
Policy = Callable[[int, tuple, np.random.Generator], tuple[str, int]]


def rule_policy(rule_set: RuleSet) -> Policy:
    """The rule set as a policy."""
    return lambda state, pattern, rng: decide(rule_set, state, pattern, rng)


def act(world: World, policy: Policy, pos, rng: np.random.Generator) -> None:
    """Let the agent at `pos` sense, decide and act."""
    state = world.agents[pos]
    action, arg = policy(state, sense(world, pos), rng)
    if action == "brick":
        del world.agents[pos]
        world.grid[pos], world.brick_state[pos] = LATTICE_BRICK, arg
    elif action == "move":
        world.agents[neighbour(pos, arg)] = world.agents.pop(pos)
    else:
        world.agents[pos] = arg


def border_cells(shape: tuple[int, int]) -> list[tuple[int, int]]:
    """The cells on the edge of the grid, where agents enter."""
    rows, cols = shape
    return [(r, c) for r in range(rows) for c in range(cols)
            if r in (0, rows - 1) or c in (0, cols - 1)]


def spawn(world: World, n_agents: int, rng: np.random.Generator) -> None:
    """Agents enter at random free border cells until the population is full."""
    free = [p for p in border_cells(world.grid.shape)
            if world.grid[p] == LATTICE_EMPTY and p not in world.agents]
    missing = min(n_agents - len(world.agents), len(free))
    if missing <= 0:
        return
    for i in rng.choice(len(free), size=missing, replace=False):
        world.agents[free[int(i)]] = BLANK


def step(world: World, policy: Policy, n_agents: int, rng: np.random.Generator) -> None:
    """One synchronous round: spawn, then every agent acts in a seeded order."""
    spawn(world, n_agents, rng)
    order = sorted(world.agents)
    for i in rng.permutation(len(order)):
        if order[int(i)] in world.agents:
            act(world, policy, order[int(i)], rng)


def is_built(world: World, target: np.ndarray | None) -> bool:
    """Whether the grid is exactly the target (never, without a target)."""
    return target is not None and np.array_equal(world.grid, target)


def simulate(rule_set: RuleSet, seeds, shape, n_agents: int, max_steps: int,
             rng: np.random.Generator,
             on_step: Callable[[World, int], None] | None = None) -> Result:
    """Run the rule set until its target is built or `max_steps` elapse.

    `on_step(world, step)` is called after each step (used for perturbations).
    """
    return simulate_policy(rule_policy(rule_set), seeds, shape, n_agents, max_steps, rng,
                           rule_set.target, on_step)


def simulate_policy(policy: Policy, seeds, shape, n_agents: int, max_steps: int,
                    rng: np.random.Generator, target: np.ndarray | None,
                    on_step: Callable[[World, int], None] | None = None) -> Result:
    """Run any policy until `target` is built or `max_steps` elapse."""
    world = make_world(shape, seeds)
    for t in range(1, max_steps + 1):
        step(world, policy, n_agents, rng)
        if on_step is not None:
            on_step(world, t)
        if is_built(world, target):
            return Result(world.grid, world.brick_state, t, True)
    return Result(world.grid, world.brick_state, max_steps, False)

"""Goals another agent in sight will reach first (issue 36, `AgentConfig.yield_goals`).

Agents share no plans: each sees the others only as bodies on its AGENT layer (what they
carry is invisible). Two agents that head for the same brick both walk there and one
walks on again; with 32 agents that was a large part of the team's distance. So an agent
guesses who goes where from what it sees: every agent in sight, itself included, takes
the goal nearest it that nobody nearer has taken (a greedy assignment by straight-line
distance, nearest pair first), and the goals others took are left to them.

The guess is cheap and often wrong about one agent (it may carry a brick, or head
elsewhere), so it only ever re-orders: a goal is left to another only while some goal
stays, and the caller keeps every goal when none would.

Pure functions over numpy arrays.
"""

from __future__ import annotations

import numpy as np
from numba import njit


def claimed_by_others(goals: np.ndarray, others: np.ndarray, row: float, col: float) -> np.ndarray:
    """The goals (bool grid) other agents (bool grid of the cells they stand in) take
    before this agent, which stands at (`row`, `col`) in the grid's cell coordinates
    (fractions allowed); a bool grid. On equal distances this agent goes first, then the
    others in row order: each agent makes the same guess about itself, and a tie costs
    no more than the plain rule."""
    g = np.argwhere(goals)
    a = np.argwhere(others)
    out = np.zeros(goals.shape, bool)
    if not len(g) or not len(a):
        return out
    agents = np.empty((len(a) + 1, 2))
    agents[0] = row, col
    agents[1:] = a
    # both in C order (argwhere's is not, and vstack keeps it): one compiled signature.
    taken = _greedy(agents, np.ascontiguousarray(g, np.float64))
    out[g[taken > 0, 0], g[taken > 0, 1]] = True
    return out


@njit(cache=True)
def _greedy(agents, goals):
    """Per goal, 0 if free or taken by agent 0 (this one), 1 if taken by another agent."""
    na, ng = len(agents), len(goals)
    d = np.empty(na * ng)
    for i in range(na):
        for j in range(ng):
            d[i * ng + j] = np.hypot(agents[i, 0] - goals[j, 0], agents[i, 1] - goals[j, 1])
    order = np.argsort(d, kind="mergesort")   # stable: agent 0 first on a tie
    agent_done = np.zeros(na, np.bool_)
    goal_by = np.full(ng, -1)
    left_agents, left_goals = na, ng
    for k in order:
        i, j = k // ng, k % ng
        if agent_done[i] or goal_by[j] >= 0:
            continue
        agent_done[i] = True
        goal_by[j] = i
        left_agents -= 1
        left_goals -= 1
        if left_agents == 0 or left_goals == 0:
            break
    return (goal_by > 0).astype(np.int64)

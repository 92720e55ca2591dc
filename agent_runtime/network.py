"""The construction action-selection network (paper §4.4, §5, Fig. 7 and Fig. 8).

Six internal state nodes feed seven outputs through an excitatory and an inhibitory
weight per link; an output fires when its summed input reaches the threshold T = 0.7
(a_j = step(sum_i (w_exc_ij + w_inh_ij) * a_i, T)). Grab and Drop are the arm outputs;
the other five are motor outputs, of which the one with the largest input wins.

The paper gives Grab's weights (0.5 from At-Brick and from Drop-Site-Available, so both
must fire, and an inhibitory link from Holding-Brick) and the inhibition of Avoid-Red by
Near-Brick; the rest of `engineered()` is chosen here so that the network runs the
sequence of Fig. 7: locate a brick (approach it when near, navigate to it when one is
known, else explore), grab it, navigate to a missing part of the structure, drop it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np

STATE_NODES = ("holding_brick", "at_drop_site", "at_brick", "near_brick", "brick_available",
               "drop_site_available")
OUTPUTS = ("grab", "drop", "config_nav", "brick_nav", "explore", "avoid_red", "approach_red")
ARM_OUTPUTS = OUTPUTS[:2]
MOTOR_OUTPUTS = OUTPUTS[2:]
_ARM_INDEX = tuple((name, OUTPUTS.index(name)) for name in ARM_OUTPUTS)
_MOTOR_INDEX = tuple((name, OUTPUTS.index(name)) for name in MOTOR_OUTPUTS)
THRESHOLD = 0.7
NONE = "none"

# Fig. 8 as tables: (state node, output) -> weight.
_EXCITE = {
    ("at_brick", "grab"): 0.5, ("drop_site_available", "grab"): 0.5,
    ("holding_brick", "drop"): 0.5, ("at_drop_site", "drop"): 0.5,
    ("holding_brick", "config_nav"): 0.5, ("drop_site_available", "config_nav"): 0.5,
    ("brick_available", "brick_nav"): 0.5, ("drop_site_available", "brick_nav"): 0.5,
    ("drop_site_available", "explore"): 0.8,
    ("holding_brick", "avoid_red"): 0.8,
    ("near_brick", "approach_red"): 0.5, ("drop_site_available", "approach_red"): 0.5,
}
_INHIBIT = {
    ("holding_brick", "grab"): -1.0,
    ("at_drop_site", "config_nav"): -1.0,
    ("holding_brick", "brick_nav"): -1.0, ("near_brick", "brick_nav"): -1.0, ("at_brick", "brick_nav"): -1.0,
    ("holding_brick", "explore"): -1.0, ("brick_available", "explore"): -1.0,
    ("near_brick", "explore"): -1.0, ("at_brick", "explore"): -1.0,
    ("at_drop_site", "avoid_red"): -1.0, ("drop_site_available", "avoid_red"): -1.0,
    ("near_brick", "avoid_red"): -1.0,
    ("holding_brick", "approach_red"): -1.0, ("at_brick", "approach_red"): -1.0,
}


@dataclass(frozen=True)
class Choice:
    """What the network chose: an arm output and a motor output (either may be "none")."""

    arm: str
    motor: str
    outputs: tuple[float, ...]   # each output's summed input


@dataclass(frozen=True)
class ActionNetwork:
    """The construction network of Fig. 8: state nodes -> outputs through excitatory and inhibitory weights.

    The six state nodes (STATE_NODES) feed the seven outputs (OUTPUTS) through one
    excitatory (>= 0) and one inhibitory (<= 0) weight per link; an output fires when its
    summed input reaches the step threshold, and per group (arm, motor) the strongest firing
    output is chosen (`select`). `engineered()` gives the paper's hand-set weights (the
    teacher's network); a learned `Student` hands out frozen copies of its own.
    """

    excite: np.ndarray    # (6, 7), >= 0
    inhibit: np.ndarray   # (6, 7), <= 0
    threshold: float = THRESHOLD

    def inputs(self, state: np.ndarray) -> np.ndarray:
        """Summed input of every output for the state node activations `state` (6,)."""
        return np.asarray(state, dtype=np.float64) @ self._weights

    @cached_property
    def _weights(self) -> np.ndarray:
        # The network is frozen (a learning student hands out copies), so the sum is too.
        return self.excite + self.inhibit

    def choose(self, state: np.ndarray) -> Choice:
        """The (arm, motor) outputs this network fires for the state node activations `state`.

        The weights never change, and an agent's state nodes are 0 or 1: a handful of
        states recur every step, so each one's choice is worked out once."""
        state = np.asarray(state, dtype=np.float64)
        key = state.tobytes()
        choice = self._chosen.get(key)
        if choice is None:
            choice = self._chosen[key] = select(self.inputs(state), self.threshold)
        return choice

    @cached_property
    def _chosen(self) -> dict[bytes, Choice]:
        return {}


def select(net: np.ndarray, threshold: float = THRESHOLD) -> Choice:
    """Step threshold, then per group the firing output with the largest summed input `net` (7,).

    Shared by the engineered network and the learning student (agent_runtime/learning.py).
    """
    values = np.asarray(net, dtype=np.float64).tolist()
    fired = [v >= threshold - 1e-12 for v in values]
    return Choice(arm=_winner(values, fired, _ARM_INDEX), motor=_winner(values, fired, _MOTOR_INDEX),
                  outputs=tuple(values))


def _winner(net: list[float], fired: list[bool], group: tuple[tuple[str, int], ...]) -> str:
    """The firing output of `group` ((name, index) pairs) with the largest input (first on a tie)."""
    best, best_net = NONE, -math.inf
    for name, j in group:
        if fired[j] and net[j] > best_net:
            best, best_net = name, net[j]
    return best


def engineered() -> ActionNetwork:
    """The hand-set network of Fig. 8 (what the teacher uses)."""
    excite = np.zeros((len(STATE_NODES), len(OUTPUTS)))
    inhibit = np.zeros_like(excite)
    for table, target in ((_EXCITE, excite), (_INHIBIT, inhibit)):
        for (node, output), w in table.items():
            target[STATE_NODES.index(node), OUTPUTS.index(output)] = w
    return ActionNetwork(excite, inhibit)

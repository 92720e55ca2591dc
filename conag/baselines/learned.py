"""Learning the transition rule set by imitation (R3, §5.2, Fig. 11).

A teacher agent runs the hand-made rule set (R2) in the lattice world (R1).
At every agent decision we record what the agent saw — its own state and its
8 neighbours (occupancy kind and brick state) — and what the teacher decided,
as one class: "no rule fires" (the implicit explore/random-move default of
`lattice.decide`), or "become a brick in state k", or "wait in state k".
A one-hidden-layer feed-forward network (tanh, softmax over the classes) is
trained on these pairs with plain minibatch gradient descent on the
cross-entropy; an error is a decision where the network's argmax differs
from the teacher's class, counted online (the prediction is made before the
minibatch's update), per epoch — the quantity plotted in Fig. 11.

The trained network then drives the lattice world in place of the rule set,
through `lattice.simulate_policy` (any policy `(state, pattern, rng) -> decision`;
`lattice.simulate` is the same loop with the rule set as the policy). With the
teacher as the policy it reproduces `lattice.simulate` exactly, random stream
included.

All randomness comes from the `np.random.Generator` passed in.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .lattice import (
    MOVES,
    SEEN_FREE,
    SEEN_WALL,
    RuleSet,
    matches,
    simulate_policy,
)

N_KINDS = 4  # SEEN_FREE, SEEN_WALL, SEEN_AGENT, SEEN_EDGE
EXPLORE = 0  # class of "no rule fires": move to a random free 4-neighbour (or wait)


# --------------------------------------------------------------------------- classes

def n_states_of(rule_set: RuleSet, seeds: dict) -> int:
    """Number of state values to encode: BLANK (0) .. the largest state used."""
    return max([0, *rule_set.states, *seeds.values()]) + 1


def n_classes(n_states: int) -> int:
    """EXPLORE, then ("brick", k) for every k, then ("wait", k) for every k."""
    return 1 + 2 * n_states


def to_class(action: str, new_state: int, n_states: int) -> int:
    """The network's class of a rule's (action, new state): 0 explore, then brick, then wait."""
    if action == "brick":
        return 1 + new_state
    if action == "wait":
        return 1 + n_states + new_state
    raise ValueError(action)


def from_class(cls: int, n_states: int) -> tuple[str, int] | None:
    """(action, new state) of a rule class; None for EXPLORE."""
    if cls == EXPLORE:
        return None
    cls -= 1
    return ("brick", cls) if cls < n_states else ("wait", cls - n_states)


def teacher_class(rule_set: RuleSet, state: int, pattern, n_states: int) -> int:
    """The teacher's decision as a class (first matching rule, as `decide`)."""
    for rule in rule_set.rules:
        if matches(rule, state, pattern):
            return to_class(rule.action, rule.new_state, n_states)
    return EXPLORE


def explore(state: int, pattern, rng: np.random.Generator):
    """The implicit default of `lattice.decide` (same random draws)."""
    free = [d for d in MOVES if pattern[d][0] == SEEN_FREE]
    if not free:
        return "wait", state
    return "move", free[int(rng.integers(len(free)))]


# --------------------------------------------------------------------------- encoding

def input_size(n_states: int) -> int:
    """Length of an encoded input: own state one-hot, then per neighbour kind + state one-hots."""
    return n_states + 8 * (N_KINDS + n_states)


def encode(state: int, pattern, n_states: int) -> np.ndarray:
    """Own state one-hot, then per neighbour: kind one-hot + brick-state one-hot.

    The brick-state block is all zeros when the neighbour is not a brick
    (agents' and free cells' states are not part of what a rule can test).
    """
    x = np.zeros(input_size(n_states))
    x[state] = 1.0
    width = N_KINDS + n_states
    for i, (kind, seen_state) in enumerate(pattern):
        base = n_states + i * width
        x[base + kind] = 1.0
        if kind == SEEN_WALL:  # a brick, whose visible state the agent reads
            x[base + N_KINDS + seen_state] = 1.0
    return x


# --------------------------------------------------------------------------- network

class ImitationNet:
    """One hidden tanh layer, softmax output; plain minibatch gradient descent."""

    def __init__(self, n_in: int, n_hidden: int, n_out: int, rng: np.random.Generator,
                 lr: float = 0.5):
        self.w1 = rng.normal(0.0, 1.0 / np.sqrt(n_in), (n_in, n_hidden))
        self.b1 = np.zeros(n_hidden)
        self.w2 = rng.normal(0.0, 1.0 / np.sqrt(n_hidden), (n_hidden, n_out))
        self.b2 = np.zeros(n_out)
        self.lr = lr

    def forward(self, x: np.ndarray):
        """(hidden activations, class probabilities) for the inputs `x`."""
        h = np.tanh(x @ self.w1 + self.b1)
        z = h @ self.w2 + self.b2
        z = z - z.max(axis=-1, keepdims=True)
        p = np.exp(z)
        return h, p / p.sum(axis=-1, keepdims=True)

    def predict(self, x: np.ndarray) -> np.ndarray:
        """Argmax class for each row of x (or for a single input vector)."""
        return self.forward(x)[1].argmax(axis=-1)

    def train_step(self, x: np.ndarray, y: np.ndarray) -> int:
        """One gradient step on a minibatch; returns the errors made *before* it."""
        x = np.atleast_2d(x)
        y = np.atleast_1d(y)
        h, p = self.forward(x)
        errors = int((p.argmax(axis=1) != y).sum())
        grad_z = p.copy()
        grad_z[np.arange(len(y)), y] -= 1.0
        grad_z /= len(y)
        grad_h = (grad_z @ self.w2.T) * (1.0 - h * h)
        self.w2 -= self.lr * (h.T @ grad_z)
        self.b2 -= self.lr * grad_z.sum(axis=0)
        self.w1 -= self.lr * (x.T @ grad_h)
        self.b1 -= self.lr * grad_h.sum(axis=0)
        return errors


# --------------------------------------------------------------------------- policies



@dataclass
class NetPolicy:
    """Drives agents with a trained network instead of the rule set."""

    net: ImitationNet
    n_states: int

    def __call__(self, state: int, pattern, rng: np.random.Generator):
        """The trained network's decision for an agent in `state` sensing `pattern`; explore if none."""
        cls = int(self.net.predict(encode(state, pattern, self.n_states)))
        decision = from_class(cls, self.n_states)
        return explore(state, pattern, rng) if decision is None else decision


@dataclass
class RecordingTeacher:
    """The rule set as a policy, recording (input, class) at every decision."""

    rule_set: RuleSet
    n_states: int

    def __post_init__(self):
        self.inputs: list[np.ndarray] = []
        self.targets: list[int] = []

    def __call__(self, state: int, pattern, rng: np.random.Generator):
        """The rule set's decision, recording the encoded input and its class for training."""
        cls = teacher_class(self.rule_set, state, pattern, self.n_states)
        self.inputs.append(encode(state, pattern, self.n_states))
        self.targets.append(cls)
        decision = from_class(cls, self.n_states)
        return explore(state, pattern, rng) if decision is None else decision


# --------------------------------------------------------------------------- learning

def collect(rule_set: RuleSet, seeds, shape, rng: np.random.Generator, episodes: int,
            n_agents: int = 8, max_steps: int = 20000):
    """Teacher episodes -> (inputs X, teacher classes y) over every decision."""
    teacher = RecordingTeacher(rule_set, n_states_of(rule_set, seeds))
    for _ in range(episodes):
        simulate_policy(teacher, seeds, shape, n_agents, max_steps, rng, rule_set.target)
    return np.array(teacher.inputs), np.array(teacher.targets, dtype=int)


def learn(rule_set: RuleSet, seeds, shape, rng: np.random.Generator, epochs: int = 30,
          episodes: int = 5, n_hidden: int = 32, lr: float = 0.5, batch: int = 32,
          n_agents: int = 8, return_net: bool = False):
    """Imitation learning of a rule set; errors (count) per epoch.

    The teacher's decisions from `episodes` runs form the training set; each
    epoch is one shuffled pass of minibatch gradient descent over it, and its
    error count is the number of decisions whose argmax differed from the
    teacher's class at the moment they were presented.
    """
    n_states = n_states_of(rule_set, seeds)
    x, y = collect(rule_set, seeds, shape, rng, episodes, n_agents)
    net = ImitationNet(input_size(n_states), n_hidden, n_classes(n_states), rng, lr)
    per_epoch = []
    for _ in range(epochs):
        order = rng.permutation(len(y))
        total = 0
        for start in range(0, len(y), batch):
            idx = order[start:start + batch]
            total += net.train_step(x[idx], y[idx])
        per_epoch.append(total)
    errors = np.array(per_epoch)
    if return_net:
        return errors, net, NetPolicy(net, n_states), len(y)
    return errors

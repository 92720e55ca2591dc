"""Q-learning of the construction sequence from the teacher's signals (paper §5.1; L4).

The paper's last paragraph of §5.1: Q-learning "with a suitable set of parameters showed
comparable error rates". Here: tabular Q-learning over the 64 patterns of the six binary
state nodes, one table for the arm (none, Grab, Drop) and one for the motor (none and the
five motor outputs), each learned from its own signal as the reward:

    Q(s, a) <- Q(s, a) + alpha * (r + gamma * max_a' Q(s', a') - Q(s, a))

with s' the state of the next step (the update of a step is made when the next state is
known; `end_episode` closes the last one without a successor). The choice is greedy,
ties broken at random by the injected generator; tables start at 0, so an action not yet
tried (0) is preferred to one the teacher has punished (< 0): that is the exploration,
and no random action is ever taken once a rewarded one is known, so errors can reach 0.
"""

from __future__ import annotations

import numpy as np

from agent_runtime.network import ARM_OUTPUTS, MOTOR_OUTPUTS, NONE, STATE_NODES, Choice

ARM_ACTIONS = (NONE, *ARM_OUTPUTS)
MOTOR_ACTIONS = (NONE, *MOTOR_OUTPUTS)
N_STATES = 2 ** len(STATE_NODES)


def state_index(state) -> int:
    """The state node pattern (0/1 activations, STATE_NODES order) as an integer."""
    bits = np.asarray(state, dtype=np.float64) > 0.5
    return int(bits @ (1 << np.arange(len(STATE_NODES))))


class QLearner:
    """Tabular Q-learning of the arm and motor outputs over the 2^6 binary states (§5.1).

    One Q table per group (arm, motor); greedy choice with random tie-breaks; the teacher's
    +1 / -1 of a step is its reward, learned when the next state is known (discount `gamma`).
    """

    def __init__(self, rng: np.random.Generator, gamma: float = 0.5):
        if not 0 <= gamma < 1:
            raise ValueError("gamma must be in [0, 1)")
        self.rng, self.gamma = rng, gamma
        self.arm_q = np.zeros((N_STATES, len(ARM_ACTIONS)))
        self.motor_q = np.zeros((N_STATES, len(MOTOR_ACTIONS)))
        self._pending: tuple[int, int, int, int, int, float] | None = None  # s, a_arm, a_motor, r_arm, r_motor, alpha

    def _greedy(self, row: np.ndarray) -> int:
        best = np.flatnonzero(row >= row.max() - 1e-12)
        return int(best[0] if len(best) == 1 else self.rng.choice(best))

    def choose(self, state) -> Choice:
        """The greedy (arm, motor) actions in `state`; the outputs report their action values."""
        s = state_index(state)
        arm, motor = ARM_ACTIONS[self._greedy(self.arm_q[s])], MOTOR_ACTIONS[self._greedy(self.motor_q[s])]
        # The Decision's "outputs": each output's action value in this state.
        outputs = (*self.arm_q[s, 1:], *self.motor_q[s, 1:])
        return Choice(arm=arm, motor=motor, outputs=tuple(float(v) for v in outputs))

    def learn(self, state, arm: str, motor: str, arm_signal: int, motor_signal: int, eta: float) -> None:
        """Record this step's signals (learning rate alpha = eta); update the previous step with s' = state."""
        s = state_index(state)
        self._update(s)
        self._pending = (s, ARM_ACTIONS.index(arm), MOTOR_ACTIONS.index(motor), arm_signal, motor_signal, eta)

    def end_episode(self) -> None:
        """The trial is over: update the last step with no successor."""
        self._update(None)

    def _update(self, next_state: int | None) -> None:
        if self._pending is None:
            return
        s, a, m, r_arm, r_motor, alpha = self._pending
        for q, action, r in ((self.arm_q, a, r_arm), (self.motor_q, m, r_motor)):
            future = 0.0 if next_state is None else self.gamma * q[next_state].max()
            q[s, action] += alpha * (r + future - q[s, action])
        self._pending = None

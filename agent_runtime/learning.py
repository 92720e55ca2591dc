"""The learning student of paper §5.1 (L2): the Fig. 8 network with learned weights.

A fully connected single-layer network from the six internal state nodes to the seven
construction outputs, an excitatory weight (>= 0) and an inhibitory weight (<= 0) per
link, initialised uniformly in [0, 0.5] and [-0.5, 0] from an injected generator. It
chooses exactly as the engineered network does (`network.select`: step threshold
T = 0.7, the largest firing output per group) and learns online from the teacher's two
signals per step with the delta rule of §5.1:

    w_exc(t+1) = w_exc(t) + eta * R_j * a_i        w_inh(t+1) = w_inh(t) - eta * R_j * a_i

The rule leaves three things open: the sign of the inhibitory update (both weights move
by +eta * R_j * a_i in signed terms, so a +1 raises the output's input), which outputs a
group's one signal applies to (the chosen one; all of the group when none was chosen and
the teacher says -1), and when a +1 stops (once the output's input is T + `margin`). Why,
and what the literal readings give: docs/design.md, "Learning (§5.1)".

Weights keep their signs (excitatory clipped at 0 from below, inhibitory at 0 from
above) and have no other bound; with the margin they stop moving once no errors are made.

Weights are saved as a small JSON file with a format name and version.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np

from agent_runtime.network import (
    ARM_OUTPUTS,
    MOTOR_OUTPUTS,
    NONE,
    OUTPUTS,
    STATE_NODES,
    THRESHOLD,
    ActionNetwork,
    Choice,
    select,
)

FORMAT = "conag-student-weights"
VERSION = 1
INIT_EXCITE = (0.0, 0.5)
INIT_INHIBIT = (-0.5, 0.0)
MARGIN = 0.1  # a +1 strengthens an output only while its input is below T + MARGIN
SHAPE = (len(STATE_NODES), len(OUTPUTS))
_GROUPS = ((ARM_OUTPUTS, 0), (MOTOR_OUTPUTS, 1))


class WeightsFileError(ValueError):
    """A weights file that cannot be read as a student's weights."""


class Student:
    """A learning construction network: mutable weights, the engineered network's choice rule."""

    def __init__(self, excite: np.ndarray, inhibit: np.ndarray, threshold: float = THRESHOLD):
        excite = np.array(excite, dtype=np.float64)
        inhibit = np.array(inhibit, dtype=np.float64)
        for name, w in (("excite", excite), ("inhibit", inhibit)):
            if w.shape != SHAPE:
                raise ValueError(f"{name} weights must have shape {SHAPE}, got {w.shape}")
            if not np.isfinite(w).all():
                raise ValueError(f"{name} weights must be finite")
        if (excite < 0).any() or (inhibit > 0).any():
            raise ValueError("excitatory weights must be >= 0 and inhibitory weights <= 0")
        self.excite, self.inhibit, self.threshold = excite, inhibit, float(threshold)

    @classmethod
    def random(cls, rng: np.random.Generator) -> Student:
        """Weights uniform in [0, 0.5] (excitatory) and [-0.5, 0] (inhibitory), as in §5.1."""
        return cls(rng.uniform(*INIT_EXCITE, SHAPE), rng.uniform(*INIT_INHIBIT, SHAPE))

    def network(self) -> ActionNetwork:
        """A frozen copy of the current weights."""
        return ActionNetwork(self.excite.copy(), self.inhibit.copy(), self.threshold)

    def choose(self, state: np.ndarray) -> Choice:
        """The (arm, motor) outputs the current weights fire for the state node activations `state`."""
        net = np.asarray(state, dtype=np.float64) @ (self.excite + self.inhibit)
        return select(net, self.threshold)

    def learn(self, state, arm: str, motor: str, arm_signal: int, motor_signal: int, eta: float,
              margin: float = MARGIN) -> None:
        """Apply the teacher's two signals for the step where `state` made the student choose (arm, motor)."""
        a = np.asarray(state, dtype=np.float64)
        for (group, _), chosen, signal in zip(_GROUPS, (arm, motor), (arm_signal, motor_signal)):
            if signal not in (-1, 1):
                raise ValueError(f"a reinforcement signal must be +1 or -1, got {signal!r}")
            if chosen == NONE:
                if signal > 0:
                    continue  # rightly quiet: nothing fired, nothing to change
                cols, signal = [OUTPUTS.index(o) for o in group], 1  # wanted something: raise the group
            elif chosen in group:
                cols = [OUTPUTS.index(chosen)]
                if signal > 0 and a @ (self.excite[:, cols[0]] + self.inhibit[:, cols[0]]) >= self.threshold + margin:
                    continue  # right, and firing clearly: the delta rule's error is zero
            else:
                raise ValueError(f"{chosen!r} is not an output of the group {group}")
            step = eta * signal * a[:, None]
            self.excite[:, cols] = np.maximum(self.excite[:, cols] + step, 0.0)
            self.inhibit[:, cols] = np.minimum(self.inhibit[:, cols] + step, 0.0)

    # a small file --------------------------------------------------------------------------
    def save(self, path: str | os.PathLike) -> None:
        """Write the weights as JSON (atomically: a reader never sees half a file)."""
        path = Path(path)
        doc = {"format": FORMAT, "version": VERSION, "state_nodes": list(STATE_NODES), "outputs": list(OUTPUTS),
               "threshold": self.threshold, "excite": self.excite.round(12).tolist(),
               "inhibit": self.inhibit.round(12).tolist()}
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        tmp.write_text(json.dumps(doc, indent=1) + "\n", encoding="utf-8")
        os.replace(tmp, path)

    @classmethod
    def load(cls, path: str | os.PathLike) -> Student:
        """Read weights written by `save`; a WeightsFileError names the file and what is wrong."""
        try:
            doc = json.loads(Path(path).read_text(encoding="utf-8"))
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            raise WeightsFileError(f"{path}: cannot read student weights: {exc}") from None

        def need(ok: bool, what: str) -> None:
            if not ok:
                raise WeightsFileError(f"{path}: {what}")

        need(isinstance(doc, dict) and doc.get("format") == FORMAT, f"not a student weights file (format {FORMAT!r})")
        need(doc.get("version") == VERSION, f"unsupported version {doc.get('version')!r}, expected {VERSION}")
        need(doc.get("state_nodes") == list(STATE_NODES), f"state nodes must be {list(STATE_NODES)}")
        need(doc.get("outputs") == list(OUTPUTS), f"outputs must be {list(OUTPUTS)}")
        threshold = doc.get("threshold")
        need(isinstance(threshold, (int, float)) and not isinstance(threshold, bool) and math.isfinite(threshold),
             "threshold must be a finite number")
        try:
            return cls(_matrix(doc.get("excite")), _matrix(doc.get("inhibit")), threshold)
        except (TypeError, ValueError) as exc:
            raise WeightsFileError(f"{path}: bad weights: {exc}") from None


def _matrix(value) -> np.ndarray:
    if not (isinstance(value, list) and all(isinstance(row, list) for row in value)
            and all(isinstance(v, (int, float)) and not isinstance(v, bool) for row in value for v in row)):
        raise ValueError(f"expected a {SHAPE[0]} x {SHAPE[1]} list of numbers")
    return np.array(value, dtype=np.float64)

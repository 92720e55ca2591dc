"""The teacher's rule (paper §5.1; L1), with no bus: compare, then reinforce.

The teacher is not in the world: it sees what the student sees (the six internal state
nodes the student reports in its Decision), works out what the engineered network of
Fig. 8 would choose on the same inputs, and answers with two signals, one for the arm
output (Grab, Drop or none) and one for the motor output (the five navigation and
reactive behaviours or none): +1 where the student chose what the teacher would have,
-1 where it did not. A step is an error when either signal is -1.

`Teacher` numbers the reinforcements to each student (`seq` from 0, one per decision)
and keeps per-student counts for progress lines.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field

import numpy as np

from agent_runtime.network import ActionNetwork, engineered
from protocol.messages import Decision, Reinforcement

WINDOW = 100  # decisions in the "recent errors" window of the progress lines


def signals(decision: Decision, network: ActionNetwork) -> tuple[int, int]:
    """(arm, motor): +1 where the student's choice equals the network's on the same state, else -1."""
    want = network.choose(np.asarray(decision.state, dtype=np.float64))
    return (1 if decision.arm == want.arm else -1), (1 if decision.motor == want.motor else -1)


def is_error(r: Reinforcement) -> bool:
    """Whether the teacher disagreed with the arm or the motor output of the step."""
    return r.arm < 0 or r.motor < 0


@dataclass
class StudentRecord:
    """What the teacher knows of one student."""

    next_seq: int = 0
    decisions: int = 0
    errors: int = 0
    last_tick: int = -1
    recent: deque = field(default_factory=lambda: deque(maxlen=WINDOW))

    @property
    def recent_errors(self) -> int:
        """Errors among the student's recent decisions."""
        return sum(self.recent)


class Teacher:
    """Reinforces any number of students with one engineered network."""

    def __init__(self, network: ActionNetwork | None = None):
        self.network = network or engineered()
        self.students: dict[str, StudentRecord] = {}
        self.bad_messages = 0  # decisions that could not be decoded (counted by the process)

    def reinforce(self, decision: Decision) -> Reinforcement:
        """The two signals (+1 agree / -1 disagree, arm and motor) for a student's decision."""
        rec = self.students.setdefault(decision.agent_id, StudentRecord())
        arm, motor = signals(decision, self.network)
        r = Reinforcement(decision.agent_id, decision.tick, rec.next_seq, arm, motor)
        rec.next_seq += 1
        rec.decisions += 1
        rec.errors += is_error(r)
        rec.recent.append(is_error(r))
        rec.last_tick = decision.tick
        return r

    def forget(self, agent_id: str) -> None:
        """The student is gone: a new incarnation starts a fresh sequence."""
        self.students.pop(agent_id, None)

    def progress(self) -> str:
        """One line: each student's decisions, errors, errors in the last WINDOW decisions."""
        if not self.students:
            return "no students yet"
        return "  ".join(f"{a}: tick {r.last_tick} decisions {r.decisions} errors {r.errors} "
                         f"(last {len(r.recent)}: {r.recent_errors})" for a, r in sorted(self.students.items()))

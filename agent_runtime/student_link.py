"""The learning agent's end of the teacher link: decisions out, reinforcements in, in order.

A `StudentLink` publishes the agent's Decisions reliably (zenoh RELIABLE, congestion
control BLOCK: a decision is never dropped on the way to the teacher) and takes the
teacher's Reinforcements from a FIFO inbox (`protocol.bus.Inbox`; never "latest wins": a
full inbox holds the sender back instead of dropping). Each reinforcement answers the decision of
the same tick, kept here until answered; `poll` hands back the (decision, reinforcement)
pairs in the order they came, for the student to learn from before its next step.

Nothing here waits for the teacher: with no teacher the agent keeps acting on its current
weights, unanswered decisions are forgotten (only the newest `keep` are held), and a
teacher that comes back simply answers the next decisions. The teacher's liveliness
token says whether one is there; `seq` (one per reinforcement, from 0 per teacher
incarnation) tells a gap (none expected) from a restarted teacher.
"""

from __future__ import annotations

import logging
import time
from collections import OrderedDict
from dataclasses import dataclass

import zenoh

from protocol import keys
from protocol.bus import Declarations, Inbox, Presence
from protocol.codec import ProtocolError, decode, encode
from protocol.messages import Decision, Reinforcement

log = logging.getLogger("conag.student")

FIFO_CAPACITY = 4096


@dataclass
class LinkCounts:
    """What a StudentLink has seen, for the agent's log and tests."""

    decisions: int = 0        # published
    reinforcements: int = 0   # received and matched to a pending decision
    errors: int = 0           # of those, with a -1 for the arm or the motor
    unmatched: int = 0        # for a decision no longer pending (or never made)
    bad: int = 0              # undecodable, or for another agent
    gaps: int = 0             # seq jumped forward (should not happen: the link is reliable)
    teacher_restarts: int = 0  # seq went back


class StudentLink:
    """Decisions out (reliable), the teacher's reinforcements in (a FIFO inbox), paired by tick.

    A context manager; see the module for what happens with no teacher.
    """

    def __init__(self, session: zenoh.Session, world_id: str, agent_id: str, keep: int = 1024):
        self.agent_id, self.keep = agent_id, keep
        self.counts = LinkCounts()
        self._pending: OrderedDict[int, Decision] = OrderedDict()
        self._next_seq: int | None = None
        self._declared = Declarations()
        self._pub = self._declared.add(session.declare_publisher(keys.decision(world_id, agent_id),
                                                                 reliability=zenoh.Reliability.RELIABLE,
                                                                 congestion_control=zenoh.CongestionControl.BLOCK))
        self._inbox = self._declared.add(Inbox(FIFO_CAPACITY).subscribe(session,
                                                                        keys.reinforcement(world_id, agent_id)))
        self._teachers = self._declared.add(Presence(session, keys.all_teacher_tokens(world_id)))

    @property
    def teachers(self) -> set[str]:
        """The teachers whose liveliness token is up (as of the last `poll`)."""
        return self._teachers.present

    def publish(self, decision: Decision) -> None:
        """Send a decision to the teacher and keep it until it is answered."""
        self._pending[decision.tick] = decision
        while len(self._pending) > self.keep:
            self._pending.popitem(last=False)
        self._pub.put(encode(decision))
        self.counts.decisions += 1

    def poll(self, wait: float = 0.0) -> list[tuple[Decision, Reinforcement]]:
        """Every reinforcement that has arrived, paired with the decision it answers, in order.

        With `wait` > 0 and a teacher present, first wait up to `wait` seconds for the answer
        to the newest decision, so that a step is learned from before the next one is taken
        (the teacher answers within a fraction of a millisecond on one host); with no
        teacher there is nothing to wait for.
        """
        self._teacher_events()
        pairs = []
        newest = next(reversed(self._pending), None)
        deadline = time.monotonic() + wait
        while True:
            sample = self._inbox.get(0)
            if sample is None:
                remaining = deadline - time.monotonic()
                if not (newest in self._pending and self.teachers and remaining > 0):
                    break
                sample = self._inbox.get(min(remaining, 0.005))
                self._teacher_events()  # a teacher that just went is not waited for
                if sample is None:
                    continue
            try:
                r = decode(sample.payload.to_bytes(), Reinforcement)
            except ProtocolError as exc:
                self.counts.bad += 1
                log.debug("ignored a bad reinforcement: %s", exc)
                continue
            if r.agent_id != self.agent_id:
                self.counts.bad += 1
                continue
            self._sequence(r.seq)
            decision = self._pending.pop(r.tick, None)
            if decision is None:
                self.counts.unmatched += 1
                continue
            # Answers come in decision order: anything older is never going to be answered.
            while self._pending and next(iter(self._pending)) < r.tick:
                self._pending.popitem(last=False)
            self.counts.reinforcements += 1
            self.counts.errors += r.arm < 0 or r.motor < 0
            pairs.append((decision, r))
        return pairs

    def _sequence(self, seq: int) -> None:
        if self._next_seq is not None and seq != self._next_seq:
            if seq < self._next_seq:
                self.counts.teacher_restarts += 1
                log.info("agent %s: the teacher started over (seq %d after %d)", self.agent_id, seq,
                         self._next_seq - 1)
            else:
                self.counts.gaps += 1
                log.warning("agent %s: %d reinforcement(s) missing before seq %d", self.agent_id,
                            seq - self._next_seq, seq)
        self._next_seq = seq + 1

    def _teacher_events(self) -> None:
        for teacher, alive in self._teachers.update():
            if alive:
                log.info("agent %s: teacher %s is here", self.agent_id, teacher)
            else:
                log.warning("agent %s: teacher %s is gone; acting on the current weights", self.agent_id, teacher)

    def close(self) -> None:
        """Undeclare the token watch, the inbox and the publisher."""
        self._declared.close()

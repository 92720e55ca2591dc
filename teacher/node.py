"""The teacher process (`conag teacher`): the zenoh shell around `teacher.core.Teacher`.

It declares its liveliness token (students see whether a teacher is there), watches the
students' tokens, takes every student's Decisions from one wildcard subscription into a
FIFO inbox (`protocol.bus.Inbox`: a full inbox holds the senders back, it never drops), and
answers each with a Reinforcement on that student's key, published RELIABLE with
congestion control BLOCK: reinforcements are neither dropped nor reordered. One loop,
one thread: decisions are answered in the order they arrive.

A teacher restarted mid-run simply answers the decisions that come after it is up (its
`seq` numbers start again from 0, which tells the student it is a new teacher); students
do not wait for it in the meantime. One teacher per world.
"""

from __future__ import annotations

import logging
import time

import zenoh

from protocol import keys
from protocol.bus import Declarations, Inbox, Presence, undeclare, wait_for_token
from protocol.codec import ProtocolError, decode, encode
from protocol.messages import Decision
from teacher.core import Teacher

log = logging.getLogger("conag.teacher")

FIFO_CAPACITY = 4096


class TeacherLink:
    """The teacher's end of the bus: students' decisions in, their tokens watched, its own
    token, one reinforcement publisher per student (declared when it first decides).

    A context manager: leaving it undeclares the token first, then the watch, the
    decision inbox and the publishers.
    """

    def __init__(self, session: zenoh.Session, world_id: str, teacher_id: str = "teacher"):
        self.session, self.world_id = session, world_id
        self._publishers: dict[str, zenoh.Publisher] = {}
        self._declared = Declarations()
        decisions = Inbox(FIFO_CAPACITY).subscribe(session, keys.all_agents(world_id, "decision"))
        self.decisions = self._declared.add(decisions)
        self.students = self._declared.add(Presence(session, keys.all_agent_tokens(world_id)))
        # Declared last: a student that sees the token knows the subscription is there.
        self._declared.add(session.liveliness().declare_token(keys.teacher_token(world_id, teacher_id)))

    def follow_students(self) -> None:
        """Apply the students' token changes that came since the last call."""
        for agent, alive in self.students.update():
            log.info("student %s is %s", agent, "here" if alive else "gone")

    def publisher(self, agent: str) -> zenoh.Publisher:
        """The reliable reinforcement publisher for `agent`, declared when it is first needed."""
        pub = self._publishers.get(agent)
        if pub is None:
            pub = self.session.declare_publisher(keys.reinforcement(self.world_id, agent),
                                                 reliability=zenoh.Reliability.RELIABLE,
                                                 congestion_control=zenoh.CongestionControl.BLOCK)
            self._publishers[agent] = pub
        return pub

    def answer(self, sample: zenoh.Sample, teacher: Teacher) -> None:
        """Reinforce the decision in `sample`; a bad one is counted and ignored."""
        try:
            d = decode(sample.payload.to_bytes(), Decision)
            if d.agent_id != keys.agent_of(str(sample.key_expr)):
                raise ProtocolError("decision agent_id does not match its key")
        except ProtocolError as exc:
            teacher.bad_messages += 1
            log.debug("ignored a bad decision on %s: %s", sample.key_expr, exc)
            return
        self.publisher(d.agent_id).put(encode(teacher.reinforce(d)))

    def close(self) -> None:
        """Undeclare everything: the token, the watch and inbox, then the publishers."""
        self._declared.close()
        publishers, self._publishers = list(self._publishers.values()), {}
        undeclare(*publishers)

    def __enter__(self) -> TeacherLink:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def run_teacher(session: zenoh.Session, world_id: str, stop, teacher_id: str = "teacher",
                on_progress=None, progress_every: float = 1.0, teacher: Teacher | None = None,
                on_ready=None, recorded: float = 0.0) -> Teacher:
    """Reinforce every student of `world_id` until `stop` is set.

    `on_ready()` once the subscriptions and the token are declared; `on_progress(teacher,
    present)` every `progress_every` seconds (`present`: the students whose token is up).
    `recorded` > 0: the run is recorded; wait up to that many seconds for the recorder's
    token first (its link to this process), so that the recording holds the first
    reinforcements too (students decide aloud only once they see the teacher's token).
    """
    teacher = teacher if teacher is not None else Teacher()
    heard = recorded <= 0 or wait_for_token(session, keys.all_recorder_tokens(world_id), recorded, stop=stop)
    if not heard and not stop.is_set():
        log.warning("teacher %s: no recorder of world %s heard within %g s; teaching anyway (the recording may "
                    "miss the first reinforcements)", teacher_id, world_id, recorded)
    with TeacherLink(session, world_id, teacher_id) as link:
        if on_ready is not None:
            on_ready()
        last_progress = time.monotonic()
        while not stop.is_set():
            link.follow_students()
            sample = link.decisions.get(0.1)
            if sample is not None:
                link.answer(sample, teacher)
            if on_progress is not None and time.monotonic() - last_progress >= progress_every:
                last_progress = time.monotonic()
                on_progress(teacher, link.students.present)
    return teacher

"""The teacher process (`conag teacher`): the zenoh shell around `teacher.core.Teacher`.

It declares its liveliness token (students see whether a teacher is there), watches the
students' tokens, takes every student's Decisions from one wildcard subscription into a
FIFO inbox (`conag.bus.Inbox`: a full inbox holds the senders back, it never drops), and
answers each with
a Reinforcement on that student's key, published RELIABLE with congestion control BLOCK:
reinforcements are neither dropped nor reordered. One loop, one thread: decisions are
answered in the order they arrive.

A teacher restarted mid-run simply answers the decisions that come after it is up (its
`seq` numbers start again from 0, which tells the student it is a new teacher); students
do not wait for it in the meantime. One teacher per world.
"""

from __future__ import annotations

import logging
import time

import zenoh

from conag.bus import Inbox
from protocol import keys
from protocol.codec import ProtocolError, decode, encode
from protocol.messages import Decision
from teacher.core import Teacher

log = logging.getLogger("conag.teacher")

FIFO_CAPACITY = 4096


def run_teacher(session: zenoh.Session, world_id: str, stop, teacher_id: str = "teacher",
                on_progress=None, progress_every: float = 1.0, teacher: Teacher | None = None,
                on_ready=None) -> Teacher:
    """Reinforce every student of `world_id` until `stop` is set.

    `on_ready()` once the subscriptions and the token are declared; `on_progress(teacher,
    present)` every `progress_every` seconds (`present`: the students whose token is up).
    """
    teacher = teacher if teacher is not None else Teacher()
    publishers: dict[str, zenoh.Publisher] = {}
    present: set[str] = set()  # students whose liveliness token is up
    decisions = Inbox(FIFO_CAPACITY).subscribe(session, keys.all_agents(world_id, "decision"))
    tokens = Inbox(256).watch(session, keys.all_agent_tokens(world_id))
    # Declared last: a student that sees the token knows the subscription is there.
    token = session.liveliness().declare_token(keys.teacher_token(world_id, teacher_id))
    if on_ready is not None:
        on_ready()

    def publisher(agent: str) -> zenoh.Publisher:
        pub = publishers.get(agent)
        if pub is None:
            pub = session.declare_publisher(keys.reinforcement(world_id, agent),
                                            reliability=zenoh.Reliability.RELIABLE,
                                            congestion_control=zenoh.CongestionControl.BLOCK)
            publishers[agent] = pub
        return pub

    last_progress = time.monotonic()
    try:
        while not stop.is_set():
            while (sample := tokens.get(0)) is not None:
                agent = str(sample.key_expr).rsplit("/", 1)[-1]
                if sample.kind == zenoh.SampleKind.PUT:
                    present.add(agent)
                    log.info("student %s is here", agent)
                else:
                    present.discard(agent)
                    log.info("student %s is gone", agent)
            sample = decisions.get(0.1)
            if sample is not None:
                _answer(sample, teacher, publisher)
            if on_progress is not None and time.monotonic() - last_progress >= progress_every:
                last_progress = time.monotonic()
                on_progress(teacher, present)
    finally:
        try:
            token.undeclare()
        except Exception:  # the session may be closing already
            pass
        tokens.close()
        decisions.close()
        for pub in publishers.values():
            try:
                pub.undeclare()
            except Exception:
                pass
    return teacher


def _answer(sample: zenoh.Sample, teacher: Teacher, publisher) -> None:
    try:
        d = decode(sample.payload.to_bytes(), Decision)
        if d.agent_id != keys.agent_of(str(sample.key_expr)):
            raise ProtocolError("decision agent_id does not match its key")
    except ProtocolError as exc:
        teacher.bad_messages += 1
        log.debug("ignored a bad decision on %s: %s", sample.key_expr, exc)
        return
    publisher(d.agent_id).put(encode(teacher.reinforce(d)))

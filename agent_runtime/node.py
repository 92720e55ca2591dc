"""The agent process (`conag agent --id ID`): the zenoh shell around `agent_runtime.brain.Brain`.

It declares its liveliness token, attaches by id (a restarted process gets its old
body back and rebuilds its maps from its sensors), then for every sensor frame: one
decision step, the command to the world, the Decision for the teacher. Frames are
"latest wins"; a slow agent acts on the newest one.

When its world goes (the world's liveliness token disappears: killed, or stopped), the
agent says so in its log ("waiting for world w0 ..." once it has been gone `WAIT_QUIET`
seconds, again every `WAIT_REPORT` seconds),
waits for a world with that id to come back (`conag run` restarts it from its last
checkpoint) and attaches again like a restarted agent: a new Welcome, maps rebuilt from
the sensors (the body is where the checkpoint left it, not where the old maps think).

With `learning` (`conag agent --learn`) the construction network is a `Student`
(random weights from the seed, or loaded from a file) instead of the engineered one:
before each step the agent applies every reinforcement that has arrived to the decision
it answers (`agent_runtime.student_link.StudentLink`; with a teacher present it waits up to `wait`
seconds for the answer to its last step), and saves its weights every `save_every` ticks
and on the way out. With no teacher on the bus it keeps acting on its current weights.

Blueprint changes and state reports go through `agent_runtime.feeds.AgentFeeds`: the newest
blueprint is applied before each step, an AgentState is published every 100 ticks and
on exit. A query on the decision key is answered with the newest Decision: a viewer asks
for it at its display rate, not the 50-100 a second of a lockstep run.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from dataclasses import dataclass
from functools import partial

import numpy as np

from agent_runtime.brain import Brain
from agent_runtime.config import AgentConfig
from agent_runtime.feeds import AgentFeeds
from agent_runtime.foreman_brain import ForemanBrain
from agent_runtime.learning import Student
from agent_runtime.student_link import StudentLink
from agent_runtime.worker import Worker
from agent_runtime.world_link import AttachError, WorldLink
from protocol import keys
from protocol.bus import undeclare
from protocol.codec import encode
from protocol.messages import Decision

log = logging.getLogger("conag.agent")
WAIT_QUIET = 3.0    # seconds a world may be gone before the agent warns (a run ending stops its agents sooner)
WAIT_REPORT = 30.0  # seconds between "waiting for world" lines
ROLES = ("agent", "foreman", "worker")  # a ConAg agent; a foreman (a ConAg agent that marks); a reactive worker


@dataclass(frozen=True)
class Learning:
    """How a learning agent learns: rate, where its weights come from and go."""

    eta: float = 0.1
    weights_in: str | None = None     # start from these weights instead of random ones
    weights_out: str | None = None    # save here every `save_every` ticks and on exit
    save_every: int = 500
    wait: float = 0.02                # seconds to wait for the teacher's answer to the last step (if one is there)

    def __post_init__(self) -> None:
        if not (np.isfinite(self.eta) and self.eta > 0):
            raise ValueError("the learning rate eta must be a number > 0")
        if self.save_every < 1:
            raise ValueError("save_every must be >= 1 tick")
        if not self.wait >= 0:
            raise ValueError("wait must be >= 0 seconds")

    def student(self, seed: int) -> Student:
        """The learner to start from: the weights in `weights_in`, else random ones from `seed`."""
        if self.weights_in:
            return Student.load(self.weights_in)
        # A stream of its own: not the one the brain explores with.
        return Student.random(np.random.default_rng(np.random.SeedSequence(seed).spawn(1)[0]))


@dataclass
class AgentReport:
    """What a run of `run_agent` did (for the command line's last line and for tests)."""

    ticks: int = 0
    student: Student | None = None
    link: StudentLink | None = None   # a learning agent's link to the teacher (counts, teachers present)
    world_link: WorldLink | None = None  # its link to the world (frames refused, bad frames)


@dataclass(frozen=True)
class AgentOptions:
    """Which body an agent process serves, and how its brain acts (`conag agent`)."""

    world_id: str
    agent_id: str
    cfg: AgentConfig | None = None    # None: AgentConfig()
    seed: int = 0                     # the agent's own randomness (exploring; a student's random weights)
    attach_timeout: float = 30.0      # seconds to wait for the world
    recorded: bool = False            # wait (up to attach_timeout) for the run's recorder before attaching
    learning: Learning | None = None  # a learning student (paper §5.1)
    network: object | None = None     # replaces the engineered construction network (e.g. a trained Student)
    role: str = "agent"               # "agent"; in a society "foreman" (marks cues) or "worker" (docs/society.md)

    def __post_init__(self) -> None:
        if self.role not in ROLES:
            raise ValueError(f"an agent's role is one of {', '.join(ROLES)}, not {self.role!r}")
        if self.role == "worker" and (self.learning is not None or self.network is not None):
            raise ValueError("a worker has no construction network to learn or replace")


def run_agent(session, opts: AgentOptions, stop=None, report: AgentReport | None = None) -> AgentReport:
    """Serve one body until `stop` is set (or a signal handler raises).

    `report` (filled in as it goes, so a caller sees it even after a signal) is also
    returned.
    """
    report = report if report is not None else AgentReport()
    agent = AgentProcess(session, opts, report)
    try:
        agent.attach()
        agent.serve(stop)
    finally:
        agent.close()
    return report


class AgentProcess:
    """One agent's links, brain and last tick, between `attach` and `close` (a process of
    its own, or one of several in a `conag agents` host: `agent_runtime.host`)."""

    def __init__(self, session, opts: AgentOptions, report: AgentReport):
        self.opts, self.report, self.learning = opts, report, opts.learning
        # A bad weights file fails here, before attaching.
        self.student = self.learning.student(opts.seed) if self.learning else opts.network
        w, a = opts.world_id, opts.agent_id
        self.link = WorldLink(session, w, a)
        # before attaching: no blueprint change is missed; brick news only from agents that tell it
        self.feeds = AgentFeeds(session, w, a, news=opts.role != "worker" and (opts.cfg or AgentConfig()).share_bricks)
        self.brain: Brain | Worker | None = None
        self.tick = 0
        self.reattaches = 0  # worlds lost and found again
        self.teacher = StudentLink(session, w, a) if self.learning else None
        self.decisions = None if self.learning else session.declare_publisher(keys.decision(w, a), express=True)
        self.last_decision: Decision | None = None  # the newest, for queries (read by zenoh's thread)
        self._decision_queries = session.declare_queryable(keys.decision(w, a), self._on_decision_query)
        report.student, report.link, report.world_link = self.student, self.teacher, self.link

    def attach(self) -> None:
        """Attach to the world and make the brain from the Welcome."""
        if self.opts.recorded and not self.link.wait_for_recorder(self.opts.attach_timeout):
            log.warning("agent %s: no recorder of world %s heard within %g s; attaching anyway (the recording "
                        "may miss this agent's first messages)", self.opts.agent_id, self.opts.world_id,
                        self.opts.attach_timeout)
        welcome = self.link.attach(timeout=self.opts.attach_timeout)
        log.info("agent %s attached to body %d at (%.2f, %.2f)%s", self.opts.agent_id, welcome.body, welcome.x,
                 welcome.y, f", restart {welcome.restarts}" if welcome.restarts else "")
        self._new_brain(welcome)

    def _new_brain(self, welcome) -> None:
        # Each incarnation gets its own stream: a restart must not replay the same choices.
        rng = np.random.default_rng([self.opts.seed, welcome.restarts, self.reattaches])
        role = self.opts.role
        if role == "worker":
            self.brain = Worker(welcome, rng=rng)
        else:
            kind = ForemanBrain if role == "foreman" else Brain
            self.brain = kind(welcome, self.opts.cfg, rng, network=self.student)
        self.tick = welcome.tick - 1

    def serve(self, stop) -> None:
        """Step on every new frame until `stop` is set."""
        while stop is None or not stop.is_set():
            frame = self.link.next_frame(self.tick, timeout=None if stop is None else 0.5)
            if frame is not None:
                self.step(frame)
            elif self.link.world_lost:
                self.reattach(stop)

    def reattach(self, stop) -> None:
        """The world is gone: say so (unless it was only stopping along with this agent),
        wait for it to come back, attach again."""
        a, w = self.opts.agent_id, self.opts.world_id
        lost_at, said = time.monotonic(), 0.0
        log.info("agent %s: world %s is gone (last tick %d); waiting for it", a, w, self.tick)
        while stop is None or not stop.is_set():
            if self.link.wait_for_world(0.25):
                try:
                    welcome = self.link.attach(timeout=self.opts.attach_timeout)
                except AttachError as exc:
                    log.warning("agent %s: %s; still waiting for world %s ...", a, exc, w)
                    continue
                self.reattaches += 1
                log.warning("agent %s re-attached to world %s at tick %d (body %d at (%.2f, %.2f))", a, w,
                            welcome.tick, welcome.body, welcome.x, welcome.y)
                self._new_brain(welcome)
                return
            waited = time.monotonic() - lost_at
            # Not at once: when a run ends, its world stops a moment before its agents do.
            if waited >= WAIT_QUIET and (not said or waited - said >= WAIT_REPORT):
                log.warning("agent %s: world %s is gone (last tick %d, %.0f s ago); waiting for world %s to "
                            "come back ...", a, w, self.tick, waited, w)
                said = waited

    def step(self, frame, outbox: list[Callable[[], None]] | None = None) -> None:
        """Learn from the reinforcements that came, decide, act, tell the teacher, report.

        The command goes to the world at once, or with `outbox` is left there as a call that
        sends it (a host sends its agents' commands together: `agent_runtime.host`)."""
        learning, student, teacher = self.learning, self.student, self.teacher
        if teacher is not None:
            for d, r in teacher.poll(wait=learning.wait):
                student.learn(d.state, d.arm, d.motor, r.arm, r.motor, learning.eta)
        self.feeds.before_step(self.brain)
        step = self.brain.step(frame)
        send = partial(self.link.send, frame.tick, step.speed, step.turn, step.action, step.mark)
        if outbox is None:
            send()
        else:
            outbox.append(send)
        if teacher is not None:
            teacher.publish(step.decision)
        elif step.decision is not None:  # (a worker has no construction network to report)
            self.decisions.put(encode(step.decision))
            self.last_decision = step.decision
        self.tick = frame.tick
        self.report.ticks += 1
        self.feeds.after_step(self.brain, self.tick)
        if learning and self.report.ticks % learning.save_every == 0:
            if learning.weights_out:
                student.save(learning.weights_out)
            log.info("agent %s tick %d: %s", self.opts.agent_id, self.tick, _progress(teacher))

    def close(self) -> None:
        """A last state report, the weights saved, then everything undeclared (the token last)."""
        self.feeds.close(self.brain, max(self.tick, 0))
        if self.learning and self.learning.weights_out:
            self.student.save(self.learning.weights_out)
        if self.teacher is not None:
            self.teacher.close()
        undeclare(self.decisions, self._decision_queries)
        self.link.close()

    def _on_decision_query(self, query) -> None:
        """Answer with the newest Decision (none before the first step)."""
        decision = self.last_decision
        if decision is not None:
            query.reply(keys.decision(self.opts.world_id, self.opts.agent_id), encode(decision))


def _progress(teacher: StudentLink) -> str:
    c = teacher.counts
    return (f"{c.reinforcements} reinforcements, {c.errors} errors, teacher "
            f"{'present' if teacher.teachers else 'absent'}")

"""The agent process (`conag agent --id ID`): the zenoh shell around `brain.Brain`.

It declares its liveliness token, attaches by id (a restarted process gets its old
body back and rebuilds its maps from its sensors), then for every sensor frame: one
decision step, the command to the world, the Decision for the teacher. Frames are
"latest wins"; a slow agent acts on the newest one.

With `learning` (`conag agent --learn`) the construction network is a `Student`
(random weights from the seed, or loaded from a file) instead of the engineered one:
before each step the agent applies every reinforcement that has arrived to the decision
it answers (`student_link.StudentLink`; with a teacher present it waits up to `wait`
seconds for the answer to its last step), and saves its weights every `save_every` ticks
and on the way out. With no teacher on the bus it keeps acting on its current weights.

Blueprint changes and state reports go through `world_feeds.AgentFeeds`: the newest
blueprint is applied before each step, an AgentState is published every 100 ticks and
on exit.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np

from agent_runtime.brain import Brain
from agent_runtime.config import AgentConfig
from agent_runtime.learning import Student
from agent_runtime.link import WorldLink
from agent_runtime.student_link import StudentLink
from agent_runtime.world_feeds import AgentFeeds
from protocol import keys
from protocol.codec import encode

log = logging.getLogger("conag.agent")


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


def run_agent(session, world_id: str, agent_id: str, cfg: AgentConfig, seed: int,
              attach_timeout: float = 30.0, stop=None, learning: Learning | None = None,
              network=None, report: AgentReport | None = None) -> AgentReport:
    """Serve one body until `stop` is set (or a signal handler raises).

    `network` replaces the engineered construction network (e.g. a trained Student that
    no longer learns); `learning` makes the agent a learning student. `report` (filled in
    as it goes) is also returned.
    """
    report = report if report is not None else AgentReport()
    student = learning.student(seed) if learning else network  # a bad weights file fails before attaching
    link = WorldLink(session, world_id, agent_id)
    feeds = AgentFeeds(session, world_id, agent_id)  # before attaching: no blueprint change is missed
    brain, tick = None, 0
    teacher = StudentLink(session, world_id, agent_id) if learning else None
    decisions = None if learning else session.declare_publisher(keys.decision(world_id, agent_id), express=True)
    report.student, report.link = student, teacher
    try:
        welcome = link.attach(timeout=attach_timeout)
        log.info("agent %s attached to body %d at (%.2f, %.2f)%s", agent_id, welcome.body, welcome.x, welcome.y,
                 f", restart {welcome.restarts}" if welcome.restarts else "")
        # Each incarnation gets its own stream: a restart must not replay the same choices.
        brain = Brain(welcome, cfg, np.random.default_rng([seed, welcome.restarts]), network=student)
        tick = welcome.tick - 1
        while stop is None or not stop.is_set():
            frame = link.next_frame(tick, timeout=None if stop is None else 0.5)
            if frame is None:
                continue
            if teacher is not None:
                for d, r in teacher.poll(wait=learning.wait):
                    student.learn(d.state, d.arm, d.motor, r.arm, r.motor, learning.eta)
            feeds.before_step(brain)
            step = brain.step(frame)
            link.send(frame.tick, step.speed, step.turn, step.action)
            if teacher is not None:
                teacher.publish(step.decision)
            else:
                decisions.put(encode(step.decision))
            tick = frame.tick
            report.ticks += 1
            feeds.after_step(brain, tick)
            if learning and report.ticks % learning.save_every == 0:
                if learning.weights_out:
                    student.save(learning.weights_out)
                log.info("agent %s tick %d: %s", agent_id, tick, _progress(teacher))
    finally:
        feeds.close(brain, max(tick, 0))
        if learning and learning.weights_out:
            student.save(learning.weights_out)
        if teacher is not None:
            teacher.close()
        if decisions is not None:
            try:
                decisions.undeclare()
            except Exception:  # the session may be closing already
                pass
        link.close()
    return report


def _progress(teacher: StudentLink) -> str:
    c = teacher.counts
    return (f"{c.reinforcements} reinforcements, {c.errors} errors, teacher "
            f"{'present' if teacher.teachers else 'absent'}")

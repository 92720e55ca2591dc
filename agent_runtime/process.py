"""The agent process (`conag agent --id ID`): the zenoh shell around `brain.Brain`.

It declares its liveliness token, attaches by id (a restarted process gets its old
body back and rebuilds its maps from its sensors), then for every sensor frame: one
decision step, the command to the world, the Decision for the teacher. Frames are
"latest wins"; a slow agent acts on the newest one.
"""

from __future__ import annotations

import logging

import numpy as np

from agent_runtime.brain import Brain
from agent_runtime.config import AgentConfig
from agent_runtime.link import WorldLink
from protocol import keys
from protocol.codec import encode

log = logging.getLogger("conag.agent")


def run_agent(session, world_id: str, agent_id: str, cfg: AgentConfig, seed: int,
              attach_timeout: float = 30.0, stop=None) -> None:
    """Serve one body until `stop` is set (or a signal handler raises)."""
    link = WorldLink(session, world_id, agent_id)
    decisions = session.declare_publisher(keys.decision(world_id, agent_id), express=True)
    try:
        welcome = link.attach(timeout=attach_timeout)
        log.info("agent %s attached to body %d at (%.2f, %.2f)%s", agent_id, welcome.body, welcome.x, welcome.y,
                 f", restart {welcome.restarts}" if welcome.restarts else "")
        # Each incarnation gets its own stream: a restart must not replay the same choices.
        brain = Brain(welcome, cfg, np.random.default_rng([seed, welcome.restarts]))
        tick = welcome.tick - 1
        while stop is None or not stop.is_set():
            frame = link.next_frame(tick, timeout=None if stop is None else 0.5)
            if frame is None:
                continue
            step = brain.step(frame)
            link.send(frame.tick, step.speed, step.turn, step.action)
            decisions.put(encode(step.decision))
            tick = frame.tick
    finally:
        decisions.undeclare()
        link.close()

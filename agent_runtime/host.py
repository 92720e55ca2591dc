"""Several agents in one process (`conag agents --ids a1..a20`): the scale option of issue 15.

Each hosted agent is what `conag agent` runs (`agent_runtime.node.AgentProcess`): its own
liveliness token, attach, sensor-frame subscriber, command publisher, blueprint inbox,
state reports, brain and random stream. They share the process, its one zenoh session and
its one thread: the loop takes whichever agent's frame has come and steps that agent, so
the agents of one host think one after another, as in the in-process simulator.

What it buys: the interpreter, numpy, numba and the compiled kernels are loaded once per
host instead of once per agent (an agent process costs about 75 MB of private memory and
most of a second of CPU to start, a hosted agent a few MB and a few milliseconds), and
the world sends its frames over one connection per host; the commands of the agents
stepped in one pass over the host's frames go back together, in one zenoh batch. What it costs: the agents of a
host share one core, and a crash of the host (a SIGKILL, an exception) takes all of them.
One agent is stopped alone by a line `stop ID` on the host's stdin (`conag run` does that
for `conag kill ID`): it closes that agent's links, its token goes, and the world treats
it as gone, like a killed process; `conag restart ID` then starts it as a process of its
own.

Ids are given as a list and ranges: `a1..a20`, `a1,a3,a5`, `a1..a5,b1`.
"""

from __future__ import annotations

import logging
import queue
import re
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import replace

from agent_runtime.node import AgentOptions, AgentProcess, AgentReport

log = logging.getLogger("conag.agent")

_RANGE = re.compile(r"^([A-Za-z_-]*)(\d+)\.\.\1(\d+)$")


def parse_ids(text: str) -> list[str]:
    """Agent ids from `a1..a20` ranges and commas, in order, each once (ValueError if malformed)."""
    ids: list[str] = []
    for part in (p.strip() for p in text.split(",")):
        if not part:
            continue
        m = _RANGE.match(part)
        if m:
            first, last = int(m.group(2)), int(m.group(3))
            if last < first:
                raise ValueError(f"empty id range {part!r}")
            ids += [f"{m.group(1)}{i}" for i in range(first, last + 1)]
        elif ".." in part:
            raise ValueError(f"bad id range {part!r} (expected e.g. a1..a20)")
        else:
            ids.append(part)
    if not ids:
        raise ValueError("no agent ids given")
    if len(set(ids)) != len(ids):
        raise ValueError("an agent id is given twice")
    return ids


class AgentHost:
    """The agents of one process, stepped in one thread (see the module).

    `stop_requests`: ids to stop alone (the CLI feeds it from stdin). `reports`: one
    AgentReport per id, filled in as the agents go.
    """

    def __init__(self, session, opts: list[AgentOptions]):
        self.session = session
        self.reports = {o.agent_id: AgentReport() for o in opts}
        self.stop_requests: queue.SimpleQueue[str] = queue.SimpleQueue()
        # Links before any attach: every agent's token and subscriptions are up when the world answers.
        self.agents = {o.agent_id: AgentProcess(session, o, self.reports[o.agent_id]) for o in opts}

    def attach(self) -> None:
        """Attach every agent (each retries until the world answers or its timeout passes)."""
        for agent in self.agents.values():
            agent.attach()

    def serve(self, stop: threading.Event | None = None) -> None:
        """Step whichever agent has a new frame until `stop` is set or no agent is left."""
        pause = 0.0
        outbox: list[Callable[[], None]] = []
        while self.agents and (stop is None or not stop.is_set()):
            self._apply_stop_requests()
            stepped = False
            for agent in list(self.agents.values()):
                frame = agent.link.next_frame(agent.tick, timeout=0.0)
                if frame is not None:
                    agent.step(frame, outbox)
                    stepped = True
                elif agent.link.world_lost:
                    # The world died (`conag run` restarts it from its checkpoint): wait for it
                    # and attach again, as a lone agent does; the others follow at once. The
                    # commands not yet sent answer the dead world's frames: they go too.
                    outbox.clear()
                    agent.reattach(stop)
                    stepped = True
            # The pass's commands together, after it: zenoh writes them to the world in one
            # batch, and the world wakes once for them, not once per agent (a lockstep world
            # waits for them all anyway).
            for send in outbox:
                send()
            outbox.clear()
            if stepped:
                pause = 0.0
            else:
                # Nothing new: poll finely at first, backing off so an idle host leaves the core.
                pause = min(max(pause * 2, 0.0001), 0.002)
                time.sleep(pause)

    def _apply_stop_requests(self) -> None:
        while True:
            try:
                agent_id = self.stop_requests.get_nowait()
            except queue.Empty:
                return
            agent = self.agents.pop(agent_id, None)
            if agent is None:
                log.warning("stop %s: no such agent in this host", agent_id)
                continue
            agent.close()
            log.info("agent %s stopped (the host goes on with %d)", agent_id, len(self.agents))

    def close(self) -> None:
        """Close every agent still hosted (a last state report each, then its links)."""
        for agent in self.agents.values():
            agent.close()
        self.agents.clear()


def read_stop_requests(host: AgentHost, stream=None) -> threading.Thread:
    """A daemon thread feeding `stop ID` lines of `stream` (stdin) to the host."""
    stream = stream if stream is not None else sys.stdin

    def read() -> None:
        for line in stream:
            words = line.split()
            if len(words) == 2 and words[0] == "stop":
                host.stop_requests.put(words[1])

    thread = threading.Thread(target=read, name="host-stdin", daemon=True)
    thread.start()
    return thread


def host_options(base: AgentOptions, ids: list[str]) -> list[AgentOptions]:
    """One AgentOptions per id, the rest as in `base`."""
    return [replace(base, agent_id=agent_id) for agent_id in ids]

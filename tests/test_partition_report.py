"""The partition harness's report of a build that did not complete (faults/partition.py):
the last status and each agent's line as a stall report has it, from the agent's last
AgentState as `conag echo --json` printed it. The harness itself needs network namespaces (tests/test_partition.py);
its report is made from what it read, checked here without them."""

from __future__ import annotations

from dataclasses import asdict, replace

from conag.recording.echo import describe
from faults.partition import report_lines
from protocol import keys
from protocol.codec import encode
from protocol.messages import BEHAVIOURS, AgentState
from tests.conftest import make


def _state(agent: str, tick: int, behaviour: str, blocker: str) -> str:
    """One line of `conag echo 'agent/*/state' --json`."""
    state = AgentState(agent, tick, behaviour, False, 1, blocker, (0,) * len(BEHAVIOURS))
    return describe(keys.agent_state("w0", agent), encode(state), as_json=True)


def test_the_report_gives_each_agents_last_word_and_the_ticks_since_the_last_fill():
    world = make("A.+.+\n.A...", agents=2)
    for agent in ("a1", "a2"):
        world.attach(agent)
    status = world.status()
    statuses = [(t, asdict(replace(status, tick=tick, sites_filled=filled)))
                for t, (tick, filled) in enumerate([(10, 0), (40, 1), (60, 1), (90, 1)])]
    log = "\n".join([_state("a1", 20, "brick_nav", "old news"),
                     "not json",
                     _state("a1", 80, "explore", "no free brick on the map"),
                     '{"key": "cut off by the stop'])
    report = report_lines(statuses, log)
    assert report[0] == "last status: tick 90, 1/2 sites, no site filled for the last 50 ticks"
    a1, a2 = report[1:]
    assert a1.startswith("  a1: alive") and "explore (tick 80)" in a1 and "no free brick on the map" in a1
    assert "old news" not in a1
    assert a2.startswith("  a2: alive") and a2.endswith("no AgentState received")


def test_no_status_read_means_no_report():
    assert report_lines([], _state("a1", 5, "explore", "")) == []

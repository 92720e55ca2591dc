"""The run summary as a type (world_server/summary.py): `RunSummary` gives exactly the JSON
the dict it replaced gave, keys in the contract's order, and reads back what it wrote."""

from __future__ import annotations

import json
import os
import signal
from dataclasses import replace
from pathlib import Path

import pytest

from protocol.messages import BEHAVIOURS, AgentState, WorldStatus
from world_server.summary import AgentSummary, RunSummary, run_summary, write_summary

STATUS = WorldStatus(world_id="w0", scenario="walled", seed=5, mode="lockstep", tick=900, sites_filled=3,
                     sites_total=4, bricks_total=6, agents_alive=2, bad_messages=0, completed=False,
                     agent_ids=("a2", "a10", "a1"), agent_alive=(True, True, False),
                     agent_distance=(3.1234567891, 1.0, 0.0), agent_grabs=(1, 0, 2), agent_drops=(0, 0, 2),
                     agent_restarts=(0, 1, 0), agent_x=(4.25, 6.5, 1.0), agent_y=(4.5, 4.5, 1.0),
                     agent_present=(True, True, False))


def state(agent: str) -> AgentState:
    ticks = tuple(i for i, _ in enumerate(BEHAVIOURS))
    return AgentState(agent_id=agent, tick=300, behaviour=BEHAVIOURS[1], holding=True, sites_open=1,
                      blocker="", behaviour_ticks=ticks)


def as_it_was(status: WorldStatus, states: dict[str, AgentState], stalled: bool) -> dict:
    """The summary as world_server/summary.py built it before it was a type (edf9282)."""
    agents = sorted(
        ({"id": a, "distance": round(d, 6), "grabs": g, "drops": dr, "restarts": r,
          "behaviour_ticks": {n: k for n, k in zip(BEHAVIOURS, states[a].behaviour_ticks) if k} if a in states
          else {}}
         for a, d, g, dr, r in zip(status.agent_ids, status.agent_distance, status.agent_grabs,
                                   status.agent_drops, status.agent_restarts)),
        key=lambda agent: str(agent["id"]))
    return {"scenario": status.scenario, "seed": status.seed, "completed": status.completed, "stalled": stalled,
            "ticks": status.tick, "sites_total": status.sites_total, "sites_filled": status.sites_filled,
            "bricks_total": status.bricks_total, "total_distance": round(sum(status.agent_distance), 6),
            "agents": agents}


def test_the_summary_is_the_json_it_was_key_for_key_in_order():
    states = {"a2": state("a2")}
    for stalled in (False, True):
        old = as_it_was(STATUS, states, stalled)
        new = RunSummary.of(STATUS, states, stalled)
        assert json.dumps(new.as_dict(), indent=2) == json.dumps(old, indent=2)
        assert new.to_json() == json.dumps(old, indent=2) + "\n"
        assert json.dumps(run_summary(STATUS, states, stalled)) == json.dumps(old)
    assert [a.id for a in RunSummary.of(STATUS).agents] == ["a1", "a10", "a2"]


def test_conag_run_adds_world_restarts_last():
    new = replace(RunSummary.of(STATUS), stalled=True, world_restarts=2)
    old = as_it_was(STATUS, {}, False)
    old["stalled"] = True            # what `conag run` did to the world's dict
    old["world_restarts"] = 2
    assert new.to_json() == json.dumps(old, indent=2) + "\n"


def test_a_summary_reads_back_what_it_wrote(tmp_path):
    written = write_summary(STATUS, tmp_path / "s.json", {"a1": state("a1")}, stalled=True)
    text = (tmp_path / "s.json").read_text(encoding="utf-8")
    back = RunSummary.from_json(text)
    assert back == written and back.to_json() == text
    assert isinstance(back.agents[0], AgentSummary)
    assert back.agents[0].behaviour_ticks == written.agents[0].behaviour_ticks
    with_restarts = replace(back, world_restarts=0)
    assert RunSummary.from_json(with_restarts.to_json()) == with_restarts


def test_conag_run_records_which_agent_ran_before_world_restarts():
    agent = {"preset": "paper", "without": ["ghost_association"], "changed": {"map_size": 31}}
    new = replace(RunSummary.of(STATUS), world_restarts=1, agent=agent)
    data = json.loads(new.to_json())
    assert list(data)[-3:] == ["agents", "agent", "world_restarts"] and data["agent"] == agent
    assert RunSummary.from_json(new.to_json()) == new
    assert "agent" not in RunSummary.of(STATUS).as_dict()   # the world's own summary: it does not know


def test_a_summary_is_written_whole_or_not_at_all(tmp_path, monkeypatch):
    path = tmp_path / "s.json"
    write_summary(STATUS, path)
    before = path.read_text()

    def full_disk(*_args, **_kwargs):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(os, "replace", full_disk)  # the new text written, then the disk full
    with pytest.raises(OSError):
        write_summary(replace(STATUS, tick=901), path)
    monkeypatch.undo()
    assert path.read_text() == before  # the summary there is untouched, and no temporary is left
    assert [p.name for p in tmp_path.iterdir()] == ["s.json"]


def test_the_world_writes_its_summary_before_a_late_sigterm_can_stop_it(tmp_path, monkeypatch, endpoint):
    """`conag run` stops its world with SIGINT, then SIGTERM: the world's summary is written
    while its own handlers still take such signals (once Python's default is back, a SIGTERM
    kills the process mid-write, and the run read an empty summary: CI, once)."""
    from conag import cli
    from conag.commands import world as world_command

    handlers = []

    def write(*args, **kwargs):
        handlers.append(signal.getsignal(signal.SIGTERM))
        return write_summary(*args, **kwargs)

    monkeypatch.setattr(world_command, "write_summary", write)
    path = tmp_path / "final.json"
    scenario = str(Path(__file__).resolve().parent.parent / "scenarios" / "quick_wall.toml")
    assert cli.main(["world", scenario, "--tick-mode", "realtime", "--ticks", "3", "--listen", endpoint,
                     "--quiet", "--summary", str(path)]) == 0
    assert handlers and handlers[0] not in (signal.SIG_DFL, signal.default_int_handler, None)
    assert RunSummary.from_json(path.read_text()).ticks == 3


@pytest.mark.parametrize("text", ["", "{\"not\": \"a summary\"}"])
def test_conag_run_says_which_file_when_the_worlds_summary_cannot_be_read(tmp_path, text):
    from conag import run as supervisor

    class Exited:
        returncode = 0

    path = tmp_path / "final.json"
    path.write_text(text)
    with pytest.raises(RuntimeError, match=r"the world's final status .*final\.json cannot be read"):
        supervisor._final_summary(path, Exited())

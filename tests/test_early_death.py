"""No stop at start-up, no silent wait (issue 35): a lockstep world told that an agent died
before attaching goes on without it, and a lockstep world that cannot tick (agents still
to attach, none live any more) says so every few seconds; `conag run` goes on without an
agent process that died before the first tick, and starts it again when asked."""

from __future__ import annotations

import json
import logging
import subprocess
import sys
import threading
import time

import pytest

from agent_runtime.world_link import WorldLink
from conag import run as conag_run
from conag.agent_settings import AgentSettings
from conag.run import RunOptions, exit_words, run
from tests.conftest import LONG_WALL, conag, free_port, wait_until
from tests.scripted import ScriptedBody
from world_server.scenario import load_scenario, parse_scenario
from world_server.server import WAIT_REPORT, read_go_without_requests

WORLD = '''
name = "early"
seed = 3
agents = 2
layout = """
..........
..A.b..+..
..........
"""
[world]
sensor_noise = 0.0
status_period = 0.05
'''


def test_a_lockstep_world_goes_without_an_agent_that_died_before_attaching(bus, start_world):
    statuses = []
    rw = start_world(WORLD, wait_agents=2, on_status=statuses.append)
    a1 = ScriptedBody(WorldLink(bus.client_session(), "w0", "a1"))
    a1.link.send(a1.frame.tick, 0.0, 0.0)
    seen = len(statuses)
    wait_until(lambda: len(statuses) >= seen + 3, what="the world's loop to go round")
    assert rw.world.tick == 0  # it waits for a2
    rw.server.go_without("a2")
    for _ in range(3):
        a1.act(0.0, 0.0)
    assert rw.world.tick == 3 and list(rw.world.agents) == ["a1"]


def test_go_without_requests_are_read_from_the_worlds_stdin():
    told = []

    class Server:
        def go_without(self, agent):
            told.append(agent)

    lines = ["without a2\n", "without\n", "stop a3\n", "without a/*\n", "without a4 now\n", "without a5\n"]
    read_go_without_requests(Server(), iter(lines)).join(5)
    assert told == ["a2", "a5"]


def test_a_lockstep_world_that_cannot_tick_says_why_every_few_seconds(bus, start_world, caplog):
    # A clock fifty times as fast as the wall's: WAIT_REPORT seconds pass in a tenth of one.
    fast = lambda: time.monotonic() * 50  # noqa: E731
    with caplog.at_level(logging.WARNING, logger="conag.world"):
        rw = start_world(WORLD, wait_agents=1, clock=fast)

        def warnings(text: str) -> list[str]:
            return [r.getMessage() for r in caplog.records if text in r.getMessage()]

        wait_until(lambda: len(warnings("waiting")) >= 2, what="two lines about the wait for agents")
        assert warnings("waiting")[0].startswith("tick 0: waiting ")
        assert "for agents to attach: 0 of 1 so far; no tick before they all have" in warnings("waiting")[0]
        link = WorldLink(bus.client_session(), "w0", "a1")
        a1 = ScriptedBody(link)
        a1.act(0.0, 0.0)
        link.close()                          # its process is gone: no live agent is left
        wait_until(lambda: warnings("no live agent"), what="a line about no live agent")
        assert "(a1 gone): waiting for one to attach; no tick before" in warnings("no live agent")[0]
        assert rw.world.tick >= 1
    assert WAIT_REPORT <= 10  # "every few seconds"


def test_exit_words_say_how_a_process_ended():
    assert exit_words(2) == "exited (code 2)"
    assert exit_words(-9) == "was killed (SIGKILL)"


# --- conag run ------------------------------------------------------------------------------------

def _dying_agent(monkeypatch, dies: str):
    """`conag run`'s agent `dies` is, the first time, a process that exits at once (code 3)."""
    start, started = conag_run.Fleet.start, set()

    def fake_start(fleet, agent_id):
        if agent_id != dies or agent_id in started:
            return start(fleet, agent_id)
        started.add(agent_id)
        proc = subprocess.Popen([sys.executable, "-c", "raise SystemExit(3)"])
        with fleet.lock:
            fleet.procs[agent_id] = proc
        return proc

    monkeypatch.setattr(conag_run.Fleet, "start", fake_start)


@pytest.mark.slow
def test_conag_run_goes_on_without_an_agent_that_died_before_the_first_tick(tmp_path, monkeypatch, capsys):
    _dying_agent(monkeypatch, "a2")
    out = tmp_path / "summary.json"
    opts = RunOptions("scenarios/quick_wall.toml", load_scenario("scenarios/quick_wall.toml"),
                      f"tcp/127.0.0.1:{free_port()}", agents=2, headless=True, quiet=True, summary=str(out))
    summary = run(opts, threading.Event())
    out_text = capsys.readouterr().out
    assert "agent a2 exited (code 3) before the world's first tick: the run goes on without it" in out_text
    assert summary["completed"] and [a["id"] for a in summary["agents"]] == ["a1"]
    assert json.loads(out.read_text())["completed"]


@pytest.mark.slow
def test_conag_run_starts_an_agent_that_died_before_the_first_tick_again_when_asked(tmp_path, monkeypatch):
    _dying_agent(monkeypatch, "a2")
    told = threading.Event()
    go_without = conag_run.WorldProcess.go_without

    def tell(world, agent):
        go_without(world, agent)
        told.set()

    monkeypatch.setattr(conag_run.WorldProcess, "go_without", tell)
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    scenario = tmp_path / "long.toml"
    scenario.write_text(LONG_WALL)
    opts = RunOptions(str(scenario), parse_scenario(LONG_WALL), endpoint, headless=True, quiet=True)
    result = {}
    runner = threading.Thread(target=lambda: result.update(run(opts, threading.Event())), daemon=True)
    runner.start()
    assert told.wait(60), "conag run did not tell the world of a2"
    restarted = conag("restart", "a2", "--connect", endpoint)
    assert restarted.returncode == 0 and "started a2" in restarted.stdout, restarted.stderr
    runner.join(300)
    assert result["completed"]
    assert sorted(a["id"] for a in result["agents"]) == ["a1", "a2", "a3"]
    assert next(a for a in result["agents"] if a["id"] == "a2")["drops"] > 0


@pytest.mark.slow
def test_conag_run_ends_when_every_agent_died_before_the_first_tick(endpoint):
    # Every agent process exits at once (a preset it does not know): nothing is left to build.
    opts = RunOptions("scenarios/quick_wall.toml", load_scenario("scenarios/quick_wall.toml"), endpoint,
                      headless=True, quiet=True, agent=AgentSettings(preset="no-such-preset"))
    started = time.monotonic()
    with pytest.raises(RuntimeError, match="every agent process exited before the world's first tick"):
        run(opts, threading.Event())
    assert time.monotonic() - started < 60

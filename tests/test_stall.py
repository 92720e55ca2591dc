"""A run never stalls in silence (issue #10, part 4): the stall clock, the report, the
in-process simulator's stall stop, and `conag run --stall-ticks` (exit code 4, the report
naming every agent, `stalled` and behaviour counts in the summary)."""

from __future__ import annotations

import json
from dataclasses import replace

import pytest

from conag import sim
from protocol.messages import BEHAVIOURS, AgentState, Perturbation, WorldStatus
from tests.conftest import conag, free_port
from world_server.scenario import parse_scenario
from world_server.stall import StallClock, StallWatch, stall_report
from world_server.summary import run_summary

# The only site is walled in by `#`: no agent can ever bring a brick to it.
WALLED = '''
name = "walled"
seed = 5
agents = 2
max_ticks = 20000
layout = """
...........
.b..A.A..b.
...........
......###..
......#+#..
......###..
"""
'''


def state(agent: str, behaviour: str = "explore", **kw) -> AgentState:
    ticks = tuple(7 if b == behaviour else 0 for b in BEHAVIOURS)
    return AgentState(**{"agent_id": agent, "tick": 300, "behaviour": behaviour, "holding": True, "sites_open": 1,
                         "blocker": "holds a brick but no open site is reachable", "behaviour_ticks": ticks, **kw})


STATUS = WorldStatus(world_id="w0", scenario="walled", seed=5, mode="lockstep", tick=900, sites_filled=0,
                     sites_total=1, bricks_total=2, agents_alive=1, bad_messages=0, completed=False,
                     agent_ids=("a1", "a2"), agent_alive=(True, False), agent_distance=(3.0, 1.0),
                     agent_grabs=(1, 0), agent_drops=(0, 0), agent_restarts=(0, 0),
                     agent_x=(4.25, 6.5), agent_y=(4.5, 4.5), agent_present=(True, True))


# ---------------------------------------------------------------- the clock and the report


def test_the_clock_stops_a_run_only_after_limit_ticks_without_a_fill():
    c = StallClock(100)
    assert not c.observe(0, 0, 3) and not c.observe(99, 0, 3)
    assert c.observe(100, 0, 3) and c.idle(100) == 100
    assert not c.observe(150, 1, 3) and c.idle(150) == 0           # a site filled: progress
    assert not c.observe(240, 0, 3)                                # a brick taken off a site ...
    assert c.observe(250, 1, 3) and c.since == 150                 # ... and put back is no progress:
    assert not c.observe(260, 2, 3) and c.since == 260             # only beating the best (1) is
    assert not c.observe(390, 2, 4) and c.since == 390             # a site added: a fresh count
    assert c.observe(490, 2, 4)
    assert not c.observe(10_000, 4, 4)                             # nothing left to do: never stalled
    with pytest.raises(ValueError):
        StallClock(0)


def test_a_team_still_sweeping_the_world_for_bricks_is_not_stalled():
    c = StallClock(100)
    assert not c.observe(0, 0, 3, searched=0)
    assert not c.observe(90, 0, 3, searched=4) and c.since == 90   # new squares seen: progress
    assert not c.observe(189, 0, 3, searched=4)
    assert c.observe(190, 0, 3, searched=4)                        # nothing new for 100 ticks
    assert not c.observe(200, 1, 3, searched=4) and c.since == 200 # a fill still counts


FAR_PILE = """
name = "far pile"
seed = 3
agents = 1
max_ticks = 20000
layout = \"\"\"
{rows}
\"\"\"
"""


def test_a_simrun_does_not_stop_an_agent_that_is_still_searching_the_world():
    # The pile is 70 cells from the agent, far beyond its sensors: finding it takes longer
    # than the stall limit, but every square the agent sweeps is new, so the run goes on.
    rows = ["." * 78 for _ in range(12)]
    rows[5] = "A.+" + "." * 70 + "bbb.."
    run = sim.start(parse_scenario(FAR_PILE.format(rows="\n".join(rows))))
    result = run.run(6000, stall_ticks=600)
    assert result.completed and run.filled_at.min() > 600, (result, run.filled_at)
    assert run.brains["a1"].searched > 0


def test_the_report_names_every_agent_with_its_position_and_last_state():
    lines = stall_report(STATUS, 600, {"a1": state("a1", "brick_nav")})
    assert lines[0] == "STALLED at tick 900: no site filled for 600 ticks (0/1 sites)"
    assert lines[1] == ("  a1: alive at (4.25, 4.50): brick_nav (tick 300), holding a brick, 1 sites open, "
                        "blocker: holds a brick but no open site is reachable")
    assert lines[2] == "  a2: GONE at (6.50, 4.50): no AgentState received"


# The last site is inside a closed `#` box: an agent fills the one it can reach, then
# believes every site is filled (it never sees the boxed one open), though the world counts
# 1/2. The report must say why the build stalled (issue 35), not repeat the agent's belief.
BOXED = '''
name = "boxed"
seed = 1
agents = 1
max_ticks = 20000
layout = """
..........
.A...+....
.bb.......
......###.
......#+#.
......###.
"""
'''
BOXED_WHY = "site (7,4) is inside a closed ring with no brick and no way in"


def test_an_agent_that_believes_every_site_filled_gets_the_start_up_checks_reason_as_its_blocker():
    status = replace(STATUS, sites_filled=5, sites_total=6)
    believes = state("a1", sites_open=0, blocker="believes every site is filled")
    line = stall_report(status, 600, {"a1": believes}, BOXED_WHY)[1]
    assert line.endswith(f"blocker: {BOXED_WHY} (found at start-up; the agent: believes every site is filled)")
    # No reason found at start-up: the world's count says the agent is wrong.
    line = stall_report(status, 600, {"a1": believes})[1]
    assert line.endswith("blocker: believes every site is filled, but the world counts 1 open")
    # An agent that names what blocks it, with sites open, is taken at its word.
    line = stall_report(status, 600, {"a1": state("a1")}, BOXED_WHY)[1]
    assert line.endswith("blocker: holds a brick but no open site is reachable")
    # A watch passes the reason on to its report.
    watch = StallWatch(300, BOXED_WHY)
    watch.states["a1"] = believes
    assert not watch.observe(replace(status, tick=100)) and watch.observe(replace(status, tick=400))
    assert BOXED_WHY in watch.report[1]


def test_the_summary_has_stalled_and_each_agents_behaviour_ticks():
    s = run_summary(STATUS, {"a1": state("a1", "config_nav")}, stalled=True)
    assert s["stalled"] is True and s["completed"] is False
    assert [a["behaviour_ticks"] for a in s["agents"]] == [{"config_nav": 7}, {}]
    assert run_summary(STATUS)["stalled"] is False


# ---------------------------------------------------------------- in process (sim)


def test_a_simrun_that_cannot_progress_stops_as_stalled_and_reports_why():
    run = sim.start(parse_scenario(WALLED))
    result = run.run(5000, stall_ticks=300)
    assert (result.completed, result.stalled, result.ticks) == (False, True, 300)
    assert not result                                              # falsy, as the old bool
    assert {a: sum(c.values()) for a, c in run.behaviour_ticks.items()} == {"a1": 300, "a2": 300}
    lines = run.stall_report()
    assert lines[0] == "STALLED at tick 300: no site filled for 300 ticks (0/1 sites)"
    assert [line.split(":")[0] for line in lines[1:]] == ["  a1", "  a2"]
    assert all("alive at (" in line and "blocker:" in line for line in lines[1:]), lines


def test_a_simrun_stalled_by_a_site_in_a_closed_box_names_it_as_the_blocker():
    run = sim.start(parse_scenario(BOXED))
    result = run.run(5000, stall_ticks=300)
    assert result.stalled and run.world.status().sites_filled == 1
    lines = run.stall_report()
    assert "(1/2 sites)" in lines[0]
    assert f"0 sites open, blocker: {BOXED_WHY} (found at start-up; the agent: believes every site is filled)" \
        in lines[1], lines


@pytest.mark.slow
def test_a_simrun_counts_from_each_run_and_a_fill_restarts_the_count():
    run = sim.start(parse_scenario(WALLED))
    assert run.run(120) == sim.SimResult(False, False, 120)        # no limit: runs to max_ticks
    result = run.run(400, stall_ticks=300)                         # the count starts with this run
    assert result.stalled and result.ticks == 420
    assert run.perturb(Perturbation("add_site", 2.5, 3.5)).ok        # a site the agents can reach
    result = run.run(5000, stall_ticks=300)
    assert result.stalled and run.world.status().sites_filled == 1
    filled_at = int(run.filled_at.max())
    assert filled_at > 420 and result.ticks == filled_at + 300


# ---------------------------------------------------------------- conag run


@pytest.mark.slow
def test_conag_run_stops_a_stalled_build_with_exit_code_4_and_a_report(tmp_path):
    scenario, out = tmp_path / "walled.toml", tmp_path / "summary.json"
    scenario.write_text(WALLED)
    r = conag("run", scenario, "--headless", "--stall-ticks", 300, "--summary", out,
              "--listen", f"tcp/127.0.0.1:{free_port()}", timeout=120)
    assert r.returncode == 4, r.stdout + r.stderr
    lines = r.stdout.splitlines()
    head = next(i for i, line in enumerate(lines) if line.startswith("STALLED at tick "))
    assert "no site filled for" in lines[head] and "(0/1 sites)" in lines[head]
    for agent, line in zip(("a1", "a2"), lines[head + 1:head + 3]):
        assert line.startswith(f"  {agent}: alive at (") and "blocker:" in line, line
    assert "walled: STALLED: 0/1 sites" in r.stdout
    s = json.loads(out.read_text())
    assert s["stalled"] is True and s["completed"] is False
    assert [a["id"] for a in s["agents"]] == ["a1", "a2"]
    for a in s["agents"]:
        assert set(a["behaviour_ticks"]) <= set(BEHAVIOURS) and sum(a["behaviour_ticks"].values()) > 0, a


@pytest.mark.slow
def test_conag_run_names_the_unreachable_site_as_the_blocker_of_a_stalled_build(tmp_path):
    scenario = tmp_path / "boxed.toml"
    scenario.write_text(BOXED)
    r = conag("run", scenario, "--headless", "--stall-ticks", 300, "--listen", f"tcp/127.0.0.1:{free_port()}",
              timeout=120)
    assert r.returncode == 4, r.stdout + r.stderr
    assert f"cannot be built: {BOXED_WHY}" in r.stderr
    lines = r.stdout.splitlines()
    head = next(i for i, line in enumerate(lines) if line.startswith("STALLED at tick "))
    assert "(1/2 sites)" in lines[head]
    assert lines[head + 1].startswith("  a1: alive at (") and f"blocker: {BOXED_WHY}" in lines[head + 1], lines

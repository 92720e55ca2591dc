"""`conag run`: a world and one process per agent build the structure; agents die and return."""

from __future__ import annotations

import json

import pytest

from tests.conftest import LONG_WALL, conag, free_port, run_and_restart_mid_build

pytestmark = pytest.mark.slow


def test_run_builds_fig6_with_three_agent_processes_and_writes_the_summary(tmp_path):
    out = tmp_path / "summary.json"
    r = conag("run", "scenarios/fig6.toml", "--headless", "--summary", out,
              "--listen", f"tcp/127.0.0.1:{free_port()}", timeout=240)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "fig6: complete" in r.stdout
    assert any(line.startswith("tick ") and "sites" in line for line in r.stdout.splitlines())  # progress
    s = json.loads(out.read_text())
    assert set(s) == {"scenario", "seed", "completed", "stalled", "ticks", "sites_total", "sites_filled",
                      "bricks_total", "total_distance", "agents", "agent", "world_restarts"}
    assert s["world_restarts"] == 0
    assert s["agent"] == {"preset": "default", "without": [], "changed": {}}   # which agent ran
    assert s["stalled"] is False and all(a["behaviour_ticks"] for a in s["agents"])
    assert s["completed"] and s["sites_filled"] == s["sites_total"] == 4 and s["bricks_total"] == 5
    assert [a["id"] for a in s["agents"]] == ["a1", "a2", "a3"]
    assert sum(a["drops"] for a in s["agents"]) >= 4
    assert s["total_distance"] == pytest.approx(sum(a["distance"] for a in s["agents"]), abs=1e-3)


def test_the_papers_agent_builds_fig6_and_the_summary_says_it_ran(tmp_path):
    out = tmp_path / "summary.json"
    r = conag("run", "scenarios/fig6.toml", "--headless", "--summary", out, "--agent", "paper",
              "--listen", f"tcp/127.0.0.1:{free_port()}", timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    s = json.loads(out.read_text())
    assert s["completed"] and s["agent"] == {"preset": "paper", "without": [], "changed": {}}


def test_an_agent_killed_mid_build_and_restarted_rejoins_and_the_structure_completes(tmp_path):
    # `conag restart` SIGKILLs the process (mid-build, perhaps holding a brick) and starts
    # a new one with the same id at once; a separate `conag kill` first would let the
    # two others finish this small structure before the new process is up. In lockstep at
    # most 100 ticks a second, the build lasts about 10 s whatever the machine's speed
    # (in realtime the agents' timing differs run to run, and 1 build in 4 of the 10 fresh-
    # clone CI runs stalled at 29 of 30 sites: an agent's fragility, not the restart's).
    s, restarted = run_and_restart_mid_build(tmp_path, LONG_WALL, "--max-tick-rate", 100)
    assert restarted.returncode == 0 and "started a2" in restarted.stdout, restarted.stderr
    assert s["completed"] and s["bricks_total"] == 32
    restarts = {a["id"]: a["restarts"] for a in s["agents"]}
    assert restarts == {"a1": 0, "a2": 1, "a3": 0}


def test_kill_with_no_run_going_is_a_clear_error():
    r = conag("kill", "a1", "--connect", f"tcp/127.0.0.1:{free_port()}", "--timeout", "1")
    assert r.returncode == 1 and "no `conag run`" in r.stderr


def test_a_bad_map_size_is_a_usage_error_before_anything_starts():
    r = conag("run", "scenarios/quick_wall.toml", "--map-size", 40, "--listen", f"tcp/127.0.0.1:{free_port()}")
    assert r.returncode == 2 and "map_size must be an odd integer" in r.stderr

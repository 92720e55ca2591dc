"""`python3 -m faults.chaos`: a build goes on while agent processes are SIGKILLed at random, some started
again and some left dead; it completes and no brick is lost or made. The runs are slow tests;
whom a kill may pick is checked without one."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from faults.chaos import ChaosOptions, Roster
from tests.conftest import ROOT


def chaos(*args, timeout: float) -> subprocess.CompletedProcess:
    """`python3 -m faults.chaos ARGS...` to the end, from the repository root."""
    return subprocess.run([sys.executable, "-m", "faults.chaos", *map(str, args)], cwd=ROOT, capture_output=True,
                          text=True, timeout=timeout)


def test_a_kill_spares_an_agent_until_it_has_lived_min_life_ticks():
    roster = Roster(["a1", "a2"])
    assert roster.ready(199, 200) == []
    assert roster.ready(200, 200) == ["a1", "a2"]
    roster.born["a1"] = 250  # restarted at tick 250
    assert roster.ready(449, 200) == ["a2"] and roster.ready(450, 200) == ["a1", "a2"]
    assert roster.ready(240, 200) == ["a2"]  # a world gone back to an older checkpoint: a1 waits
    assert roster.ready(0, 0) == ["a2"]
    with pytest.raises(ValueError, match="--min-life"):
        ChaosOptions("scenarios/fig6.toml", min_life=-1)
    with pytest.raises(ValueError, match="--world-min-life"):
        ChaosOptions("scenarios/fig6.toml", kill_world_every=1.0, world_min_life=-1)


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_nested_squares_completes_under_random_kills_with_bricks_total_kept(tmp_path):
    # A build of a few seconds (about 3,400 ticks): fig6 completes in about one second once
    # the kernels are cached, often before the first kill. A kill every 1.5 s would, on a
    # slow machine, come before a restarted process has done anything (a lone agent that
    # lives 30-80 ticks at a time stalls at 31/32: each new process has to see inside the
    # outer ring again before it closes it); --min-life (200 ticks) spares it until it has.
    out = tmp_path / "chaos.json"
    r = chaos("scenarios/nested_squares.toml", "--runs", 2, "--kill-every", 1.5, "--seed", 1, "--json", out,
              timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    report = json.loads(out.read_text())
    assert report["total"] == 2 and report["completed"] == 2 and report["bricks_kept"] == 2
    runs = report["runs"]
    assert all(run["bricks_total"] == run["bricks_expected"] > 0 for run in runs)
    assert sum(run["kills"] for run in runs) >= 2, r.stdout  # it did kill
    assert all(life >= 200 for run in runs for life in run["lives"]), r.stdout
    assert "2/2 runs complete" in r.stdout


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_nested_squares_completes_while_its_world_is_sigkilled(tmp_path):
    # The world process itself is SIGKILLed a third of a second or so after it has ticked 500
    # ticks past where it (re)started; `conag run` restarts it from its last checkpoint and
    # the agents attach again by themselves. One agent: a build of about 3,400 ticks, so some
    # six kills on any machine (a kill a second alone gave an idle machine's 6 s build one).
    out = tmp_path / "chaos.json"
    r = chaos("scenarios/nested_squares.toml", "--agents", 1, "--runs", 1, "--kill-every", 0,
              "--kill-world-every", 0.3, "--world-min-life", 500, "--checkpoint-every", 50, "--seed", 2,
              "--json", out, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    report = json.loads(out.read_text())
    run = report["runs"][0]
    assert run["completed"] and run["bricks_total"] == run["bricks_expected"] > 0, r.stdout
    assert run["world_restarts"] >= 2, r.stdout  # it did kill the world, more than once
    # Every restarted world went on from at most one checkpoint interval before the kill.
    assert len(run["ticks_lost"]) >= 2 and all(0 <= n <= 50 for n in run["ticks_lost"]), r.stdout

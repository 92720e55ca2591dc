"""`conag chaos`: a build goes on while agent processes are SIGKILLed at random, some started
again and some left dead; it completes and no brick is lost or made."""

from __future__ import annotations

import json

import pytest

from tests.conftest import conag

pytestmark = pytest.mark.slow


@pytest.mark.timeout(600)
def test_nested_squares_completes_under_random_kills_with_bricks_total_kept(tmp_path):
    # A build of a few seconds (about 3,400 ticks): fig6 completes in about one second once
    # the kernels are cached, often before the first kill, and kills much faster than an
    # agent process starts would leave nobody working.
    out = tmp_path / "chaos.json"
    r = conag("chaos", "scenarios/nested_squares.toml", "--runs", 2, "--kill-every", 1.5, "--seed", 1, "--json", out,
              timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    report = json.loads(out.read_text())
    assert report["total"] == 2 and report["completed"] == 2 and report["bricks_kept"] == 2
    runs = report["runs"]
    assert all(run["bricks_total"] == run["bricks_expected"] > 0 for run in runs)
    assert sum(run["kills"] for run in runs) >= 2, r.stdout  # it did kill
    assert "2/2 runs complete" in r.stdout


@pytest.mark.timeout(600)
def test_nested_squares_completes_while_its_world_is_sigkilled(tmp_path):
    # The world process itself is SIGKILLed every second or so once it ticks (again);
    # `conag run` restarts it from its last checkpoint and the agents attach again by
    # themselves. One agent: a build of about 2,700 ticks, long enough for a few kills even
    # on an idle machine (with two it ended after two kills, the second as it completed).
    out = tmp_path / "chaos.json"
    r = conag("chaos", "scenarios/nested_squares.toml", "--agents", 1, "--runs", 1, "--kill-every", 0,
              "--kill-world-every", 1, "--checkpoint-every", 50, "--seed", 2, "--json", out, timeout=600)
    assert r.returncode == 0, r.stdout + r.stderr
    report = json.loads(out.read_text())
    run = report["runs"][0]
    assert run["completed"] and run["bricks_total"] == run["bricks_expected"] > 0, r.stdout
    assert run["world_restarts"] >= 2, r.stdout  # it did kill the world, more than once
    # Every restarted world went on from at most one checkpoint interval before the kill.
    assert len(run["ticks_lost"]) >= 2 and all(0 <= n <= 50 for n in run["ticks_lost"]), r.stdout

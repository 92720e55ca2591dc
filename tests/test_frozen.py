"""Frozen processes cost no build (issue 35): an agent, the world or the `conag run`
supervisor stopped with SIGSTOP for 15 s mid-build, then SIGCONT; the structure is still
finished and no brick is lost or made. Slow tests: each freezes a real process."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

from tests.conftest import ROOT, run_acting_mid_build, wait_until

SCENARIO = ROOT / "scenarios" / "nested_squares.toml"
FREEZE_S = 15.0


def _bricks_in(path: Path) -> int:
    from world_server.scenario import load_scenario

    sc = load_scenario(path)
    return int(sc.grid("b").sum() + sc.grid("B").sum())


def _pid_of(*words: str) -> int | None:
    """The pid of the process whose command line holds every one of `words` (this run's)."""
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            cmd = Path(f"/proc/{entry}/cmdline").read_bytes()
        except OSError:
            continue
        # NUL-separated, or one string with spaces (a process forked by the fork server, titled)
        args = cmd.replace(b"\0", b" ").decode(errors="replace").split()
        if all(w in args for w in words):
            return int(entry)
    return None


def _freeze_mid_build(tmp_path: Path, target) -> dict:
    """`conag run` nested_squares with two agents; once it ticks, SIGSTOP the process
    `target(endpoint, run)` names for FREEZE_S seconds, then SIGCONT; the run's summary."""
    def freeze(ep: str, run: subprocess.Popen) -> None:
        pid = wait_until(lambda: target(ep, run), timeout=30, what="the process to freeze")
        os.kill(pid, signal.SIGSTOP)
        try:
            time.sleep(FREEZE_S)  # the freeze itself is what is tested: a fixed length, by design
        finally:
            os.kill(pid, signal.SIGCONT)

    out = tmp_path / "summary.json"
    run_acting_mid_build(SCENARIO, out, freeze, "--agents", 2, timeout=400)
    return json.loads(out.read_text())


def _check(summary: dict) -> None:
    assert summary["completed"] and summary["sites_filled"] == summary["sites_total"] > 0
    assert summary["bricks_total"] == _bricks_in(SCENARIO)


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_a_frozen_agent_costs_no_build(tmp_path):
    _check(_freeze_mid_build(tmp_path, lambda ep, run: _pid_of("agent", "a2", ep)))


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_a_frozen_world_costs_no_build(tmp_path):
    _check(_freeze_mid_build(tmp_path, lambda ep, run: _pid_of("world", ep)))


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_a_frozen_supervisor_costs_no_build(tmp_path):
    _check(_freeze_mid_build(tmp_path, lambda ep, run: run.pid))

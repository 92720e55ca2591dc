"""`conag run --secure`: a router with access control on loopback, every process a client
with its own credential; the build completes, and only the operator's credential can
restart an agent of the run."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

import pytest

from conag.cli import main as conag_main
from protocol.bus.deployment import client_file
from tests.conftest import ROOT, conag, free_port

pytestmark = pytest.mark.slow


def test_run_secure_with_fresh_credentials_builds_quick_wall(tmp_path):
    out = tmp_path / "summary.json"
    r = conag("run", "scenarios/quick_wall.toml", "--secure", "--headless", "--summary", out,
              "--listen", f"tcp/127.0.0.1:{free_port()}", timeout=240)
    assert r.returncode == 0, r.stdout + r.stderr
    assert "secure bus: router on" in r.stdout and "quick_wall: complete" in r.stdout
    s = json.loads(out.read_text())
    assert s["completed"] and s["sites_filled"] == 3 and s["bricks_total"] == 4


# Three agents, three sites, two bricks: a build that never completes, so the run is still
# going whatever the machine's speed when the checks below reach it (stopped by SIGTERM).
ENDLESS = '''
name = "endless"
seed = 3
agents = 3
max_ticks = 1000000
layout = """
..........
..+++.....
..........
.b..A.A.A.
.........b
"""
'''


def test_run_secure_with_a_deployment_only_the_operator_restarts_an_agent(tmp_path):
    keys_dir = tmp_path / "keys"
    assert conag_main(["keys", str(keys_dir), "--agents", "3"]) == 0
    out = tmp_path / "summary.json"
    ep = f"tcp/127.0.0.1:{free_port()}"
    scenario = tmp_path / "endless.toml"
    scenario.write_text(ENDLESS)
    run = subprocess.Popen([sys.executable, "-m", "conag", "run", str(scenario), "--headless", "--secure",
                            str(keys_dir), "--stall-ticks", "0", "--summary", str(out), "--listen", ep], cwd=ROOT,
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)

    def as_(user, *args):
        return conag(*args, "--zenoh-config", keys_dir / client_file(user), "--connect", ep)

    try:
        for line in run.stdout:  # wait until the build is under way
            if line.startswith("tick ") and int(line.split()[1]) > 0:
                break
        restarted = as_("operator", "restart", "a2")
        assert restarted.returncode == 0 and "started a2" in restarted.stdout, restarted.stderr
        attempts = {"observer": ("restart", "a3"), "agent-a1": ("restart", "a3"), "agent-a2": ("kill", "a1"),
                    "teacher": ("kill", "a3")}  # the other identities: tests/test_secure_bus.py
        with ThreadPoolExecutor(len(attempts) + 1) as pool:
            refused = {u: pool.submit(as_, u, *a, "--timeout", "3") for u, a in attempts.items()}
            status = pool.submit(as_, "observer", "status", "--json", "--timeout", "30")  # the observer reads
        for user, r in refused.items():
            r = r.result()
            assert r.returncode == 1 and "no `conag run`" in r.stderr, (user, r.stdout, r.stderr)
        st = status.result()
        assert st.returncode == 0 and json.loads(st.stdout)["world_id"] == "w0", st.stderr
        # The run still answers the operator: the refusals above were not a run already gone.
        alive = as_("operator", "kill", "a9")
        assert alive.returncode == 1 and "no agent 'a9' in this run" in alive.stderr, alive.stderr
        run.send_signal(signal.SIGTERM)
        rest, _ = run.communicate(timeout=120)
        assert run.returncode == 130, rest
    finally:
        if run.poll() is None:
            run.kill()
            run.wait(10)
    s = json.loads(out.read_text())
    assert s["bricks_total"] == 2 and s["ticks"] > 0
    assert {a["id"]: a["restarts"] for a in s["agents"]} == {"a1": 0, "a2": 1, "a3": 0}


def test_run_secure_refuses_a_deployment_without_the_runs_agents(tmp_path):
    keys_dir = tmp_path / "keys"
    assert conag_main(["keys", str(keys_dir), "--agents", "1"]) == 0
    r = conag("run", "scenarios/fig6.toml", "--secure", keys_dir, "--listen", f"tcp/127.0.0.1:{free_port()}")
    assert r.returncode == 2 and "no credentials for agent(s) a2, a3" in r.stderr, r.stderr

"""The real `conag` command line, run as subprocesses on free loopback ports."""

from __future__ import annotations

import json
import signal

import pytest

from tests.conftest import SCENARIOS, Process, conag, free_port, wait_until
from world_server.scenario import load_scenario

pytestmark = pytest.mark.slow  # every test starts `conag` processes

QUICK_WALL = SCENARIOS / "quick_wall.toml"
PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def _status(ep: str) -> dict:
    r = conag("status", "--connect", ep, "--json", "--timeout", "10")
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


@pytest.fixture
def running_world():
    """A `conag world` process serving quick_wall on a free port until the test stops it."""
    started = []

    def start() -> tuple[Process, str]:
        ep = f"tcp/127.0.0.1:{free_port()}"
        proc = Process("world", str(QUICK_WALL), "--ticks", "100000000", "--listen", ep)
        started.append(proc)
        # The header is printed once the signal handlers are in; the status queryable follows.
        proc.wait_for("world w0: quick_wall")
        return proc, ep

    yield start
    for proc in started:
        proc.kill()


def test_world_runs_a_fixed_number_of_ticks_and_writes_a_summary(tmp_path):
    summary = tmp_path / "out.json"
    ep = f"tcp/127.0.0.1:{free_port()}"
    r = conag("world", QUICK_WALL, "--ticks", 50, "--tick-mode", "realtime", "--listen", ep, "--summary", summary)
    assert r.returncode == 0, r.stderr
    lines = r.stdout.splitlines()
    assert lines[0].startswith("world w0: quick_wall (12x8 cells, 3 sites, 4 bricks), realtime mode")
    assert any(line.startswith("tick ") and "sites 0/3" in line for line in lines[1:-1])
    assert lines[-1].startswith("final: tick      50  sites 0/3  bricks 4")
    data = json.loads(summary.read_text(encoding="utf-8"))
    assert (data["ticks"], data["sites_total"], data["bricks_total"]) == (50, 3, 4)
    assert set(data) == {"scenario", "seed", "completed", "stalled", "ticks", "sites_total", "sites_filled",
                         "bricks_total", "total_distance", "agents"}  # the run summary (world_server/summary.py)
    assert data["scenario"] == "quick_wall" and data["completed"] is False


def test_status_perturb_and_sigterm_on_a_running_world(running_world):
    world, ep = running_world()

    r = conag("status", "--connect", ep, "--timeout", "10")
    assert r.returncode == 0, r.stderr
    assert r.stdout.startswith("tick ") and "sites 0/3" in r.stdout and "bricks 4" in r.stdout

    data = _status(ep)
    assert data["scenario"] == "quick_wall" and data["sites_total"] == 3 and data["bricks_total"] == 4

    s = load_scenario(QUICK_WALL)
    x, y = s.to_world(s.cells_col_row("b"))[0]
    r = conag("perturb", "remove", "--at", f"{x},{y}", "--connect", ep)
    assert r.returncode == 0, r.stderr
    assert "removed brick" in r.stdout

    # The status queryable answers the latest publication (every status_period), so poll.
    wait_until(lambda: _status(ep)["bricks_total"] == 3, interval=0.2, what="the status to count 3 bricks")
    r = conag("status", "--connect", ep, "--timeout", "10")
    assert r.returncode == 0 and "bricks 3" in r.stdout

    r = conag("perturb", "remove", "--at", "0.5,0.5", "--connect", ep)  # an empty corner cell
    assert r.returncode == 1
    assert "no disc within" in r.stdout + r.stderr

    r = conag("perturb", "move", "--at", f"{x},{y}", "--connect", ep)
    assert r.returncode == 2
    assert "--to" in r.stderr

    assert world.stop(signal.SIGTERM) == 0, world.err
    assert world.out.splitlines()[-1].startswith("final: tick")
    assert "Traceback" not in world.err


def test_sigint_stops_a_world_cleanly(running_world):
    world, ep = running_world()
    assert _status(ep)["tick"] >= 0  # serving
    assert world.stop(signal.SIGINT) == 0, world.err
    assert world.out.splitlines()[-1].startswith("final: tick")
    assert "Traceback" not in world.err and "KeyboardInterrupt" not in world.err


def test_sigusr1_prints_where_each_thread_waits_and_the_world_goes_on(running_world):
    # What a test that times out on a stop asks for (conftest's Process.stop).
    world, ep = running_world()
    world.proc.send_signal(signal.SIGUSR1)
    # The main thread's stack ends where `python -m conag` started it.
    wait_until(lambda: "_run_module_as_main" in world.err, what="the main thread's stack on stderr")
    assert "thread 0x" in world.err.lower() and "(most recent call first)" in world.err, world.err
    assert _status(ep)["tick"] >= 0  # still serving
    assert world.stop(signal.SIGTERM) == 0, world.err


def test_status_without_a_world_fails_within_its_timeout():
    ep = f"tcp/127.0.0.1:{free_port()}"
    r = conag("status", "--connect", ep, "--timeout", "1", timeout=20)
    assert r.returncode == 1
    assert "error: no world 'w0' answered within 1 s" in r.stderr  # --timeout 1, not the default 5 s


def test_bad_scenario_names_file_line_and_column(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "bad"\nseed = 1\nagents = 1\nlayout = """\n....\n.A?.\n"""\n', encoding="utf-8")
    r = conag("world", bad, "--listen", f"tcp/127.0.0.1:{free_port()}")
    assert r.returncode == 2
    assert "bad.toml:6:3:" in r.stderr and "expected" in r.stderr
    assert "Traceback" not in r.stderr


def test_missing_scenario_is_a_usage_error(tmp_path):
    missing = tmp_path / "missing.toml"
    r = conag("world", missing, "--listen", f"tcp/127.0.0.1:{free_port()}")
    assert r.returncode == 2
    assert r.stderr.startswith("error:") and "missing.toml" in r.stderr and "No such file" in r.stderr
    assert "Traceback" not in r.stderr


def test_render_writes_a_png(tmp_path):
    out = tmp_path / "x.png"
    r = conag("render", SCENARIOS / "fig6.toml", "--out", out)
    assert r.returncode == 0, r.stderr
    assert out.read_bytes()[:8] == PNG_SIGNATURE
    assert str(out) in r.stdout


def test_world_logs_rejections_at_v_after_the_subcommand_and_perturb_add_needs_force_on_a_site():
    from protocol import keys
    from protocol.bus import BusOptions, open_session

    ep = f"tcp/127.0.0.1:{free_port()}"
    world = Process("world", str(QUICK_WALL), "--ticks", "100000000", "--listen", ep, "-v")
    try:
        world.wait_for("world w0: quick_wall")
        session = open_session(BusOptions(connect=(ep,)))
        try:
            def rejected() -> bool:
                # Put again each time: the first puts may go out before the session has met the world.
                session.put(keys.command("w0", "a9"), b"not a command")
                return "ignored bad message" in world.err and "a9" in world.err

            wait_until(rejected, interval=0.2, what="the rejection logged")
        finally:
            session.close()
        s = load_scenario(QUICK_WALL)
        x, y = s.to_world(s.cells_col_row("+"))[0]
        r = conag("perturb", "add", "--at", f"{x},{y}", "--connect", ep)
        assert r.returncode == 1 and "drop site" in r.stdout and "force" in r.stdout
        assert _status(ep)["bricks_total"] == 4
        r = conag("perturb", "add", "--at", f"{x},{y}", "--force", "--connect", ep)
        assert r.returncode == 0 and "added brick" in r.stdout, r.stdout + r.stderr
        wait_until(lambda: _status(ep)["sites_filled"] == 1, interval=0.2, what="the forced brick to fill the site")
    finally:
        world.kill()

"""`conag run`'s exit codes tell complete, incomplete, stalled, interrupted and error apart;
a second Ctrl-C is quiet; no temporary directory is left behind."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from conag.exit_codes import EXIT_ERROR, EXIT_INCOMPLETE, EXIT_INTERRUPTED, EXIT_STALLED
from tests.conftest import ROOT, free_port, wait_until

pytestmark = pytest.mark.slow

# One agent, a site it cannot fill (its only brick is walled in): never complete.
WALLED = '''
name = "walled"
seed = 1
agents = 1
max_ticks = 100000
layout = """
........
.A...+..
........
#####...
#b..#...
#####...
"""
'''


def _start(tmp_path: Path, scenario: str, *args: str) -> subprocess.Popen:
    """`conag run` in a process group of its own (as a shell's foreground job is), with its
    own TMPDIR, so a test can send Ctrl-C to the whole group and look for leftovers."""
    (tmp_path / "tmp").mkdir(exist_ok=True)
    env = dict(os.environ, TMPDIR=str(tmp_path / "tmp"))
    return subprocess.Popen([sys.executable, "-m", "conag", "run", scenario, "--headless",
                             "--listen", f"tcp/127.0.0.1:{free_port()}", *args], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)


def _finish(proc: subprocess.Popen, timeout: float = 120) -> tuple[int, str, str]:
    try:
        out, err = proc.communicate(timeout=timeout)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(10)
    return proc.returncode, out, err


def _no_leftovers(tmp_path: Path) -> None:
    assert list((tmp_path / "tmp").iterdir()) == []


def _walled(tmp_path: Path) -> str:
    path = tmp_path / "walled.toml"
    path.write_text(WALLED)
    return str(path)


def _wait_for_ticks(proc: subprocess.Popen) -> None:
    for line in proc.stdout:  # progress lines: wait until the build is under way
        if line.startswith("tick ") and int(line.split()[1]) > 0:
            return
    raise AssertionError("conag run ended before ticking")


def test_incomplete_when_the_tick_limit_passes(tmp_path):
    rc, out, err = _finish(_start(tmp_path, _walled(tmp_path), "--max-ticks", "50"))
    assert rc == EXIT_INCOMPLETE, out + err
    assert "NOT complete" in out
    _no_leftovers(tmp_path)


def test_stalled_when_no_site_is_filled_for_stall_ticks(tmp_path):
    rc, out, err = _finish(_start(tmp_path, _walled(tmp_path), "--stall-ticks", "100"))
    assert rc == EXIT_STALLED, out + err
    assert "STALLED at tick" in out
    _no_leftovers(tmp_path)


def test_ctrl_c_twice_is_interrupted_quietly_and_leaves_nothing_behind(tmp_path):
    proc = _start(tmp_path, _walled(tmp_path), "--stall-ticks", "0")
    _wait_for_ticks(proc)
    os.killpg(proc.pid, signal.SIGINT)   # Ctrl-C reaches every process of the foreground group
    os.killpg(proc.pid, signal.SIGINT)   # ... and again, impatiently
    rc, out, err = _finish(proc)
    assert rc == EXIT_INTERRUPTED, out + err
    assert "INTERRUPTED" in out
    assert "Traceback" not in err and "_Stopped" not in err, err
    _no_leftovers(tmp_path)


def _children(pid: int) -> dict[int, str]:
    """Child processes of `pid` and their command lines (Linux /proc)."""
    found = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
            if int(fields[1]) == pid:
                cmdline = (stat.parent / "cmdline").read_bytes().replace(b"\0", b" ").decode()
                found[int(stat.parent.name)] = cmdline
        except (OSError, IndexError, ValueError):
            continue
    return found


def _world_pid(proc: subprocess.Popen, not_this: int | None = None) -> int | None:
    """The run's world process (other than `not_this`); None once the run has exited."""
    def world():
        if proc.poll() is not None:
            return -1
        return next((p for p, c in _children(proc.pid).items() if " world " in c and p != not_this), None)

    pid = wait_until(world, timeout=60, what="the world process")
    return None if pid == -1 else pid


def test_a_world_that_dies_is_restarted_from_its_checkpoint(tmp_path):
    proc = _start(tmp_path, _walled(tmp_path), "--stall-ticks", "0", "--checkpoint-every", "20")
    _wait_for_ticks(proc)
    first = _world_pid(proc)
    for line in proc.stdout:  # past the first checkpoint
        if line.startswith("tick ") and int(line.split()[1]) > 40:
            break
    os.kill(first, signal.SIGKILL)
    assert _world_pid(proc, not_this=first) is not None
    said = next((line for line in proc.stdout if "the world died" in line), "")
    assert said.startswith("the world died (exit -9); restarted it from its checkpoint of tick "), said
    for line in proc.stdout:  # the run goes on: ticks again, and says how often its world was restarted
        if line.startswith("tick ") and "world restarts 1" in line:
            break
    os.killpg(proc.pid, signal.SIGINT)
    rc, out, err = _finish(proc)
    assert rc == EXIT_INTERRUPTED, out + err
    assert "Traceback" not in err, err
    _no_leftovers(tmp_path)  # the checkpoints went with the run's temporary directory


def test_an_error_when_the_world_keeps_dying(tmp_path):
    proc = _start(tmp_path, _walled(tmp_path), "--stall-ticks", "0")
    _wait_for_ticks(proc)
    killed = None
    for _ in range(6):  # killed as soon as it is there, again and again
        world = _world_pid(proc, not_this=killed)
        if world is None:
            break  # the run gave up
        os.kill(world, signal.SIGKILL)
        killed = world
    rc, out, err = _finish(proc)
    assert rc == EXIT_ERROR, out + err
    assert "times in a row within 10 s of starting; not starting it again" in err
    assert "Traceback" not in err, err
    _no_leftovers(tmp_path)


def test_the_exit_codes_are_in_the_help():
    r = subprocess.run([sys.executable, "-m", "conag", "run", "--help"], cwd=ROOT, capture_output=True, text=True)
    text = " ".join(r.stdout.split())
    for code, what in ((0, "complete"), (EXIT_ERROR, "an error"), (EXIT_INCOMPLETE, "not complete"),
                       (EXIT_STALLED, "stalled"), (EXIT_INTERRUPTED, "interrupted")):
        assert f"{code} {what}" in text or f"{code} the structure is {what}" in text, (code, text)

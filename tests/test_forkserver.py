"""The fork server starts agent processes as forks of one preloaded interpreter: what the
supervisor relies on of a process it started (its pid, exit code, kill, wait) holds for a
forked one, and nothing outlives the server."""

from __future__ import annotations

import os
import signal
import subprocess
import time

import pytest

from conag.forkserver import ForkServer, ForkServerError


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with open(f"/proc/{pid}/stat") as f:     # a zombie is not alive
        return f.read().split(")")[-1].split()[0] != "Z"


@pytest.fixture(scope="module")
def server():
    with ForkServer(warm=False) as fs:
        yield fs


def test_a_forked_command_reports_its_exit_code(server):
    child = server.spawn(["status", "--run", "no-such-run"])   # a usage error: exit 2
    assert child.wait(20) == 2 and child.poll() == 2
    assert server.spawn(["generate", "--help"]).wait(20) == 0


@pytest.mark.slow
def test_a_forked_process_prints_where_the_supervisor_prints(tmp_path):
    # `conag run`'s agents print their last line ("agent a1: ... ticks") to the run's stdout.
    script = ("from conag.forkserver import ForkServer\n"
              "with ForkServer(warm=False) as fs:\n"
              "    print('child exit', fs.spawn(['generate', '--help']).wait(20), flush=True)\n")
    out = subprocess.run([os.sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "usage: conag generate" in out.stdout and "child exit 0" in out.stdout


def test_a_forked_agent_is_killed_and_waited_for_like_a_spawned_one(server):
    # An agent that waits to attach to a world that is not there: it runs until killed.
    child = server.spawn(["agent", "--id", "a1", "--world-id", "nowhere", "--connect", "tcp/127.0.0.1:9",
                          "--attach-timeout", "60"])
    assert child.poll() is None
    with pytest.raises(subprocess.TimeoutExpired):
        child.wait(0.5)
    assert _alive(child.pid)
    child.kill()
    assert child.wait(20) == -signal.SIGKILL
    child.kill()                                       # again, after it ended: nothing happens


def test_sigterm_stops_a_forked_agent_cleanly(server):
    child = server.spawn(["agent", "--id", "a1", "--world-id", "nowhere", "--connect", "tcp/127.0.0.1:9",
                          "--attach-timeout", "60"])
    time.sleep(1.0)                                    # past start-up: its signal handlers are installed
    child.send_signal(signal.SIGTERM)
    assert child.wait(20) in (0, 1, 130, 143, -signal.SIGTERM)


@pytest.mark.slow
def test_closing_the_server_ends_its_children():
    fs = ForkServer(warm=False)
    child = fs.spawn(["agent", "--id", "a1", "--world-id", "nowhere", "--connect", "tcp/127.0.0.1:9",
                      "--attach-timeout", "60"])
    fs.close()
    assert child.wait(20) is not None
    assert not _alive(child.pid)
    with pytest.raises(ForkServerError):
        fs.spawn(["status"])


def test_a_stop_signal_inside_a_library_call_is_a_stop_not_a_crash():
    # Ctrl-C landing while numba loads a kernel reaches the child as a SystemError whose
    # cause is the stop: the child exits as interrupted (130) without a traceback.
    from conag.common import _Stopped
    from conag.forkserver import _interrupted
    wrapped = SystemError("returned a result with an exception set")
    wrapped.__cause__ = _Stopped()
    assert _interrupted(wrapped)
    assert not _interrupted(SystemError("a real crash")) and not _interrupted(None)


@pytest.mark.parametrize("ending, words", [
    ("kill -KILL $$", "the fork server was killed (SIGKILL) before it was ready"),
    ("echo 'conag fork server: cannot load' >&2; exit 3",
     "the fork server exited (code 3) before it was ready (its error is above)"),
])
def test_a_fork_server_that_never_starts_says_how_it_ended(tmp_path, monkeypatch, ending, words):
    # "its error is above" only where the server printed one: a SIGKILL prints nothing
    fake = tmp_path / "python3"
    fake.write_text(f"#!/bin/sh\n{ending}\n")
    fake.chmod(0o755)
    monkeypatch.setattr("sys.executable", str(fake))
    with pytest.raises(ForkServerError) as exc:
        ForkServer(warm=False, start_timeout=30)
    assert str(exc.value) == words


def test_a_fork_server_that_hangs_is_given_up_after_its_timeout(tmp_path, monkeypatch):
    fake = tmp_path / "python3"
    fake.write_text("#!/bin/sh\nexec cat >/dev/null\n")   # silent until its input ends
    fake.chmod(0o755)
    monkeypatch.setattr("sys.executable", str(fake))
    with pytest.raises(ForkServerError, match=r"did not say it was ready within 0\.5 s"):
        ForkServer(warm=False, start_timeout=0.5)

"""Shared fixtures and helpers: real zenoh sessions in-process on loopback, a world server
thread, `wait_until` (poll a predicate with a deadline, never a bare sleep), `conag`
subprocesses, and small worlds built from inline layouts."""

from __future__ import annotations

import atexit
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import TypeVar

import numpy as np
import pytest
from hypothesis import settings

from protocol.bus import BusOptions, open_session
from tests import kernel_compile_lock, kernel_warmup
from world_server.scenario import load_scenario, parse_scenario
from world_server.server import WorldServer
from world_server.world import World

ROOT = Path(__file__).resolve().parent.parent
SCENARIOS = ROOT / "scenarios"

# Property tests draw the same examples on every run, everywhere (CI, a fresh clone, a
# laptop): a failure is one anybody can reproduce with the same command, never a draw that
# comes and goes, and no example database left in .hypothesis/ replays a failure after it
# was fixed (or keeps one from a branch). The failing example's blob is printed.
# HYPOTHESIS_PROFILE=explore draws new examples each run (and keeps the database), to look
# for bugs on purpose.
settings.register_profile("derandomized", derandomize=True, database=None, print_blob=True)
settings.register_profile("explore", print_blob=True)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "derandomized"))

# Each numba kernel compiles once across the xdist workers, not once in each: a worker that
# wants a kernel another is compiling waits for it and loads it from the cache.
kernel_compile_lock.install(kernel_compile_lock.lock_dir_for(ROOT))


def pytest_configure(config):
    """With xdist workers, compile the kernels on both cores while the workers start
    (tests/kernel_warmup.py); the controller itself runs no test."""
    if hasattr(config, "workerinput") or not getattr(config.option, "numprocesses", None):
        return
    config.kernel_warmups = [
        subprocess.Popen([sys.executable, "-m", "tests.kernel_warmup", part], cwd=ROOT,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        for part in kernel_warmup.PARTS]


def pytest_unconfigure(config):
    for warmup in getattr(config, "kernel_warmups", ()):
        warmup.kill()
        warmup.wait()

# `conag run` registers by name (conag/runs.py) and the verbs find runs there: the tests,
# and every process they start, keep a runs directory of their own, so they never see
# (nor are seen by) the runs of whoever else uses this machine.
_RUNS_DIR = tempfile.mkdtemp(prefix="conag-test-runs-")
os.environ["CONAG_RUNS_DIR"] = _RUNS_DIR
atexit.register(shutil.rmtree, _RUNS_DIR, True)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def endpoint() -> str:
    return f"tcp/127.0.0.1:{free_port()}"


class Bus:
    """Opens peer sessions (multicast off, explicit loopback endpoints) and closes them all."""

    def __init__(self, endpoint: str):
        self.endpoint = endpoint
        self.sessions = []

    def server_session(self):
        s = open_session(BusOptions(listen=(self.endpoint,)), serve=True)
        self.sessions.append(s)
        return s

    def client_session(self):
        s = open_session(BusOptions(connect=(self.endpoint,)))
        self.sessions.append(s)
        return s

    def close(self):
        for s in reversed(self.sessions):
            try:
                s.close()
            except Exception:  # noqa: BLE001 -- teardown: one session failing to close must not stop the rest
                pass


@pytest.fixture
def bus(endpoint):
    b = Bus(endpoint)
    yield b
    b.close()


class RunningWorld:
    """A WorldServer serving in a thread of this process until stopped."""

    def __init__(self, world: World, session, **kwargs):
        self.world = world
        self.stop = threading.Event()
        self.server = WorldServer(world, session, **kwargs)
        self.result = None
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self):
        self.result = self.server.run(self.stop)

    def close(self, timeout: float = 10.0):
        self.stop.set()
        self.thread.join(timeout)
        assert not self.thread.is_alive(), "world server did not stop"
        return self.result


@pytest.fixture
def start_world(bus):
    running = []

    def start(scenario, *, seed=None, world_id="w0", **kwargs) -> RunningWorld:
        if isinstance(scenario, (str, Path)) and Path(scenario).suffix == ".toml":
            scenario = load_scenario(scenario)
        elif isinstance(scenario, str):
            scenario = parse_scenario(scenario)
        rng = np.random.default_rng(scenario.seed if seed is None else seed)
        rw = RunningWorld(World(scenario, rng, world_id=world_id), bus.server_session(), **kwargs)
        running.append(rw)
        return rw

    yield start
    for rw in running:
        if rw.thread.is_alive():
            rw.close()


# --- waiting --------------------------------------------------------------------------------

T = TypeVar("T")


def wait_until(predicate: Callable[[], T], timeout: float = 60.0, interval: float = 0.02,
               what: str = "the condition") -> T:
    """Call `predicate` every `interval` seconds until it returns something truthy, and return
    that; raise AssertionError naming `what` once `timeout` seconds have passed without.

    Tests wait on what they need to see (a count reached, a process gone, a tick passed),
    never on a fixed sleep: a busy machine makes them slower, not wrong. The default is long
    because a passing wait returns at once and only a failing one pays it: in a fresh clone an
    agent's first steps compile the numba kernels, every xdist worker at once, and a 10 s
    default failed there (an agent not yet stepping after 10 s, with four workers on two cores).
    """
    deadline = time.monotonic() + timeout
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() >= deadline:
            raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")
        time.sleep(interval)


# --- `conag` as a subprocess ----------------------------------------------------------------

def conag(*args, timeout: float = 60.0) -> subprocess.CompletedProcess:
    """Run `python -m conag ARGS...` to the end; stdout and stderr captured as text."""
    return subprocess.run([sys.executable, "-m", "conag", *map(str, args)], cwd=ROOT, capture_output=True,
                          text=True, timeout=timeout)


def run_acting_mid_build(scenario: Path, summary: Path, act: Callable[[str, subprocess.Popen], T], *run_args,
                         timeout: float = 240.0) -> T:
    """`conag run` a scenario on an endpoint of its own; once it ticks, `act(endpoint, run)`;
    wait for the run to end (it must exit 0, its summary written to `summary`). Returns what
    `act` returned."""
    ep = f"tcp/127.0.0.1:{free_port()}"
    run = subprocess.Popen([sys.executable, "-m", "conag", "run", str(scenario), *map(str, run_args), "--headless",
                            "--summary", str(summary), "--listen", ep], cwd=ROOT, stdout=subprocess.PIPE,
                           stderr=subprocess.STDOUT, text=True)
    try:
        assert run.stdout is not None
        for line in run.stdout:  # wait until the build is under way
            if line.startswith("tick ") and int(line.split()[1]) > 0:
                break
        result = act(ep, run)
        rest, _ = run.communicate(timeout=timeout)
        assert run.returncode == 0, rest
    finally:
        if run.poll() is None:
            run.kill()
            run.wait(10)
    return result


def run_and_restart_mid_build(tmp_path: Path, scenario_text: str, *run_args, agent: str = "a2",
                              timeout: float = 240.0) -> tuple[dict, subprocess.CompletedProcess]:
    """`conag run` a scenario; once it ticks, `conag restart` one agent (SIGKILL, then a new
    process with the same id); wait for the run to end (it must exit 0). Returns the run
    summary and the restart command's outcome."""
    import json

    out, scenario = tmp_path / "summary.json", tmp_path / "scenario.toml"
    scenario.write_text(scenario_text)
    restarted = run_acting_mid_build(scenario, out, lambda ep, _run: conag("restart", agent, "--connect", ep),
                                     *run_args, timeout=timeout)
    return json.loads(out.read_text()), restarted


class Process:
    """A `conag` subprocess whose stdout and stderr are read by threads, so that a test can
    wait for a line (the router prints its "listening" line once its signal handlers are in)."""

    def __init__(self, *args: str):
        self.proc = subprocess.Popen([sys.executable, "-m", "conag", *args], cwd=ROOT, text=True,
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE)
        self._lines = {"out": [], "err": []}
        self._cond = threading.Condition()
        self._readers = [threading.Thread(target=self._read, args=(s, k), daemon=True)
                         for s, k in ((self.proc.stdout, "out"), (self.proc.stderr, "err"))]
        for t in self._readers:
            t.start()

    def _read(self, stream, kind: str) -> None:
        for line in stream:
            with self._cond:
                self._lines[kind].append(line)
                self._cond.notify_all()

    @property
    def out(self) -> str:
        with self._cond:
            return "".join(self._lines["out"])

    @property
    def err(self) -> str:
        with self._cond:
            return "".join(self._lines["err"])

    def wait_for(self, text: str, timeout: float = 15.0) -> None:
        deadline = time.monotonic() + timeout
        with self._cond:
            while not any(text in line for line in self._lines["out"]):
                remaining = deadline - time.monotonic()
                finished = self.proc.poll() is not None and not any(t.is_alive() for t in self._readers)
                if remaining <= 0 or finished:
                    raise AssertionError(f"no {text!r} from conag within {timeout} s (exit "
                                         f"{self.proc.poll()}): {''.join(self._lines['err'])}")
                self._cond.wait(min(remaining, 0.2))

    def stop(self, sig=signal.SIGTERM, timeout: float = 5.0) -> int:
        """Send `sig` and wait for the exit; returns the exit code. A process still there
        after `timeout` is asked for its threads' stacks (SIGUSR1) and killed, and the
        test fails with its stderr: where it waited."""
        self.proc.send_signal(sig)
        try:
            rc = self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.send_signal(signal.SIGUSR1)
            time.sleep(1.0)
            self.kill()
            raise AssertionError(f"conag did not exit within {timeout} s of signal {sig!r}; its stderr, "
                                 f"with every thread's stack at the end:\n{self.err}") from None
        for t in self._readers:
            t.join(5)
        return rc

    def kill(self) -> None:
        if self.proc.poll() is None:
            self.proc.kill()
        self.proc.wait(10)
        for t in self._readers:
            t.join(5)


# --- small worlds -----------------------------------------------------------------------------

def scenario(layout: str, agents: int = 1, seed: int = 1, **world):
    """A scenario from an inline layout, with [world] settings as keyword arguments."""
    lines = [f"{k} = {str(v).lower() if isinstance(v, bool) else repr(v)}" for k, v in world.items()]
    text = (f'name = "t"\nseed = {seed}\nagents = {agents}\nlayout = """\n{layout.strip()}\n"""\n'
            "[world]\n" + "\n".join(lines) + "\n")
    return parse_scenario(text)


def make(layout: str, seed: int = 0, agents: int = 1, **world) -> World:
    """A World on an inline layout; `seed` seeds its noise."""
    return World(scenario(layout, agents, **world), np.random.default_rng(seed))


# Thirty sites, bricks spread out: a learning student meets every state of the construction
# sequence many times (tests/test_teacher.py). Tests that act mid-build run it `paced`.
LONG_WALL = '''
name = "long_walls"
seed = 11
agents = 3
max_ticks = 40000
layout = """
b.b.b.b.b.b.b.b.b.b.
.b.b.b.b.b.b.b.b.b.b
....................
.....++++++++++.....
....................
.....++++++++++.....
....................
..b....A.A.A....b...
....................
.....++++++++++.....
....................
....................
b.b.b.b.b.b.b.b.b.b.
"""
'''


def paced(scenario_text: str, tick_rate: float) -> str:
    """`scenario_text` in realtime at `tick_rate` ticks a second: its build lasts a wall time
    we know, so a test that acts "mid-build" acts before the end however fast this machine
    steps. (A lockstep run gets the same from `conag run --max-tick-rate`, and keeps its
    lockstep dynamics: the restart tests use that.)"""
    return 'tick_mode = "realtime"\n' + scenario_text + f"\n[world]\ntick_rate = {tick_rate}\n"

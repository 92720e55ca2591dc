"""`conag chaos SCENARIO`: builds under fire. Each run is a `conag run` of the scenario while
a random agent process is SIGKILLed every few seconds (`conag kill` / `conag restart`, the
RunControl query): some are started again at once, the others left dead, never fewer than
`min_alive` alive. Kills start once the world ticks: an agent killed before it ever
attached would leave a lockstep world waiting for `--wait-agents` agents for good. Each
run reports whether it completed, its exit code, ticks, sites and `bricks_total` (which
must equal the scenario's: a kill neither loses nor makes a brick).

The kill schedule comes from one seeded generator per run (`seed`, run index): the same
seed picks the same agents at the same wall-clock offsets, though what they were doing at
that moment is up to the machine's timing.
"""

from __future__ import annotations

import json
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from bus import BusOptions, open_session
from conag.run import control
from protocol import keys
from protocol.codec import ProtocolError, decode
from protocol.messages import WorldStatus
from world_server.scenario import load_scenario
from world_server.world import World


@dataclass(frozen=True)
class ChaosOptions:
    """What `conag chaos` runs and how hard it kills."""

    scenario_path: str
    runs: int = 1
    kill_every: float = 3.0        # mean wall seconds between kills (each wait uniform in [0.5, 1.5] x this)
    restart_share: float = 0.5     # chance that a killed agent is started again at once
    min_alive: int = 1             # never leave fewer agents alive than this
    seed: int = 0                  # the kill schedule's seed (not the world's)
    agents: int | None = None      # default: the scenario's
    max_ticks: int | None = None   # default: the scenario's
    stall_ticks: int = 3000
    run_timeout: float = 600.0     # wall seconds before a run is stopped (SIGTERM)
    world_seed: int | None = None  # --seed of `conag run` (default: the scenario's)

    def __post_init__(self) -> None:
        if self.runs < 1:
            raise ValueError("--runs must be >= 1")
        if not self.kill_every > 0:
            raise ValueError("--kill-every must be > 0 seconds")
        if not 0 <= self.restart_share <= 1:
            raise ValueError("--restart-share must be in [0, 1]")
        if self.min_alive < 1:
            raise ValueError("--min-alive must be >= 1")


@dataclass
class ChaosRun:
    """One run's outcome."""

    run: int
    exit_code: int = -1
    completed: bool = False
    stalled: bool = False
    ticks: int = 0
    sites_filled: int = 0
    sites_total: int = 0
    bricks_total: int = -1
    bricks_expected: int = -1
    kills: int = 0
    restarts: int = 0
    left_dead: list[str] = field(default_factory=list)
    wall_seconds: float = 0.0

    @property
    def bricks_kept(self) -> bool:
        return self.bricks_total == self.bricks_expected

    def line(self) -> str:
        state = "complete" if self.completed else "STALLED" if self.stalled else f"NOT complete (exit {self.exit_code})"
        return (f"run {self.run}: {state}: {self.sites_filled}/{self.sites_total} sites in {self.ticks} ticks, "
                f"{self.kills} kills ({self.restarts} restarted, left dead: {', '.join(self.left_dead) or 'none'}), "
                f"bricks_total {self.bricks_total} (expected {self.bricks_expected}), {self.wall_seconds:.0f} s")


def _free_endpoint() -> str:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{s.getsockname()[1]}"


def chaos_run(opts: ChaosOptions, index: int, stop: threading.Event, log=print) -> ChaosRun:
    """One `conag run` under kills; `stop` ends it early (the run is stopped with SIGTERM)."""
    scenario = load_scenario(opts.scenario_path)
    n_agents = scenario.agents if opts.agents is None else opts.agents
    result = ChaosRun(index, bricks_expected=World(scenario).discs.bricks_total())
    rng = np.random.default_rng([opts.seed, index])
    endpoint = _free_endpoint()
    alive = [f"a{i + 1}" for i in range(n_agents)]
    started = time.monotonic()
    with tempfile.TemporaryDirectory(prefix="conag-chaos-") as tmp:
        summary_path = Path(tmp) / "summary.json"
        cmd = [sys.executable, "-m", "conag", "run", opts.scenario_path, "--headless", "--quiet",
               "--listen", endpoint, "--summary", str(summary_path), "--agents", str(n_agents),
               "--stall-ticks", str(opts.stall_ticks)]
        if opts.max_ticks is not None:
            cmd += ["--max-ticks", str(opts.max_ticks)]
        if opts.world_seed is not None:
            cmd += ["--seed", str(opts.world_seed)]
        proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL)
        session = open_session(BusOptions(connect=(endpoint,)))
        ticking = threading.Event()

        def on_status(sample) -> None:
            try:
                if decode(sample.payload.to_bytes(), WorldStatus).tick > 0:
                    ticking.set()
            except ProtocolError:
                pass

        status_sub = session.declare_subscriber(keys.status("w0"), on_status)
        try:
            while proc.poll() is None and not ticking.wait(0.1) and not stop.is_set():
                if time.monotonic() - started > opts.run_timeout:
                    break
            while proc.poll() is None:
                wait = float(opts.kill_every * rng.uniform(0.5, 1.5))
                if stop.wait(0) or time.monotonic() - started > opts.run_timeout:
                    proc.send_signal(signal.SIGTERM)
                    break
                try:
                    proc.wait(wait)
                    break
                except subprocess.TimeoutExpired:
                    pass
                victim = alive[int(rng.integers(len(alive)))]
                restart = len(alive) <= opts.min_alive or bool(rng.random() < opts.restart_share)
                answer = control(session, "w0", "restart" if restart else "kill", victim, timeout=5.0)
                if not answer.ok:
                    continue  # the run is ending, or not up yet
                result.kills += 1
                if restart:
                    result.restarts += 1
                else:
                    alive.remove(victim)
                    result.left_dead.append(victim)
                log(f"  run {index}: {'restarted' if restart else 'killed'} {victim}")
            result.exit_code = proc.wait(opts.run_timeout)
        finally:
            status_sub.undeclare()
            session.close()
            if proc.poll() is None:
                proc.kill()
                proc.wait(10)
        if summary_path.exists():
            s = json.loads(summary_path.read_text(encoding="utf-8"))
            result.completed, result.stalled, result.ticks = s["completed"], s["stalled"], s["ticks"]
            result.sites_filled, result.sites_total, result.bricks_total = (s["sites_filled"], s["sites_total"],
                                                                            s["bricks_total"])
    result.wall_seconds = time.monotonic() - started
    return result


def chaos(opts: ChaosOptions, stop: threading.Event, log=print) -> list[ChaosRun]:
    """`opts.runs` chaos runs, one after the other; a line per kill and per run to `log`."""
    results = []
    for i in range(opts.runs):
        if stop.is_set():
            break
        r = chaos_run(opts, i, stop, log)
        log(r.line())
        results.append(r)
    return results


def report(opts: ChaosOptions, results: list[ChaosRun]) -> dict:
    """The whole experiment as JSON: the options, each run, and the totals."""
    return {"options": asdict(opts), "runs": [asdict(r) | {"bricks_kept": r.bricks_kept} for r in results],
            "completed": sum(r.completed for r in results), "bricks_kept": sum(r.bricks_kept for r in results),
            "total": len(results)}

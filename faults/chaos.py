"""`python3 -m faults.chaos SCENARIO`: builds under fire. Each run is a `conag run` of the scenario while
a random agent process is SIGKILLed every few seconds (`conag kill` / `conag restart`, the
RunControl query): some are started again at once, the others left dead, never fewer than
`min_alive` alive. Kills start once the world ticks: an agent killed before it ever
attached would leave a lockstep world waiting for `--wait-agents` agents for good. And an
agent is killed only once the world has ticked `min_life` ticks since it was started (or
started again): kills come at wall-clock times, and on a slow machine a process can be
killed again before it has done anything, so the run would measure how fast the machine
starts Python, not whether the build survives (a lone agent killed every 30-80 of its ticks
never closes nested_squares' outer ring: each new process must see inside it again). Each
run reports whether it completed, its exit code, ticks, sites and `bricks_total` (which
must equal the scenario's: a kill neither loses nor makes a brick).

With `kill_world_every` the world process itself is SIGKILLed too, every few seconds on
average, counted from when the restarted world's frames come again, and not before the
world has ticked one checkpoint interval past where it started (`conag run` restarts it
from its last checkpoint, and the agents attach again; a world that dies before it gets a
checkpoint further, three times in a row, is taken for one that cannot start), nor before
`world_min_life` ticks past it: as `min_life` does for agents, it makes the number of kills
a build sees depend on its ticks more than on the machine's speed (a wall-clock schedule
alone kills a fast machine's short build once and a slow machine's over and over).
For each world kill the run records the ticks lost: the newest tick any agent's frame
showed before the kill, less the tick the restarted world's first frame shows (at most the
checkpoint interval). `kill_every` 0 kills no agents (only the world).

The kill schedule comes from one seeded generator per run (`seed`, run index): the same
seed picks the same agents at the same wall-clock offsets, though what they were doing at
that moment is up to the machine's timing.
"""

from __future__ import annotations

import argparse
import json
import os
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

from conag.argtypes import non_negative, positive
from conag.common import stop_on_signals
from conag.exit_codes import EXIT_ERROR, EXIT_INCOMPLETE, EXIT_INTERRUPTED
from conag.run import control
from protocol import keys
from protocol.bus import BusOptions, open_session
from protocol.codec import ProtocolError, decode
from protocol.messages import SensorFrame, WorldStatus
from world_server.checkpoint import DEFAULT_EVERY
from world_server.scenario import load_scenario
from world_server.world import World


@dataclass(frozen=True)
class ChaosOptions:
    """What `python3 -m faults.chaos` runs and how hard it kills."""

    scenario_path: str
    runs: int = 1
    kill_every: float = 3.0        # mean wall seconds between kills (each wait uniform in [0.5, 1.5] x this)
    min_life: int = 200            # world ticks an agent lives, from its (re)start, before it may be killed
    restart_share: float = 0.5     # chance that a killed agent is started again at once
    min_alive: int = 1             # never leave fewer agents alive than this
    seed: int = 0                  # the kill schedule's seed (not the world's)
    agents: int | None = None      # default: the scenario's
    max_ticks: int | None = None   # default: the scenario's
    stall_ticks: int = 3000
    run_timeout: float = 600.0     # wall seconds before a run is stopped (SIGTERM)
    world_seed: int | None = None  # --seed of `conag run` (default: the scenario's)
    kill_world_every: float = 0.0  # mean wall seconds between SIGKILLs of the world (0: never)
    world_min_life: int = 0        # world ticks past where it (re)started before it may be killed
    checkpoint_every: int | None = None  # `conag run --checkpoint-every` (default: its own)
    without: str = ""              # `conag run --without`: additions switched off, comma separated

    def __post_init__(self) -> None:
        if self.runs < 1:
            raise ValueError("--runs must be >= 1")
        if not self.kill_every >= 0:
            raise ValueError("--kill-every must be >= 0 seconds (0: no agent is killed)")
        if not self.kill_world_every >= 0:
            raise ValueError("--kill-world-every must be >= 0 seconds (0: the world is not killed)")
        if self.kill_every == 0 and self.kill_world_every == 0:
            raise ValueError("nothing to kill: --kill-every and --kill-world-every are both 0")
        if self.min_life < 0:
            raise ValueError("--min-life must be >= 0 ticks")
        if self.world_min_life < 0:
            raise ValueError("--world-min-life must be >= 0 ticks")
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
    lives: list[int] = field(default_factory=list)  # per agent kill: world ticks the victim had lived
    world_kills: int = 0
    world_restarts: int = 0        # as `conag run` reports them in its summary
    ticks_lost: list[int] = field(default_factory=list)  # per world kill (see the module)
    wall_seconds: float = 0.0
    why: list[str] = field(default_factory=list)  # what `conag run` printed after its progress, if it did not complete

    @property
    def bricks_kept(self) -> bool:
        return self.bricks_total == self.bricks_expected

    def line(self) -> str:
        state = "complete" if self.completed else "STALLED" if self.stalled else f"NOT complete (exit {self.exit_code})"
        return (f"run {self.run}: {state}: {self.sites_filled}/{self.sites_total} sites in {self.ticks} ticks, "
                f"{self.kills} kills ({self.restarts} restarted, left dead: {', '.join(self.left_dead) or 'none'}"
                + (f"; shortest life {min(self.lives)} ticks" if self.lives else "") + "), "
                f"bricks_total {self.bricks_total} (expected {self.bricks_expected}), {self.wall_seconds:.0f} s"
                + (f", {self.world_kills} world kills ({self.world_restarts} restarts, ticks lost "
                   f"{', '.join(map(str, self.ticks_lost)) or '-'})" if self.world_kills else "")
                + "".join(f"\n    {line}" for line in self.why))


def _free_endpoint() -> str:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{s.getsockname()[1]}"


class FrameWatch:
    """The newest tick the agents' frames show, and per world kill the ticks lost: the newest
    tick before the kill less the first tick of the restarted world (its frames have another
    epoch, or a lower tick)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.newest, self.epoch = -1, None
        self.started_at = 0  # the first tick of the world now running (0, or where it resumed)
        self.lost: list[int] = []
        self._killed: tuple[int, int | None] | None = None  # (newest tick, epoch) at a kill not yet recovered

    def on_frame(self, sample) -> None:
        try:
            f = decode(sample.payload.to_bytes(), SensorFrame)
        except ProtocolError:
            return
        with self._lock:
            if self._killed is not None:
                before, epoch = self._killed
                if f.epoch == epoch and f.tick >= before:
                    return  # a frame of the world that was killed, late
                self.lost.append(before - f.tick)
                self._killed = None
                self.newest, self.epoch, self.started_at = f.tick, f.epoch, f.tick
            elif f.tick > self.newest or f.epoch != self.epoch:
                self.newest, self.epoch = f.tick, f.epoch

    def killed(self) -> None:
        with self._lock:
            if self._killed is None:
                self._killed = (self.newest, self.epoch)

    @property
    def recovering(self) -> bool:
        """A world was killed and no frame of its successor has come yet."""
        with self._lock:
            return self._killed is not None


def world_pid(run_pid: int) -> int | None:
    """The `conag world` child of the `conag run` process `run_pid` (Linux /proc), if any."""
    children: list[int] = []
    for task in Path(f"/proc/{run_pid}/task").glob("*"):
        try:
            children += [int(c) for c in (task / "children").read_text().split()]
        except OSError:
            continue
    for pid in children:
        try:
            argv = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
        except OSError:
            continue
        if b"conag" in argv and argv[argv.index(b"conag") + 1:argv.index(b"conag") + 2] == [b"world"]:
            return pid
    return None


def _draw(rng: np.random.Generator, mean: float) -> float:
    """Seconds to the next kill: uniform in [0.5, 1.5] x mean; never for a mean of 0."""
    return float(mean * rng.uniform(0.5, 1.5)) if mean > 0 else float("inf")


def chaos_run(opts: ChaosOptions, index: int, stop: threading.Event, log=print) -> ChaosRun:
    """One `conag run` under kills; `stop` ends it early (the run is stopped with SIGTERM)."""
    scenario = load_scenario(opts.scenario_path)
    n_agents = scenario.agents if opts.agents is None else opts.agents
    result = ChaosRun(index, bricks_expected=World(scenario).discs.bricks_total())
    rng = np.random.default_rng([opts.seed, index])
    world_rng = np.random.default_rng([opts.seed, index, 1])  # its own: the agents' schedule stays as it was
    endpoint = _free_endpoint()
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
        if opts.checkpoint_every is not None:
            cmd += ["--checkpoint-every", str(opts.checkpoint_every)]
        if opts.without:
            cmd += ["--without", opts.without]
        # Its output is kept: a run that does not complete says why (a stall's report).
        output = (Path(tmp) / "run.out").open("w", encoding="utf-8")
        proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=output)
        session = open_session(BusOptions(connect=(endpoint,)))
        ticking = threading.Event()
        frames = FrameWatch()
        tick = [0]  # the newest tick the world's status showed
        roster = Roster([f"a{i + 1}" for i in range(n_agents)])

        def on_status(sample) -> None:
            try:
                tick[0] = decode(sample.payload.to_bytes(), WorldStatus).tick
            except ProtocolError:
                return
            if tick[0] > 0:
                ticking.set()

        subs = [session.declare_subscriber(keys.status("w0"), on_status)]
        if opts.kill_world_every:
            subs.append(session.declare_subscriber(keys.all_agents("w0", "sensors"), frames.on_frame))
        try:
            while proc.poll() is None and not ticking.wait(0.1) and not stop.is_set():
                if time.monotonic() - started > opts.run_timeout:
                    break
            now = time.monotonic()
            next_agent, next_world = now + _draw(rng, opts.kill_every), now + _draw(world_rng, opts.kill_world_every)
            # A world is killed only once it has got one checkpoint past where it started (one
            # that dies before, three times in a row, is taken for one that cannot start) and
            # `world_min_life` ticks past it.
            interval = max(opts.checkpoint_every or DEFAULT_EVERY, opts.world_min_life)
            while proc.poll() is None:
                if stop.wait(0) or time.monotonic() - started > opts.run_timeout:
                    proc.send_signal(signal.SIGTERM)
                    break
                if next_world == float("inf") and opts.kill_world_every and not frames.recovering:
                    next_world = time.monotonic() + _draw(world_rng, opts.kill_world_every)
                try:
                    proc.wait(min(max(min(next_agent, next_world) - time.monotonic(), 0.05), 0.5))
                    break
                except subprocess.TimeoutExpired:
                    pass
                now = time.monotonic()
                if now >= next_world and frames.newest >= frames.started_at + interval:
                    next_world = float("inf")  # the next is drawn once the restarted world ticks
                    pid = world_pid(proc.pid)
                    if pid is not None:
                        frames.killed()
                        os.kill(pid, signal.SIGKILL)
                        result.world_kills += 1
                        log(f"  run {index}: killed the world (pid {pid}) at tick {frames.newest}")
                # An agent not yet min_life ticks old is spared; the kill waits until one is.
                ready = roster.ready(tick[0], opts.min_life)
                if now >= next_agent and ready:
                    next_agent = now + _draw(rng, opts.kill_every)
                    _kill_agent(opts, session, rng, roster, ready, tick[0], result, index, log)
            result.exit_code = proc.wait(opts.run_timeout)
        finally:
            for sub in subs:
                sub.undeclare()
            session.close()
            if proc.poll() is None:
                proc.kill()
                proc.wait(10)
        output.close()
        result.ticks_lost = list(frames.lost)
        if summary_path.exists():
            s = json.loads(summary_path.read_text(encoding="utf-8"))
            result.completed, result.stalled, result.ticks = s["completed"], s["stalled"], s["ticks"]
            result.sites_filled, result.sites_total, result.bricks_total = (s["sites_filled"], s["sites_total"],
                                                                            s["bricks_total"])
            result.world_restarts = s.get("world_restarts", 0)
        if not result.completed:
            said = (Path(tmp) / "run.out").read_text(encoding="utf-8", errors="replace")
            result.why = said.strip().splitlines()[-12:]
    result.wall_seconds = time.monotonic() - started
    return result


class Roster:
    """The agents still alive, and the world tick each was started (again) at."""

    def __init__(self, ids: list[str]) -> None:
        self.alive = list(ids)
        self.born = dict.fromkeys(ids, 0)

    def ready(self, tick: int, min_life: int) -> list[str]:
        """The alive agents that have lived `min_life` ticks by `tick` (none, after a world
        went back to a checkpoint older than their start, until it is past it again)."""
        return [a for a in self.alive if tick - self.born[a] >= min_life]


def _kill_agent(opts: ChaosOptions, session, rng: np.random.Generator, roster: Roster, ready: list[str],
                tick: int, result: ChaosRun, index: int, log) -> None:
    """SIGKILL a random one of the `ready` agents (the world at `tick`) through `conag kill` /
    `conag restart`, never leaving fewer than `min_alive` alive."""
    victim = ready[int(rng.integers(len(ready)))]
    restart = len(roster.alive) <= opts.min_alive or bool(rng.random() < opts.restart_share)
    answer = control(session, "w0", "restart" if restart else "kill", victim, timeout=5.0)
    if not answer.ok:
        return  # the run is ending, or not up yet
    result.kills += 1
    result.lives.append(tick - roster.born[victim])
    if restart:
        result.restarts += 1
        roster.born[victim] = tick
    else:
        roster.alive.remove(victim)
        result.left_dead.append(victim)
    log(f"  run {index}: {'restarted' if restart else 'killed'} {victim} at tick {tick}")


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
    lost = [n for r in results for n in r.ticks_lost]
    return {"options": asdict(opts), "runs": [asdict(r) | {"bricks_kept": r.bricks_kept} for r in results],
            "completed": sum(r.completed for r in results), "bricks_kept": sum(r.bricks_kept for r in results),
            "total": len(results), "world_kills": sum(r.world_kills for r in results),
            "world_restarts": sum(r.world_restarts for r in results), "max_ticks_lost": max(lost, default=0)}


def build_parser() -> argparse.ArgumentParser:
    c = argparse.ArgumentParser(prog="python3 -m faults.chaos",
                       description="build while agent processes are SIGKILLed at random (some restarted)",
                       epilog=f"exit codes: 0 every run complete with bricks_total kept; {EXIT_ERROR} some run "
                              f"changed bricks_total; {EXIT_INCOMPLETE} some run did not complete; "
                              f"{EXIT_INTERRUPTED} interrupted")
    c.add_argument("scenario")
    c.add_argument("--runs", type=int, default=1, help="conag runs, one after the other (default 1)")
    c.add_argument("--kill-every", type=float, default=3.0, metavar="S",
                   help="mean wall seconds between agent kills (default 3; 0: no agent is killed)")
    c.add_argument("--min-life", type=non_negative, default=200, metavar="N",
                   help="kill an agent only once the world has ticked N ticks since it was (re)started "
                        "(default 200): on a slow machine a process killed sooner has done nothing yet")
    c.add_argument("--restart-share", type=float, default=0.5, metavar="P",
                   help="chance that a killed agent is started again at once (default 0.5)")
    c.add_argument("--kill-world-every", type=float, default=0.0, metavar="S",
                   help="also SIGKILL the world process every S wall seconds on average (default 0: never); "
                        "conag run restarts it from its last checkpoint")
    c.add_argument("--world-min-life", type=non_negative, default=0, metavar="N",
                   help="kill the world only once it has ticked N ticks past where it (re)started (default 0: "
                        "as soon as it has one checkpoint past it)")
    c.add_argument("--checkpoint-every", type=positive, metavar="N",
                   help=f"the world's checkpoint interval in ticks (default {DEFAULT_EVERY})")
    c.add_argument("--min-alive", type=int, default=1, metavar="N",
                   help="never leave fewer agents alive (a kill then restarts; default 1)")
    c.add_argument("--seed", type=int, default=0, help="seed of the kill schedule (default 0)")
    c.add_argument("--world-seed", type=int, help="the world's seed (default: the scenario's)")
    c.add_argument("--agents", type=int, help="number of agents (default: the scenario's)")
    c.add_argument("--max-ticks", type=int, help="tick limit per run (default: the scenario's)")
    c.add_argument("--stall-ticks", type=non_negative, default=3000, metavar="N",
                   help="a run stops as stalled after N ticks without a site filled (default 3000)")
    c.add_argument("--run-timeout", type=float, default=600.0, metavar="S",
                   help="stop a run after S wall seconds (default 600)")
    c.add_argument("--without", default="", metavar="NAMES",
                   help="switch these additions off in every agent, restarted ones too (conag run --without)")
    c.add_argument("--json", metavar="PATH", help="write every run's figures as JSON")
    return c



def _run(args) -> int:
    opts = ChaosOptions(args.scenario, runs=args.runs, kill_every=args.kill_every, min_life=args.min_life,
                        restart_share=args.restart_share,
                        min_alive=args.min_alive, seed=args.seed, agents=args.agents, max_ticks=args.max_ticks,
                        stall_ticks=args.stall_ticks, run_timeout=args.run_timeout, world_seed=args.world_seed,
                        kill_world_every=args.kill_world_every, world_min_life=args.world_min_life,
                        checkpoint_every=args.checkpoint_every, without=args.without)
    with stop_on_signals() as stop:
        results = chaos(opts, stop, log=lambda line: print(line, flush=True))
    out = report(opts, results)
    print(f"chaos {args.scenario}: {out['completed']}/{out['total']} runs complete, bricks_total kept in "
          f"{out['bricks_kept']}/{out['total']}"
          + (f", {out['world_kills']} world kills survived, at most {out['max_ticks_lost']} ticks lost per kill"
             if out["world_kills"] else ""))
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(out, f, indent=2)
            f.write("\n")
    if out["bricks_kept"] < out["total"]:
        return EXIT_ERROR
    if len(results) < opts.runs:
        return EXIT_INTERRUPTED
    return 0 if out["completed"] == out["total"] else EXIT_INCOMPLETE



def main(argv: list[str] | None = None) -> int:
    """Parse the command line and run the chaos builds; the exit code says how they went."""
    return _run(build_parser().parse_args(argv))


if __name__ == "__main__":
    raise SystemExit(main())

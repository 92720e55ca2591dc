"""`python3 -m faults.partition`: a build across three hosts, one of them cut off for a while.

The hosts are Linux network namespaces on one machine (`faults.netns.Hosts`): host 1 runs
the zenoh router (`conag router`, deploy/multi-host/router.json5) and the world, hosts 2
and 3 run agent processes, every process a client of the router
(deploy/multi-host/client.json5, `--connect tcp/10.231.0.1:7447`). A `conag status --watch
--json` on host 1 records each WorldStatus with the wall time it came. Once the world has
reached `cut_tick` with every agent alive, host 2's link goes down for `cut_seconds`, then
up again; the build goes on until it completes or `timeout` passes.

From the statuses alone (`measure`), each run reports for host 2's agents how long after
the cut the world saw them dead (their liveliness tokens gone) and their bodies leave the
world, and how long after the link came back they were alive with their bodies again;
whether host 3's agents stayed alive throughout, the re-attached agents moved their
bodies again, the build completed, and `bricks_total` never changed. The agent processes
are never restarted: `same_processes` says they all still ran when the world finished.
A build that does not complete also gets a report: the last status read and, as a stall
report has them, each agent's body and last AgentState (`conag echo 'agent/*/state' --json`
on host 1): what its agent was doing and what it said blocks it.

The world ticks in lockstep capped at `max_tick_rate` (100 a second): uncapped, the agent
left alone ran at several hundred ticks a second and could finish the build within the
cut, leaving nothing to come back to. (Realtime worlds do not build through a router under
load: a frame an agent misses takes that tick's odometry with it; docs/results/reliability.md.) Needs
root (see `faults.netns.unavailable`); the namespaces are deleted however a run ends, and
`--logs DIR` keeps each process's log and the statuses read (`status.jsonl`).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

from faults.netns import Hosts, unavailable
from protocol.messages import AgentState, WorldStatus
from world_server.scenario import load_scenario
from world_server.stall import agent_lines
from world_server.world import World

ROOT = Path(__file__).resolve().parent.parent
DEPLOY = ROOT / "deploy" / "multi-host"
PORT = 7447


@dataclass(frozen=True)
class PartitionOptions:
    """What a partition run builds, where its agents run and how long the cut lasts."""

    scenario_path: str = str(ROOT / "scenarios" / "nested_squares.toml")
    agents_cut: int = 2          # agents on host 2, whose link is cut
    agents_kept: int = 1         # agents on host 3
    cut_seconds: float = 10.0
    cut_tick: int = 150          # cut once the world has reached this tick with every agent alive
    tick_mode: str = "lockstep"
    max_tick_rate: float = 100.0  # lockstep pace cap: one agent left alone must not finish the build in the cut
    timeout: float = 300.0       # wall seconds for the whole build
    stall_seconds: float = 60.0  # give up once no site has been filled for this long (wall seconds)
    prefix: str = ""             # namespace names' prefix (default: from the process id)
    verbose: bool = False        # -v to the world and the agents (their logs: `--logs`)

    def __post_init__(self) -> None:
        if self.agents_cut < 1 or self.agents_kept < 0:
            raise ValueError("need at least one agent on the host that is cut off")
        if not self.cut_seconds > 0:
            raise ValueError("--cut-seconds must be > 0")


@dataclass
class PartitionRun:
    """One run's outcome, measured from the world's statuses (times in wall seconds)."""

    completed: bool = False
    ticks: int = 0
    sites_filled: int = 0
    sites_total: int = 0
    bricks_expected: int = -1
    bricks_seen: list[int] = field(default_factory=list)  # every bricks_total the world reported
    cut_tick: int = -1
    restore_tick: int = -1
    dead_after: dict[str, float | None] = field(default_factory=dict)   # from the cut
    left_after: dict[str, float | None] = field(default_factory=dict)   # from the cut
    back_after: dict[str, float | None] = field(default_factory=dict)   # from the link's return
    moved_after_back: dict[str, float] = field(default_factory=dict)    # world units driven since
    restarts: dict[str, int] = field(default_factory=dict)
    kept_alive: bool = False     # host 3's agents alive in every status after the cut
    same_processes: bool = False  # no agent process exited before the world finished
    said_waiting: bool = False   # each cut agent's log says it waits for its world
    wall_seconds: float = 0.0
    error: str = ""
    # A build that did not complete: its last status and every agent's position, behaviour
    # and blocker, from the AgentStates it last sent (`report_lines`).
    report: list[str] = field(default_factory=list)

    def came_back(self, agent: str, cut_seconds: float) -> bool:
        """`agent` was seen dead and its body leave during the cut, then came back and moved."""
        dead, left, back = self.dead_after.get(agent), self.left_after.get(agent), self.back_after.get(agent)
        return (dead is not None and left is not None and back is not None and dead < cut_seconds
                and dead <= left <= cut_seconds + back and self.moved_after_back.get(agent, 0.0) > 0
                and self.restarts.get(agent) == 1)

    def survived(self, cut_seconds: float) -> bool:
        """Everything the partition test asks for held."""
        return (self.completed and not self.error and self.kept_alive and self.same_processes
                and self.said_waiting and self.bricks_seen == [self.bricks_expected]
                and bool(self.dead_after) and all(self.came_back(a, cut_seconds) for a in self.dead_after))

    def line(self) -> str:
        def secs(d: dict) -> str:
            return ", ".join(f"{a} {'-' if v is None else f'{v:.1f}'}" for a, v in d.items())
        state = "complete" if self.completed else "NOT complete"
        return (f"{state}: {self.sites_filled}/{self.sites_total} sites in {self.ticks} ticks; cut at tick "
                f"{self.cut_tick}; seen dead after {secs(self.dead_after)} s, bodies left after "
                f"{secs(self.left_after)} s; back {secs(self.back_after)} s after the link; bricks_total "
                f"{self.bricks_seen} (expected {self.bricks_expected}); {self.wall_seconds:.0f} s"
                + (f"; error: {self.error}" if self.error else ""))


def measure(statuses: list[tuple[float, dict]], t_cut: float, t_restore: float, cut: list[str],
            kept: list[str], run: PartitionRun) -> PartitionRun:
    """Fill `run`'s timings from `(wall time, WorldStatus as a dict)` pairs, oldest first."""
    def rows(since: float):
        for t, st in statuses:
            if t >= since:
                yield t, st, dict(zip(st["agent_ids"], range(len(st["agent_ids"]))))

    run.bricks_seen = sorted({st["bricks_total"] for _, st in statuses})
    for a in cut:
        dead = left = back = None
        for t, st, at in rows(t_cut):
            if a not in at:
                continue
            i = at[a]
            if dead is None and not st["agent_alive"][i]:
                dead = (t, st)
            if left is None and not st["agent_present"][i]:
                left = (t, st)
            if dead is not None and t >= t_restore and st["agent_alive"][i] and st["agent_present"][i]:
                back = (t, st)
                break
        run.dead_after[a] = None if dead is None else round(dead[0] - t_cut, 2)
        run.left_after[a] = None if left is None else round(left[0] - t_cut, 2)
        run.back_after[a] = None if back is None else round(back[0] - t_restore, 2)
        if back is not None and statuses:
            last = statuses[-1][1]
            run.moved_after_back[a] = round(last["agent_distance"][last["agent_ids"].index(a)]
                                            - back[1]["agent_distance"][back[1]["agent_ids"].index(a)], 3)
    after = [(st, at) for _, st, at in rows(t_cut)]
    run.kept_alive = all(st["agent_alive"][at[a]] for st, at in after for a in kept if a in at) and bool(after)
    if statuses:
        last = statuses[-1][1]
        run.restarts = {a: last["agent_restarts"][i] for i, a in enumerate(last["agent_ids"])}
    return run


def report_lines(statuses: list[tuple[float, dict]], state_log: str) -> list[str]:
    """The last status read and, as a stall report has them (`world_server.stall.agent_lines`),
    each agent's body and last AgentState from `state_log`: the lines `conag echo
    'agent/*/state' --json` printed (a line cut off when it was stopped is skipped). Empty
    without a status. What a failed run leaves to diagnose it by: which agent believed what."""
    if not statuses:
        return []
    last = _message(WorldStatus, statuses[-1][1])
    # Idle since the first status that reported the last count of filled sites.
    since = next(st["tick"] for _, st in statuses if st["sites_filled"] == last.sites_filled)
    states: dict[str, AgentState] = {}
    for line in state_log.splitlines():
        try:
            echoed = json.loads(line)
            if echoed.get("type") == "AgentState":
                state = _message(AgentState, echoed["message"])
                states[state.agent_id] = state
        except (ValueError, TypeError, KeyError):
            continue
    head = (f"last status: tick {last.tick}, {last.sites_filled}/{last.sites_total} sites, no site filled "
            f"for the last {last.tick - since} ticks")
    return [head, *agent_lines(last, states)]


def _message(kind, fields: dict):
    """A message dataclass from its JSON form (tuples came back as lists)."""
    return kind(**{k: tuple(v) if isinstance(v, list) else v for k, v in fields.items()})


class _Procs:
    """The run's processes, each in its own process group with its output in a log file."""

    def __init__(self, hosts: Hosts, log_dir: Path):
        self.hosts, self.log_dir = hosts, log_dir
        self.procs: dict[str, subprocess.Popen] = {}

    def start(self, name: str, host: int, *args: str) -> subprocess.Popen:
        out = open(self.log_dir / f"{name}.log", "w", encoding="utf-8")  # noqa: SIM115 -- the process holds it
        proc = subprocess.Popen(self.hosts.argv(host, [sys.executable, "-m", "conag", *args]), cwd=ROOT,
                                stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT,
                                start_new_session=True)
        out.close()
        self.procs[name] = proc
        return proc

    def log(self, name: str) -> str:
        path = self.log_dir / f"{name}.log"
        return path.read_text(encoding="utf-8", errors="replace") if path.exists() else ""

    def stop_all(self, grace: float = 5.0) -> None:
        for proc in self.procs.values():
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGTERM)
        deadline = time.monotonic() + grace
        for proc in self.procs.values():
            try:
                proc.wait(max(deadline - time.monotonic(), 0.1))
            except subprocess.TimeoutExpired:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait(5)


class _StallClock:
    """Whether the statuses read show no new best count of filled sites for `seconds`."""

    def __init__(self, statuses: list[tuple[float, dict]], seconds: float):
        self.statuses, self.seconds = statuses, seconds
        self.best, self.since = -1, time.monotonic()

    def stalled(self) -> bool:
        if self.statuses and self.statuses[-1][1]["sites_filled"] > self.best:
            self.best, self.since = self.statuses[-1][1]["sites_filled"], time.monotonic()
        return time.monotonic() - self.since > self.seconds


def _wait(predicate, timeout: float, interval: float = 0.1) -> bool:
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() >= deadline:
            return False
        time.sleep(interval)
    return True


def _watch_statuses(proc: subprocess.Popen, into: list[tuple[float, dict]]) -> threading.Thread:
    """Read `conag status --watch --json` lines as they come, stamped with the wall time."""
    def read() -> None:
        for line in proc.stdout:
            try:
                into.append((time.monotonic(), json.loads(line)))
            except json.JSONDecodeError:
                pass
    thread = threading.Thread(target=read, daemon=True)
    thread.start()
    return thread


def partition_run(opts: PartitionOptions, log_dir: Path, log=print) -> PartitionRun:
    """One build across three namespaces with host 2 cut off for `opts.cut_seconds`."""
    scenario = load_scenario(opts.scenario_path)
    run = PartitionRun(bricks_expected=World(scenario).discs.bricks_total(), sites_total=0)
    cut = [f"a{i + 1}" for i in range(opts.agents_cut)]
    kept = [f"a{opts.agents_cut + i + 1}" for i in range(opts.agents_kept)]
    started = time.monotonic()
    statuses: list[tuple[float, dict]] = []
    hosts = Hosts(opts.prefix or f"cg{os.getpid()}h", 3)
    bus = ["--zenoh-config", str(DEPLOY / "client.json5"), "--connect", f"tcp/{hosts.address(1)}:{PORT}"]
    summary = log_dir / "summary.json"
    verbose = ["-v"] if opts.verbose else []
    with hosts:
        procs = _Procs(hosts, log_dir)
        try:
            procs.start("router", 1, "router", "--zenoh-config", str(DEPLOY / "router.json5"))
            if not _wait(lambda: "listening" in procs.log("router"), 20):
                raise RuntimeError(f"the router did not start: {procs.log('router')[-500:]}")
            world = procs.start("world", 1, "world", opts.scenario_path, *bus, "--tick-mode", opts.tick_mode,
                                "--wait-agents", str(len(cut) + len(kept)), "--stop-when-complete", "--quiet",
                                "--max-tick-rate", str(opts.max_tick_rate),
                                "--summary", str(summary), *verbose)
            agents = {a: procs.start(a, 2 if a in cut else 3, "agent", "--id", a, "--seed", str(i), *bus, *verbose)
                      for i, a in enumerate(cut + kept)}
            watcher = subprocess.Popen(hosts.argv(1, [sys.executable, "-m", "conag", "status", "--watch", "--json",
                                                      "--timeout", "30", *bus]),
                                       cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                                       start_new_session=True)
            procs.procs["status"] = watcher
            reader = _watch_statuses(watcher, statuses)
            # What each agent last said it does, for the report of a build that fails.
            procs.start("agent-states", 1, "echo", "agent/*/state", "--json", *bus)

            def ready() -> bool:
                st = statuses[-1][1] if statuses else None
                return (world.poll() is not None or (st is not None and st["tick"] >= opts.cut_tick
                        and sum(st["agent_alive"]) == len(cut) + len(kept)))
            if not _wait(ready, 120) or world.poll() is not None:
                raise RuntimeError("the world did not reach the cut tick with every agent alive")
            run.cut_tick = statuses[-1][1]["tick"]
            hosts.cut(2)
            t_cut = time.monotonic()
            log(f"  tick {run.cut_tick}: host 2 ({', '.join(cut)}) cut off for {opts.cut_seconds:g} s")
            _wait(lambda: world.poll() is not None, opts.cut_seconds)
            hosts.restore(2)
            t_restore = time.monotonic()
            run.restore_tick = statuses[-1][1]["tick"] if statuses else -1
            log(f"  tick {run.restore_tick}: host 2 back")
            stall = _StallClock(statuses, opts.stall_seconds)
            if not _wait(lambda: world.poll() is not None or stall.stalled(),
                         max(opts.timeout - (t_restore - started), 1.0)):
                run.error = f"the world did not finish within {opts.timeout:g} s"
            elif stall.stalled():
                run.error = (f"stalled: no site filled for {opts.stall_seconds:g} s "
                             f"({statuses[-1][1]['sites_filled']}/{statuses[-1][1]['sites_total']} sites)")
            run.same_processes = all(p.poll() is None for p in agents.values())
            procs.stop_all()
            reader.join(5)
            with open(log_dir / "status.jsonl", "w", encoding="utf-8") as f:
                f.writelines(json.dumps({"t": round(t - started, 3), **st}) + "\n" for t, st in statuses)
            measure(statuses, t_cut, t_restore, cut, kept, run)
            last = statuses[-1][1] if statuses else None
            if run.error or (last is not None and last["sites_filled"] < last["sites_total"]):
                run.report = report_lines(statuses, procs.log("agent-states"))
            run.said_waiting = all("waiting for world" in procs.log(a) for a in cut)
        except (RuntimeError, OSError) as exc:
            run.error = str(exc)
        finally:
            procs.stop_all()
    if summary.exists():
        s = json.loads(summary.read_text(encoding="utf-8"))
        run.completed, run.ticks = s["completed"], s["ticks"]
        run.sites_filled, run.sites_total = s["sites_filled"], s["sites_total"]
        run.bricks_seen = sorted(set(run.bricks_seen) | {s["bricks_total"]})
    run.wall_seconds = round(time.monotonic() - started, 1)
    return run


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python3 -m faults.partition", description=__doc__.split("\n\n")[0])
    p.add_argument("scenario", nargs="?", default=PartitionOptions.scenario_path)
    p.add_argument("--runs", type=int, default=1)
    p.add_argument("--agents-cut", type=int, default=2, help="agents on host 2, which is cut off (default 2)")
    p.add_argument("--agents-kept", type=int, default=1, help="agents on host 3 (default 1)")
    p.add_argument("--cut-seconds", type=float, default=10.0)
    p.add_argument("--cut-tick", type=int, default=150, help="cut once the world reaches this tick")
    p.add_argument("--tick-mode", choices=("lockstep", "realtime"), default="lockstep")
    p.add_argument("--max-tick-rate", type=float, default=100.0, metavar="HZ",
                   help="lockstep: at most HZ ticks a second (default 100), so that the agents left alone "
                        "cannot finish the build while the others are cut off")
    p.add_argument("--timeout", type=float, default=300.0, help="wall seconds a build may take")
    p.add_argument("--stall-seconds", type=float, default=60.0,
                   help="give up once no site has been filled for this long (default 60)")
    p.add_argument("--json", metavar="PATH", help="write every run's figures as JSON")
    p.add_argument("--logs", metavar="DIR", help="keep each process's log under DIR/run-N/")
    p.add_argument("-v", "--verbose", action="store_true", help="the world and the agents log more (see --logs)")
    args = p.parse_args(argv)
    reason = unavailable()
    if reason:
        print(f"error: {reason}", file=sys.stderr)
        return 2
    opts = PartitionOptions(args.scenario, args.agents_cut, args.agents_kept, args.cut_seconds, args.cut_tick,
                            args.tick_mode, args.max_tick_rate, args.timeout,
                            args.stall_seconds, verbose=args.verbose)
    results = []
    for i in range(args.runs):
        with tempfile.TemporaryDirectory(prefix="conag-partition-") as tmp:
            log_dir = Path(args.logs) / f"run-{i}" if args.logs else Path(tmp)
            log_dir.mkdir(parents=True, exist_ok=True)
            r = partition_run(opts, log_dir)
        print(f"run {i}: {r.line()}", flush=True)
        for line in r.report:
            print(f"  {line}", flush=True)
        results.append(r)
    if args.json:
        out = {"options": asdict(opts),
               "runs": [asdict(r) | {"survived": r.survived(opts.cut_seconds)} for r in results],
               "survived": sum(r.survived(opts.cut_seconds) for r in results), "total": len(results)}
        Path(args.json).write_text(json.dumps(out, indent=2), encoding="utf-8")
    survived = sum(r.survived(opts.cut_seconds) for r in results)
    print(f"{survived} of {len(results)} runs survived the partition")
    return 0 if survived == len(results) else 3


if __name__ == "__main__":
    sys.exit(main())

"""`conag run SCENARIO`: a world and one process per agent, on loopback, until done.

The world, every agent and (with `--teacher`) the teacher are separate processes (fresh
interpreters: nothing crosses a fork). This process watches the world's status, shows
progress, answers `conag kill` / `conag restart` (a RunControl query on the bus), and
once the structure is complete or the tick limit passes, stops everything and writes the
run summary. A run that fills no site for `stall_ticks` ticks is stalled: it prints why
(`world_server.stall.StallWatch`: each agent's position and last AgentState), stops
everything and is marked `stalled` in the summary, so a stuck build never just sits
there until the limit.

The run supervises the world: the world checkpoints into the run's temporary directory
every `checkpoint_every` ticks, and when its process dies without a final status (SIGKILL,
a crash) the run says so and starts it again from its last good checkpoint (from the
start if it had written none yet); the agents wait for it and attach again by themselves.
A world that dies `MAX_QUICK_DEATHS` times in a row within `QUICK_DEATH` seconds of
starting, before it got a checkpoint further, ends the run as an error.

With `record`, a `conag record` process records the run (`conag/recording/recorder.py`): it starts
after the world and before the agents, which start once it has heard the world, so the
recording holds every tick; it stops last, after the agents' final state reports. It runs
at `record_priority` ("idle" by default: Linux SCHED_IDLE), so the world and the agents get
the CPU first.

The run's world listens on `endpoint`: `conag run` picks a free loopback port unless told
(`--listen`), and registers the run by name while it runs (`conag/runs.py`), so two runs
on one machine never exchange a message and the verbs find a run by `--run NAME`.

With `secure` (`conag run --secure`, `conag/secure.py`), a zenoh router with access control
listens on the run's endpoint, every process is a client of it with its own credential, and
this process's session is the operator's.
"""

from __future__ import annotations

import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path

from conag.agent_settings import AgentSettings
from conag.common import RECORDER_PRIORITY
from conag.exit_codes import exit_words
from conag.forkserver import Forked, ForkServer, ForkServerError
from conag.noise_flags import to_note
from conag.secure import bus_flags, run_bus_options, secure_bus
from conag.sim.society import DEFAULT_CUE_REACH, society_ids
from protocol import keys
from protocol.bus import Declarations, open_session
from protocol.bus.acl import OBSERVER, TEACHER, WORLD, agent_user
from protocol.codec import ProtocolError, decode, encode
from protocol.messages import AgentState, RunControl, RunControlResult, WorldStatus
from world_server.checkpoint import DEFAULT_EVERY, CheckpointError, newest_good, read_checkpoint
from world_server.noise import NoiseSettings
from world_server.scenario import Scenario
from world_server.stall import DEFAULT_STALL_TICKS, StallWatch
from world_server.summary import RunSummary

MAX_QUICK_DEATHS = 3  # a world dying this many times in a row soon after starting is not restarted again
QUICK_DEATH = 10.0    # wall seconds: a death sooner than this after starting counts as quick


@dataclass(frozen=True)
class RunOptions:
    """What `conag run` runs, and how (`conag.commands.run` reads them from its flags)."""

    scenario_path: str
    scenario: Scenario
    endpoint: str
    world_id: str = "w0"
    agents: int | None = None
    seed: int | None = None
    max_ticks: int | None = None
    max_tick_rate: float | None = None  # lockstep: at most this many ticks a wall second (`conag world`)
    summary: str | None = None
    headless: bool = False
    quiet: bool = False
    agent: AgentSettings = field(default_factory=AgentSettings)  # every agent's (the flags: AgentSettings.argv)
    teacher: bool = False             # also run a teacher process (`conag teacher`)
    weights_dir: str | None = None    # learning agents save their weights to weights_dir/<id>.json
    stall_ticks: int = DEFAULT_STALL_TICKS  # stop when no site is filled for this many ticks; 0: never
    unbuildable: str = ""             # why the start-up check found the structure cannot be built (stall report)
    record: str | None = None         # record the run to this MCAP file (`conag record`)
    record_priority: str = RECORDER_PRIORITY  # the recorder's CPU priority (`conag record --priority`)
    view: int | None = None           # serve the browser viewer on this port (`conag view`)
    foxglove: int | None = None       # serve the Foxglove WebSocket on this port (`conag view --foxglove`)
    maps_every: int = 0               # the recorder and viewer ask for the agents' maps every N ticks
    profile: str | None = None        # the world writes its loop's times here (conag world --profile)
    per_process: int = 1              # agents per agent process; > 1: `conag agents` hosts
    agent_mode: str = "auto"          # zenoh mode of agent processes: peer, client, auto (`agent_bus_mode`)
    attach_timeout: float | None = None  # seconds each agent waits for the world (None: `attach_timeout`)
    secure: str | None = None         # a secure bus (conag/secure.py): a deployment dir; "" a fresh one
    checkpoint_every: int = DEFAULT_EVERY  # ticks between the world's checkpoints (it is restarted from the last)
    noise: NoiseSettings = field(default_factory=NoiseSettings)  # the world's noise overrides (docs/noise.md)
    fork_server: bool = True          # single agent processes are forks of a preloaded server (conag/forkserver.py)
    foremen: int = 0                  # a society (docs/society.md): foremen f1.. and reactive workers w1..
    workers: int = 0                  # instead of ConAg agents a1..; its world has cues
    cue_reach: float = DEFAULT_CUE_REACH  # how far a body marks, in a society's world

    @property
    def society(self) -> bool:
        """Whether the run is a society of foremen and workers rather than of ConAg agents."""
        return self.foremen + self.workers > 0

    @property
    def n_agents(self) -> int:
        """How many agent processes the run starts."""
        if self.society:
            return self.foremen + self.workers
        return self.agents if self.agents is not None else self.scenario.agents


class RunEnding(RuntimeError):
    """A restart asked for while the run stops its processes."""


def attach_timeout(processes: int) -> int:
    """Seconds each agent process of a run waits for the world by default. The world is on
    its way: wait for it longer than a lone agent would. A hundred interpreters starting on
    two cores took over 30 s before the first one attached."""
    return max(30, 2 * processes)


@dataclass
class Fleet:
    """The agent processes of a run, by id."""

    opts: RunOptions
    procs: dict[str, subprocess.Popen | Forked] = field(default_factory=dict)
    server: ForkServer | None = None  # single agent processes are forked from it (None: each a fresh interpreter)
    hosted: set[str] = field(default_factory=set)  # ids in procs served by a `conag agents` host, not stopped
    lock: threading.Lock = field(default_factory=threading.Lock)
    closed: bool = False  # stop_all has begun: a `conag restart` then starts nothing (it would outlive the run)

    def _bus_args(self, agent_id: str) -> list[str]:
        o = self.opts
        n = o.n_agents
        processes = -(-n // max(o.per_process, 1))
        args = ["--world-id", o.world_id, *bus_flags(o, agent_user(agent_id)),
                "--attach-timeout", str(o.attach_timeout or attach_timeout(processes))]
        if o.secure is None:  # a secure run's mode is its credential file's (a client of the router)
            args += ["--mode", agent_bus_mode(o.agent_mode, processes)]
        if o.record:  # attach once the recorder is heard: its link to the agent may come later than the world's
            args.append("--recorded")
        return args

    def start_host(self, first: int, last: int) -> subprocess.Popen:
        """One `conag agents` process for agents a<first>..a<last>; `kill` stops one alone
        through its stdin."""
        o = self.opts
        cmd = [sys.executable, "-m", "conag", "agents", "--ids", f"a{first}..a{last}", "--stdin-control",
               *self._bus_args(f"a{first}"), "--seed", str(o.seed if o.seed is not None else o.scenario.seed),
               *o.agent.argv()]
        ids = [f"a{i}" for i in range(first, last + 1)]
        with self.lock:
            if self.closed:
                raise RunEnding(f"the run is ending: {ids[0]}..{ids[-1]} not started")
            proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, text=True)
            for agent_id in ids:
                self.procs[agent_id] = proc
            self.hosted.update(ids)
        return proc

    def start(self, agent_id: str) -> subprocess.Popen | Forked:
        o = self.opts
        cmd = [sys.executable, "-m", "conag", "agent", "--id", agent_id, *self._bus_args(agent_id),
               "--seed", str(o.seed if o.seed is not None else o.scenario.seed), *o.agent.argv()]
        if o.society:
            cmd += ["--role", "foreman" if agent_id.startswith("f") else "worker"]
        if o.weights_dir:
            weights = Path(o.weights_dir) / f"{agent_id}.json"
            cmd += ["--weights-out", str(weights)]
            if agent_id in self.procs and weights.exists():
                # A restarted student picks up what it had learned (saved every few hundred
                # ticks and on exit), not its seed's random weights.
                cmd += ["--weights-in", str(weights)]
        with self.lock:
            if self.closed:
                raise RunEnding(f"the run is ending: {agent_id} not started")
            proc = self._spawn(cmd)
            self.procs[agent_id] = proc
            self.hosted.discard(agent_id)
        return proc

    def _spawn(self, cmd: list[str]) -> subprocess.Popen | Forked:
        """`cmd` (`python -m conag ...`) forked from the fork server, or, without one or
        should it fail, as a fresh interpreter."""
        if self.server is not None:
            try:
                return self.server.spawn(cmd[3:])
            except ForkServerError as exc:
                print(f"warning: {exc}; agent processes start as fresh interpreters from now on", file=sys.stderr)
                self.server = None
        return subprocess.Popen(cmd, stdin=subprocess.DEVNULL)

    def kill(self, agent_id: str) -> str:
        with self.lock:
            proc = self.procs.get(agent_id)
            hosted = agent_id in self.hosted
            self.hosted.discard(agent_id)
        if proc is None:
            raise KeyError(agent_id)
        if hosted:
            return self._stop_hosted(agent_id, proc)
        if proc.poll() is None:
            proc.kill()  # SIGKILL: the point is to show the world survives a crash
            proc.wait(10)
        return f"killed {agent_id} (pid {proc.pid})"

    @staticmethod
    def _stop_hosted(agent_id: str, proc: subprocess.Popen | Forked) -> str:
        """A hosted agent is stopped alone (its host reads `stop ID`), not its whole host."""
        if proc.poll() is None and proc.stdin is not None:
            try:
                proc.stdin.write(f"stop {agent_id}\n")
                proc.stdin.flush()
            except (BrokenPipeError, OSError):
                pass  # the host has just exited: the agent is gone anyway
        return f"stopped {agent_id} in its host (pid {proc.pid})"

    def exited_all(self) -> list[tuple[str, int, int]]:
        """Every agent whose process has exited, as (agent id, exit code, pid)."""
        with self.lock:
            procs = list(self.procs.items())
        return [(a, code, p.pid) for a, p in procs if (code := p.poll()) is not None]

    def all_exited(self) -> bool:
        """Whether every agent process has exited (and there was one)."""
        with self.lock:
            procs = list(self.procs.values())
        return bool(procs) and all(p.poll() is not None for p in procs)

    def restart(self, agent_id: str) -> str:
        killed = self.kill(agent_id) + ", " if agent_id in self.procs else ""
        proc = self.start(agent_id)
        return f"{killed}started {agent_id} (pid {proc.pid})"

    def stop_all(self, grace: float = 5.0) -> None:
        with self.lock:
            self.closed = True
            procs = list({id(p): p for p in self.procs.values()}.values())  # a host once
        for p in procs:
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + grace
        for p in procs:
            try:
                p.wait(max(deadline - time.monotonic(), 0.1))
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(5)


MAX_PEER_AGENTS = 32  # agent processes that still connect as peers with agent_mode "auto"


def agent_bus_mode(mode: str, processes: int) -> str:
    """The zenoh mode of a run's agent processes. Agent peers link to the world and are
    linked to by the processes that want their messages (recorder, teacher, viewer,
    supervisor), never to each other (`protocol.bus.session.LEAF_AUTOCONNECT`; before that,
    100 agent peers opened 4,950 connections among themselves and did not attach within
    30 s). Clients connect to the world alone, which routes for them. "auto": peers up to
    MAX_PEER_AGENTS processes, clients beyond."""
    if mode != "auto":
        return mode
    return "peer" if processes <= MAX_PEER_AGENTS else "client"


class RunBus:
    """The supervisor's session: the world's statuses (to the stall watch and the progress
    line), the agents' AgentStates (to the stall watch) and the RunControl queryable of
    `conag kill` / `conag restart`. A context manager: leaving it undeclares them all and
    closes the session."""

    def __init__(self, opts: RunOptions, fleet: Fleet, watch: StallWatch, tty: bool):
        self.opts, self.watch, self.tty = opts, watch, tty
        self.world_restarts = 0
        self.last_tick = -1        # the newest tick a status reported (0 until the world steps)
        self._started = time.monotonic()
        self.rate = TickRate()
        self.session = open_session(run_bus_options(opts))
        self._declared = Declarations()
        w, add = opts.world_id, self._declared.add
        add(self.session.declare_subscriber(keys.status(w), self.on_status))
        add(self.session.declare_queryable(keys.run_control(w), _on_control(fleet)))
        add(self.session.declare_subscriber(keys.all_agents(w, "state"), self.on_state))

    def on_status(self, sample) -> None:
        """The stall watch sees every status; a progress line for each until a stall."""
        try:
            st = decode(sample.payload.to_bytes(), WorldStatus)
        except ProtocolError:
            return
        self.last_tick = max(self.last_tick, st.tick)
        self.watch.observe(st)
        rate = self.rate.observe(st.tick)
        if not self.opts.quiet and not self.watch.stalled:
            line = _progress(st, self._started, rate, self.world_restarts)
            print(("\r" + line) if self.tty else line, end="" if self.tty else "\n", flush=True)

    def on_state(self, sample) -> None:
        try:
            state = decode(sample.payload.to_bytes(), AgentState)
        except ProtocolError:
            return
        if state.agent_id == keys.agent_of(str(sample.key_expr)):
            self.watch.states[state.agent_id] = state

    def recording(self) -> bool:
        """Whether a recorder of this world has heard it (its liveliness token is up)."""
        key = keys.recorder_token(self.opts.world_id, "recorder")
        return any(r.ok is not None for r in self.session.liveliness().get(key, timeout=0.5))

    def close(self) -> None:
        self._declared.close()
        self.session.close()

    def __enter__(self) -> RunBus:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class TickRate:
    """Ticks per second over the statuses of the last `window` seconds (the world publishes
    one every `status_period`, 0.5 s): steady enough to read, quick to follow a change."""

    def __init__(self, window: float = 2.0, clock: Callable[[], float] = time.monotonic):
        self.window, self.clock = window, clock
        self._seen: deque[tuple[float, int]] = deque()

    def observe(self, tick: int) -> float | None:
        """Take a status's tick; the rate since the oldest status in the window (None: too few yet)."""
        now = self.clock()
        if self._seen and tick < self._seen[-1][1]:
            self._seen.clear()  # a world started again
        self._seen.append((now, tick))
        while len(self._seen) > 2 and now - self._seen[1][0] >= self.window:
            self._seen.popleft()
        (t0, k0), (t1, k1) = self._seen[0], self._seen[-1]
        return (k1 - k0) / (t1 - t0) if t1 > t0 else None


def _progress(st: WorldStatus, started: float, rate: float | None = None, world_restarts: int = 0) -> str:
    return (f"tick {st.tick:>7}  sites {st.sites_filled}/{st.sites_total}  "
            f"agents alive {st.agents_alive}/{len(st.agent_ids)}  "
            + (f"{rate:7.1f} ticks/s  " if rate is not None else " " * 16)
            + f"{time.monotonic() - started:6.1f} s"
            + (f"  world restarts {world_restarts}" if world_restarts else "")
            + ("  COMPLETE" if st.completed else ""))


def run(opts: RunOptions, stop: threading.Event) -> dict:
    """Run the scenario; returns the run summary's JSON object (`RunSummary.as_dict`, also
    written to opts.summary)."""
    with tempfile.TemporaryDirectory(prefix="conag-run-") as tmp:  # gone however the run ends
        n_agents = opts.n_agents
        with secure_bus(opts, n_agents, Path(tmp)) as bus_opts:
            return _run(bus_opts, stop, Path(tmp))


@dataclass
class WorldProcess:
    """The run's world process, started again from its last checkpoint when it dies."""

    opts: RunOptions
    n_agents: int
    final_path: Path
    checkpoint: Path
    proc: subprocess.Popen | None = None
    restarts: int = 0
    started: float = 0.0
    from_tick: int = -1      # the tick of the checkpoint it started from (-1: the start)
    quick_deaths: int = 0
    without: set[str] = field(default_factory=set)  # agents its first tick does not wait for (they died)

    def start(self, resume: Path | None = None) -> None:
        self.proc = _start_world(self.opts, self.n_agents, self.final_path, self.checkpoint, resume)
        self.started = time.monotonic()
        self.from_tick = _checkpoint_tick(resume) if resume else -1
        for agent in sorted(self.without):  # a world started again is told again
            self._tell(f"without {agent}")

    def go_without(self, agent: str) -> None:
        """Its first tick does not wait for `agent` (`conag world --stdin-control`)."""
        self.without.add(agent)
        self._tell(f"without {agent}")

    def _tell(self, line: str) -> None:
        if self.proc is None or self.proc.stdin is None or self.proc.poll() is not None:
            return  # a world that died is told again when it is started again
        try:
            self.proc.stdin.write(line + "\n")
            self.proc.stdin.flush()
        except (BrokenPipeError, OSError):
            pass  # it has just exited: the same

    def died(self) -> bool:
        """The process exited without writing the final status (killed, crashed)."""
        return self.proc.poll() is not None and not self.final_path.exists()

    def restart(self) -> str:
        """Start it again from the newest good checkpoint; what happened, for the user."""
        code = self.proc.returncode
        resume = newest_good(self.checkpoint)
        tick = _checkpoint_tick(resume) if resume else -1
        # Quick: soon after starting, and before it got one checkpoint further (a world that
        # cannot even start; not one that was killed while it worked).
        quick = time.monotonic() - self.started < QUICK_DEATH and tick <= self.from_tick
        self.quick_deaths = self.quick_deaths + 1 if quick else 0
        if self.quick_deaths >= MAX_QUICK_DEATHS:
            raise RuntimeError(f"the world exited ({code}) {self.quick_deaths} times in a row within "
                               f"{QUICK_DEATH:g} s of starting; not starting it again")
        where = f"its checkpoint of tick {tick}" if resume else "the start (no checkpoint yet)"
        self.restarts += 1
        self.start(resume)
        return f"the world died (exit {code}); restarted it from {where} (world restart {self.restarts})"


def _checkpoint_tick(path: Path) -> int:
    try:
        return int(read_checkpoint(path)["tick"])
    except (OSError, CheckpointError, KeyError, TypeError, ValueError):
        return -1


def _run(opts: RunOptions, stop: threading.Event, tmp: Path) -> dict:
    n_agents = opts.n_agents
    world = WorldProcess(opts, n_agents, tmp / "final.json", tmp / "world.ckpt")
    world.start()
    final_path = world.final_path
    if opts.weights_dir:
        Path(opts.weights_dir).mkdir(parents=True, exist_ok=True)
    teacher = _start_teacher(opts) if opts.teacher else None
    fleet = Fleet(opts)
    watch = StallWatch(opts.stall_ticks, opts.unbuildable)
    tty = sys.stdout.isatty() and not opts.headless
    recorder = viewer = foxglove = None
    with RunBus(opts, fleet, watch, tty) as run_bus:
        try:
            if opts.record:
                recorder = _start_recorder(opts)
                _wait_until(run_bus.recording, stop.is_set, lambda: recorder.poll() is not None)
                if recorder.poll() is not None:
                    raise RuntimeError(f"the recorder exited ({recorder.returncode}) before the run started")
            if opts.view is not None:
                viewer = _start_viewer(opts)
            if opts.foxglove is not None:
                foxglove = _start_viewer(opts, foxglove=True)
            k = max(opts.per_process, 1)
            if k == 1 and opts.fork_server:
                fleet.server = _start_fork_server()
            for agent_id in society_ids(opts.foremen, opts.workers):
                fleet.start(agent_id)
            for first in range(1, 0 if opts.society else n_agents + 1, k):
                if k == 1:
                    fleet.start(f"a{first}")
                else:
                    fleet.start_host(first, min(first + k - 1, n_agents))
            early = EarlyDeaths(fleet, world, run_bus)
            while True:
                _wait_until(lambda: world.proc.poll() is not None, stop.is_set, lambda: watch.stalled, early.seen)
                if not stop.is_set():
                    early.handle(tty)
                if stop.is_set() or watch.stalled:
                    break
                if world.proc.poll() is None:
                    continue  # woken by an agent that died before the first tick: the run goes on
                if not world.died():
                    break
                message = world.restart()
                run_bus.world_restarts = world.restarts
                print(("\n" if tty else "") + message, flush=True)
            if watch.stalled:
                print(("\n" if tty else "") + "\n".join(watch.report), flush=True)
        finally:
            _stop(world.proc, grace=10.0)
            fleet.stop_all()
            if fleet.server is not None:
                fleet.server.close()
            if teacher is not None:
                _stop(teacher)
            for observer in (viewer, foxglove):
                if observer is not None:
                    _stop(observer)
            if recorder is not None:
                _stop(recorder, grace=60.0)  # last: it writes what is queued, the summary and the footer
    if tty and not watch.stalled:
        print()
    summary = replace(_final_summary(final_path, world.proc), stalled=watch.stalled, world_restarts=world.restarts,
                      agent=opts.agent.describe())
    if opts.summary and opts.summary != "-":
        Path(opts.summary).write_text(summary.to_json(), encoding="utf-8")
    return summary.as_dict()


class EarlyDeaths:
    """Agent processes that exit before the world's first tick. The world waits for every
    agent before that tick: each one is told to the world, which then goes without it, and
    the run goes on with the others (`conag restart ID` starts it again; it then attaches
    as any agent does). Once every agent process has exited before the first tick, nothing
    is left to build: the run ends as an error. After the first tick agents die and return
    as the run goes on (`conag kill`, crashes): the world sees their tokens go."""

    def __init__(self, fleet: Fleet, world: WorldProcess, run_bus: RunBus):
        self.fleet, self.world, self.run_bus = fleet, world, run_bus
        self._told: set[tuple[str, int]] = set()  # (agent, pid) of the processes already told

    def _new(self) -> list[tuple[str, int, int]]:
        if self.run_bus.last_tick > 0:
            return []
        return [(a, code, pid) for a, code, pid in self.fleet.exited_all() if (a, pid) not in self._told]

    def seen(self) -> bool:
        """Whether an agent process exited before the first tick that the world has not been told of."""
        return bool(self._new())

    def handle(self, tty: bool = False) -> None:
        """Tell the world, and the user, of each; raise RuntimeError once every agent is gone."""
        for agent, code, pid in self._new():
            self._told.add((agent, pid))
            self.world.go_without(agent)
            print(("\n" if tty else "") + f"agent {agent} {exit_words(code)} before the world's first tick: the run "
                  f"goes on without it (`conag restart {agent}` starts it again)", flush=True)
        if self._told and self.run_bus.last_tick <= 0 and self.fleet.all_exited():
            raise RuntimeError("every agent process exited before the world's first tick: nothing is left to build")


def _wait_until(*conditions: Callable[[], bool], poll: float = 0.1) -> None:
    """Sleep until one of `conditions` holds (the run's stop conditions: the world has
    exited, complete or out of ticks; a signal; a stall)."""
    while not any(condition() for condition in conditions):
        time.sleep(poll)


def _start_fork_server() -> ForkServer | None:
    """The run's fork server, or None (with a warning) if it cannot start."""
    try:
        return ForkServer()
    except (ForkServerError, OSError) as exc:
        print(f"warning: {exc}; agent processes start as fresh interpreters", file=sys.stderr)
        return None


def _start_teacher(opts: RunOptions) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "conag", "teacher", "--world-id", opts.world_id,
                             *bus_flags(opts, TEACHER), "--quiet", *(["--recorded"] if opts.record else [])],
                            stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL)


def _start_recorder(opts: RunOptions) -> subprocess.Popen:
    seed = opts.seed if opts.seed is not None else opts.scenario.seed
    cmd = [sys.executable, "-m", "conag", "record", opts.record, "--world-id", opts.world_id,
           *bus_flags(opts, OBSERVER), "--scenario", opts.scenario_path, "--seed", str(seed),
           "--note", f"agents={opts.n_agents}",
           "--note", "agent_args=" + " ".join(opts.agent.argv()), "--maps-every", str(opts.maps_every),
           "--priority", opts.record_priority,
           "--note", f"checkpoint_every={opts.checkpoint_every}"]
    if not opts.noise.changes_nothing:  # `conag replay --verify` puts them on the scenario again
        cmd += ["--note", f"noise={to_note(opts.noise)}"]
    return subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL)


def _start_viewer(opts: RunOptions, foxglove: bool = False) -> subprocess.Popen:
    """`conag view` on the run's bus (with `foxglove`: `conag view --foxglove`); it prints the
    page's (the WebSocket's) address (stdout is the run's)."""
    cmd = [sys.executable, "-m", "conag", "view", "--world-id", opts.world_id, *bus_flags(opts, OBSERVER),
           *(("--foxglove", str(opts.foxglove)) if foxglove else ("--port", str(opts.view)))]
    if opts.maps_every:
        cmd += ["--maps-every", str(opts.maps_every)]  # else the viewer's default
    if not foxglove and not opts.headless and sys.stdout.isatty():
        cmd.append("--open")
    return subprocess.Popen(cmd, stdin=subprocess.DEVNULL)


def _start_world(opts: RunOptions, n_agents: int, final_path: Path, checkpoint: Path,
                 resume: Path | None = None) -> subprocess.Popen:
    """The world process; it stops by itself when complete or out of ticks, writing `final_path`.
    It checkpoints to `checkpoint`; with `resume` it continues from that checkpoint."""
    cmd = [sys.executable, "-m", "conag", "world", opts.scenario_path, "--world-id", opts.world_id,
           *bus_flags(opts, WORLD, world=True), "--ticks", str(opts.max_ticks or opts.scenario.max_ticks),
           "--stop-when-complete", "--wait-agents", str(max(n_agents, 1)), "--quiet", "--summary", str(final_path),
           "--checkpoint", str(checkpoint), "--checkpoint-every", str(opts.checkpoint_every)]
    if resume is not None:
        cmd += ["--resume", str(resume)]
    else:  # a checkpoint holds the seed, the noise settings and the cues
        cmd += [*(["--seed", str(opts.seed)] if opts.seed is not None else []), *opts.noise.to_args()]
        if opts.society:
            cmd += ["--cue-reach", repr(opts.cue_reach)]
    if opts.profile:
        cmd += ["--profile", opts.profile]
    if opts.max_tick_rate:
        cmd += ["--max-tick-rate", repr(opts.max_tick_rate)]
    if opts.record:  # restarted, it lets the agents attach again only once the recorder is linked to it
        cmd.append("--recorded")
    # stdin: `without ID` lines, for agents that died before the first tick (EarlyDeaths)
    return subprocess.Popen([*cmd, "--stdin-control"], stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True)


def _final_summary(final_path: Path, world: subprocess.Popen) -> RunSummary:
    if not final_path.exists():
        raise RuntimeError(f"the world exited ({world.returncode}) without a final status")
    try:
        return RunSummary.from_json(final_path.read_text(encoding="utf-8"))
    except (ValueError, KeyError, TypeError) as exc:  # (the world writes it whole: a foreign or damaged file)
        raise RuntimeError(f"the world's final status {final_path} cannot be read ({exc}); the world exited "
                           f"({world.returncode})") from exc


def _on_control(fleet: Fleet):
    """The RunControl queryable: `conag kill` / `conag restart` of one agent process."""

    def on_control(query):
        try:
            req = decode(query.payload.to_bytes() if query.payload is not None else b"", RunControl)
            message = fleet.kill(req.agent_id) if req.op == "kill" else fleet.restart(req.agent_id)
            result = RunControlResult(True, message)
        except ProtocolError as exc:
            result = RunControlResult(False, f"bad request: {exc}")
        except KeyError as exc:
            result = RunControlResult(False, f"no agent {exc.args[0]!r} in this run")
        except RunEnding as exc:
            result = RunControlResult(False, str(exc))
        query.reply(query.key_expr, encode(result))
        query.drop()

    return on_control


def _stop(proc: subprocess.Popen, grace: float = 5.0) -> None:
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(grace)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(5)


def control(session, world_id: str, op: str, agent_id: str, timeout: float = 5.0) -> RunControlResult:
    """Ask a running `conag run` to kill or restart one agent."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        for reply in session.get(keys.run_control(world_id), payload=encode(RunControl(op, agent_id)),
                                 timeout=min(1.0, timeout)):
            if reply.ok is not None:
                return decode(reply.ok.payload.to_bytes(), RunControlResult)
        time.sleep(0.1)
    return RunControlResult(False, f"no `conag run` of world {world_id!r} answered within {timeout:g} s")

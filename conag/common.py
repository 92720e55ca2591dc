"""What every `conag` subcommand on the bus shares: the bus flags, one query, the status
line, stopping on signals and the CPU priority of the helper processes."""

from __future__ import annotations

import argparse
import os
import signal
import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from protocol.bus import MODES, BusOptions

# The recorder's priority (conag record --priority, conag run --record-priority): on a
# machine the run keeps busy a recorder would otherwise take its share of the CPU from the
# world and the agents (docs/results/benchmarks.md, recording overhead). It only has to keep up on
# average: zenoh queues what it has not written yet (conag/recording/recorder.py).
PRIORITIES = ("idle", "low", "normal")
RECORDER_PRIORITY = "idle"
LOW_NICE = 10  # "low": this much above the starting nice value
_STARTED: dict[str, int] = {}  # the scheduling policy the process had before `lower_priority`


def bus_args(p: argparse.ArgumentParser, *, find_run: bool = False) -> None:
    """The bus flags; with `find_run`, also --run NAME: the command talks to a `conag run`
    found by name (conag/runs.py), or to the one going when neither --run nor a bus flag is
    given."""
    g = p.add_argument_group("bus")
    if find_run:
        g.add_argument("--run", metavar="NAME",
                       help="the `conag run` to talk to, by name (default: the one going, if only one is; "
                            "else the default endpoint)")
        p.set_defaults(find_run=True)
    g.add_argument("--zenoh-config", metavar="FILE", help="a zenoh JSON5 configuration file")
    g.add_argument("--connect", metavar="ENDPOINT", action="append", default=[],
                   help="zenoh endpoint to connect to, e.g. tcp/127.0.0.1:7447 (repeatable)")
    g.add_argument("--listen", metavar="ENDPOINT", action="append", default=[],
                   help="zenoh endpoint to listen on (repeatable)")
    g.add_argument("--mode", choices=MODES, help="zenoh mode (default peer)")
    g.add_argument("--world-id", default="w0", help="which world on the bus (default w0)")


def bus_options(args) -> BusOptions:
    return BusOptions(args.zenoh_config, tuple(args.connect), tuple(args.listen), args.mode)


def query(session, key: str, payload: bytes | None, timeout: float) -> tuple[bytes | None, str | None]:
    """Ask the queryable on `key` once: (its answer, None), (None, its error text), or
    (None, None) when nothing answered within `timeout` seconds."""
    replies = list(session.get(key, payload=payload, timeout=timeout))
    for r in replies:
        if r.ok is not None:
            return r.ok.payload.to_bytes(), None
        return None, r.err.payload.to_bytes().decode(errors="replace")
    return None, None


def status_line(st) -> str:
    """One line of a WorldStatus, as `conag world` and `conag status` print it."""
    return (f"tick {st.tick:>7}  sites {st.sites_filled}/{st.sites_total}  bricks {st.bricks_total}  "
            f"agents alive {st.agents_alive}/{len(st.agent_ids)}  bad {st.bad_messages}  seq {st.seq}"
            + ("  COMPLETE" if st.completed else ""))


def ignore_repeat(_signum, _frame) -> None:
    """A signal handler for signals after the first: the process is already stopping."""


@contextmanager
def stop_on_signals(on_stop: Callable[[], object] | None = None):
    """An Event set by SIGINT or SIGTERM, so loops finish their tick and close the session;
    `on_stop` is called first (in the handler, before anything else runs)."""
    stop = threading.Event()

    def handler(_signum, _frame):
        # Later signals (a second Ctrl-C) go to a handler that does nothing, and that comes
        # first: Python runs a handler between any two bytecodes of the main thread, also
        # inside this one's `stop.set()`, whose lock is not re-entrant. Setting the Event
        # again there waited on that lock for ever (CI: `conag run` hung after two Ctrl-Cs).
        for s in previous:
            signal.signal(s, ignore_repeat)
        if on_stop is not None and not stop.is_set():
            on_stop()
        stop.set()

    previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield stop
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


class _Stopped(Exception):
    """Raised by `stopped_by_signal`'s handler, so a blocking wait ends at once."""


@contextmanager
def stopped_by_signal() -> Iterator[None]:
    """The first SIGINT/SIGTERM raises `_Stopped` where the process waits (an agent, for a
    frame), and the block ends quietly; later ones (a second Ctrl-C while closing) are let
    pass, so the cleanup finishes without a traceback. The previous handlers come back
    afterwards."""
    def raise_stop(_signum, _frame):
        for s in (signal.SIGINT, signal.SIGTERM):
            signal.signal(s, ignore_repeat)
        raise _Stopped()

    previous = {s: signal.signal(s, raise_stop) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    except _Stopped:
        pass
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


def _each_thread(apply: Callable[[int], None]) -> bool:
    """`apply(tid)` on every thread of this process (Linux keeps scheduling per thread);
    False when there is no /proc to list them (not Linux)."""
    try:
        threads = [int(t) for t in os.listdir("/proc/self/task")]
    except OSError:
        return False
    for tid in threads:
        try:
            apply(tid)
        except ProcessLookupError:
            continue  # the thread ended meanwhile
    return True


def lower_priority(level: str) -> None:
    """Lower the CPU priority of every thread of this process (threads started later inherit
    their starter's). "idle": the SCHED_IDLE policy (a thread runs when a core would
    otherwise idle); "low": nice raised by LOW_NICE; "normal": as it was. Call it before
    opening a zenoh session, so zenoh's threads start with it too."""
    if level not in PRIORITIES:
        raise ValueError(f"priority must be one of {', '.join(PRIORITIES)}, got {level!r}")
    if level == "normal":
        return
    _STARTED.setdefault("policy", os.sched_getscheduler(0))

    def lower(tid: int) -> None:
        if level == "idle":
            os.sched_setscheduler(tid, os.SCHED_IDLE, os.sched_param(0))
        else:
            os.setpriority(os.PRIO_PROCESS, tid, min(os.getpriority(os.PRIO_PROCESS, tid) + LOW_NICE, 19))

    if not _each_thread(lower):
        os.nice(LOW_NICE)  # the calling thread, which is all os.nice changes there


def restore_priority(level: str) -> bool:
    """Undo `lower_priority("idle")` on every thread: back to the policy the process had
    before (SCHED_OTHER, as a rule; one started idle, e.g. under `chrt -i 0`, stays idle).
    For a process that is stopping, or a recorder that starves: on a machine whose cores are
    all busy a SCHED_IDLE thread gets almost no CPU, and a recorder stopped there took
    longer than 5 s to finish its file (the slow tier beside a 2-job benchmark). "low" stays
    as it is: a raised nice value still gets a share, and only a privileged process may
    lower it again. Returns whether the policy changed."""
    policy = _STARTED.get("policy", os.SCHED_OTHER)
    if level != "idle" or policy == os.SCHED_IDLE:
        return False
    policy = policy if policy in (os.SCHED_OTHER, os.SCHED_BATCH) else os.SCHED_OTHER
    changed = []

    def restore(tid: int) -> None:
        try:
            os.sched_setscheduler(tid, policy, os.sched_param(0))
            changed.append(tid)
        except PermissionError:
            pass  # the system does not allow it: the thread stays idle

    _each_thread(restore)
    return bool(changed)

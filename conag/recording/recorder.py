"""The recorder process (`conag record OUT.mcap`): the zenoh shell around `conag.recording.mcap_log.McapRecorder`.

It subscribes to everything published under one world's root (`<root>/world/<id>/**`:
frames, commands, decisions, reinforcements, statuses, blueprints, agent states, the
world's welcomes and perturbations). zenoh queues them in a FIFO channel; the loop
thread takes each, stamps it with the clock and writes it, ends a chunk every `flush_every`
seconds (what a SIGKILL can lose) and, once stopped, writes on until the bus has been
quiet for `QUIET` seconds (what was still on its way), then the summary and the footer,
and renames the file into place.

Once the world's first status arrives (the world then routes its publications here too)
the recorder declares its liveliness token: `conag run --record` starts the agents only
then, so the recording holds the run from its first tick. The newest status goes into
the file's closing metadata (scenario name, seed, tick mode, ticks, completed).
With `maps_every` N, it asks the agents for their map snapshots every N ticks (a maps
request token, see agent_runtime/feeds.py), so they are recorded too.
With `foxglove` (the default), the recorded messages then go through a
`conag.foxglove.convert.Translator`, whose Foxglove channels are written beside the bus's
once the recorder is stopped (`McapRecorder.close`: during the run the recorder only
receives and writes), for at most `DERIVE_LIMIT` seconds: past that, the file says up to
which tick they go (`derived_until_tick`) and `conag record OUT --translate IN` makes them
all.

A busy machine. The world's frames reach the recorder with congestion control BLOCK: a
recorder that falls behind holds the world back, but zenoh closes the world's link to it
once a message has waited 5 s (`wait_before_close`), and the world drops a link whose
other end has been silent for that end's lease. Starved longer (an idle-priority recorder
whose cores other work keeps busy: 6 of 18 recordings at six-way load once), the recording
lacked ticks. So:

* an idle recorder whose loop went `STARVED` seconds without the CPU runs at the priority
  its process started with (normal, as a rule) from then on (`PriorityGuard`; every thread,
  zenoh's too), which gets its share of the CPU on any machine. The loop checks between
  any two messages it writes: a long drain of a backlog is work, not starving (counted
  from one turn of the loop to the next, 1-2 s drains at normal load raised the recorder in
  most runs of `bench.bench_record`, and a recorder at the normal priority slows the run it
  records by about 10%);
* its session announces a lease of `LEASE_MS` (zenoh's default is 10 s): the world and
  the agents wait that long for a silent recorder before they drop its link;
* should the link be closed all the same, zenoh connects it again by itself, and the
  recorder says so: it watches the world's liveliness token and the world's ticks
  (`conag.recording.gaps`), logs every gap as it closes, and writes the ticks it lacks
  into the recording's closing metadata (`ticks_lost`, `lost_ticks`), which `conag run
  --record`, `conag record` and `conag replay --verify` report.
"""

from __future__ import annotations

import logging
import threading
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

import zenoh

from conag.common import restore_priority
from conag.foxglove.convert import Translator
from conag.recording.gaps import WORLD_TYPES, TickGaps, format_gaps
from conag.recording.mcap_log import DEFAULT_TICK_NS, McapRecorder
from protocol import keys
from protocol.bus import Declarations, token_event
from protocol.codec import ProtocolError, decode
from protocol.messages import WorldStatus

log = logging.getLogger("conag.record")

QUEUE_DEPTH = 65_536   # samples zenoh may hold for the writer; when full, zenoh's receiving thread waits
IDLE_SLEEP = 0.050     # seconds the writer sleeps when nothing is waiting (10 ms: a tenth more of its CPU, the
                       # batches smaller; 50 ms leaves some 150 messages of a 3-agent run waiting, of QUEUE_DEPTH)
DRAIN_BATCH = 1024     # messages the loop writes before it turns again (flushes every `flush_every`, watches the world)
QUIET = 0.5            # once stopped, the recorder writes on until nothing has come for this long ...
QUIET_LIMIT = 10.0     # ... or for at most this long
STARVED = 1.0          # seconds the loop went without the CPU: an idle recorder then leaves the idle priority
DERIVE_LIMIT = 40.0    # seconds the Foxglove channels may take to write once stopped (`conag run` waits 60 for it all)
LEASE_MS = 60_000      # the recorder session's zenoh lease: how long others wait for it when it is silent


@dataclass
class RecordReport:
    """What a recorder wrote (filled in as it goes)."""

    path: Path | None = None
    messages: int = 0
    last_tick: int = 0
    status: WorldStatus | None = None   # the newest status heard
    heard_world: threading.Event = field(default_factory=threading.Event)
    gaps: TickGaps = field(default_factory=TickGaps)  # the world's ticks it did not hear
    raised: bool = False                # an idle recorder that starved and then ran at the normal priority


class PriorityGuard:
    """Keeps an idle-priority recorder from starving (see the module): called every turn of
    the loop, it puts every thread back at the priority the process started with (normal, as
    a rule: `restore_priority`) the first time a turn came `STARVED` seconds or more after
    the one before. It does not go back to idle: the machine that starved it once is busy."""

    def __init__(self, idle: bool, report: RecordReport, clock: Callable[[], float] = time.monotonic,
                 raise_priority: Callable[[], bool] = lambda: restore_priority("idle")):
        self.armed, self.report, self.clock, self.raise_priority = idle, report, clock, raise_priority
        self.last = clock()

    def turn(self) -> None:
        """The recorder got the CPU: called every turn of its loop and for every message it writes."""
        now = self.clock()
        late, self.last = now - self.last, now
        if self.armed and late >= STARVED:
            self.armed = False
            if self.raise_priority():
                self.report.raised = True
                log.warning("recorder: starved for %.1f s at the idle priority (every core busy); it runs at the "
                            "normal priority from now on, so that the world's link to it is not closed", late)
            else:  # started idle (`chrt -i 0`): what it was given is what it keeps
                log.info("recorder: starved for %.1f s; it was started at the idle priority and stays there", late)


def run_recorder(session: zenoh.Session, world_id: str, out: str | Path, stop: threading.Event, *,
                 metadata: Mapping[str, str] | None = None, tick_ns: int = DEFAULT_TICK_NS,
                 recorder_id: str = "recorder", flush_every: float = 1.0, maps_every: int = 0,
                 clock: Callable[[], int] = time.time_ns, report: RecordReport | None = None,
                 foxglove: bool = True, idle: bool = False) -> RecordReport:
    """Record world `world_id` into `out` until `stop` is set; returns (and fills in) `report`.
    `idle`: the process runs at the idle priority (`PriorityGuard` keeps it from starving)."""
    report = report if report is not None else RecordReport()
    status_key = keys.status(world_id)
    recorder = McapRecorder(out, metadata, tick_ns=tick_ns, derive=Translator().feed if foxglove else None)
    try:
        with Declarations() as declared:
            # A FIFO channel drained by this thread, not a Python callback: the callback's
            # hand-off from zenoh's thread (and a queue) cost more than writing the message.
            sub = declared.add(session.declare_subscriber(f"{keys.world_root(world_id)}/**",
                                                          zenoh.handlers.FifoChannel(QUEUE_DEPTH)))
            inbox = sub.handler
            world_token = declared.add(session.liveliness().declare_subscriber(
                keys.world_token(world_id), zenoh.handlers.FifoChannel(64), history=True)).handler
            if maps_every:  # the agents' map snapshots, every `maps_every` ticks
                declared.add(session.liveliness().declare_token(keys.maps_request_token(world_id, recorder_id,
                                                                                         maps_every)))
            last_flush = time.monotonic()
            guard = PriorityGuard(idle, report)

            def drain() -> int:
                return _drain(inbox, recorder, status_key, report, clock, guard.turn, most=DRAIN_BATCH)

            while not stop.is_set():
                guard.turn()
                _watch_world(world_token, report, world_id)
                if not drain():
                    time.sleep(IDLE_SLEEP)
                if not report.heard_world.is_set() and report.status is not None:
                    report.heard_world.set()
                    declared.add(session.liveliness().declare_token(keys.recorder_token(world_id, recorder_id)))
                    log.info("recorder %s: heard world %s", recorder_id, world_id)
                if time.monotonic() - last_flush >= flush_every:
                    recorder.flush()
                    last_flush = time.monotonic()
            # Stopped: the last messages may still be on their way (an idle recorder on a busy
            # machine reads its sockets late; the world's last frames came, an agent's last
            # commands had not): write on until the bus has been quiet for a while.
            drain_until_quiet(drain)
        # Undeclared: nothing more arrives; write what is still in the channel.
        _drain(inbox, recorder, status_key, report, clock)
    finally:
        st = report.status
        end = {} if st is None else {"scenario_name": st.scenario, "seed": st.seed, "mode": st.mode,
                                     "ticks": st.tick, "completed": st.completed}
        end.update(report.gaps.end_metadata())
        started = time.monotonic()
        report.path = recorder.close(end, derive_deadline=started + DERIVE_LIMIT)
        report.messages, report.last_tick = recorder.messages, recorder.tick
        if recorder.derive is not None:
            _say_derived(recorder, time.monotonic() - started, out)
    return report


def _say_derived(recorder: McapRecorder, seconds: float, out: str | Path) -> None:
    if recorder.derive_error:
        log.warning("recorder: making the Foxglove channels failed (%s); the bus's messages are all written, and "
                    "`conag record OUT.mcap --translate %s` tries again", recorder.derive_error, out)
    elif recorder.derived_until is None:
        log.info("recorder: wrote %d Foxglove messages in %.1f s", sum(recorder.derived.values()), seconds)
    else:
        log.warning("recorder: the Foxglove channels go up to tick %d of %d (writing them took longer than %g s); "
                    "`conag record OUT.mcap --translate %s` writes a copy with them all", recorder.derived_until,
                    recorder.tick, DERIVE_LIMIT, out)


def drain_until_quiet(drain: Callable[[], int], quiet: float = QUIET, limit: float = QUIET_LIMIT, *,
                      clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep) -> None:
    """Call `drain` (it writes what is waiting, returns how many) until it has found nothing
    for `quiet` seconds, or for `limit` seconds in all."""
    start = last = clock()
    while clock() - last < quiet and clock() - start < limit:
        if drain():
            last = clock()
        else:
            sleep(IDLE_SLEEP)


def _drain(inbox, recorder: McapRecorder, status_key: str, report: RecordReport,
           clock: Callable[[], int], turn: Callable[[], None] = lambda: None, most: int | None = None) -> int:
    """Write the samples waiting in `inbox` (at most `most`), calling `turn` before each
    (`PriorityGuard.turn`); returns how many (the channel, once closed by the undeclare and
    emptied, says so with an error: nothing is left then)."""
    n = 0
    while most is None or n < most:
        turn()
        try:
            sample = inbox.try_recv()
        except zenoh.ZError:
            return n
        if sample is None:
            return n
        _write(recorder, str(sample.key_expr), sample.payload.to_bytes(), clock(), status_key, report)
        n += 1
    return n


def _write(recorder: McapRecorder, key: str, data: bytes, t: int, status_key: str, report: RecordReport) -> None:
    name, tick = recorder.add(key, data, t)
    if key == status_key:
        try:
            report.status = decode(data, WorldStatus)
            report.gaps.lockstep = report.status.mode == "lockstep"
        except ProtocolError:
            pass  # recorded as it came; it just says nothing about the world
    if name in WORLD_TYPES and tick is not None:
        gap = report.gaps.heard(tick)
        if gap is not None:
            log.warning("recorder: the recording lacks the world's ticks %s (%d): the recorder fell behind and the "
                        "world's link to it was closed; it hears the world again at tick %d",
                        format_gaps([gap]), gap[1] - gap[0] + 1, tick)
    report.messages = recorder.messages


def _watch_world(tokens, report: RecordReport, world_id: str) -> None:
    """Take the world's liveliness token's comings and goings (see the module)."""
    while True:
        try:
            sample = tokens.try_recv()
        except zenoh.ZError:
            return
        if sample is None:
            return
        alive = token_event(sample)[1]
        if not alive and report.heard_world.is_set():
            # Not a warning: every run's world goes as the run ends. Ticks it lacks are warned of.
            log.info("recorder: world %s is gone after tick %d (it stopped or died, or its link to this recorder "
                     "was closed); recording on when it is back", world_id, report.gaps.newest)
        report.gaps.token(alive)

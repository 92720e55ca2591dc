"""Replaying a recording on the bus (`conag replay FILE.mcap`): the zenoh shells around `conag.recording.replay`.

`publish_recording` re-publishes recorded messages on their keys, paced as recorded (or
faster, slower, at once: `conag.recording.replay.paced`), like `ros2 bag play`: a viewer or
`conag echo` sees the run again. It waits (up to `wait` seconds) for a subscriber to
match one of its publishers before it starts. As the agents did, it answers a query on an
agent's decision key with the newest Decision it has re-published there (a live viewer
asks for the shown agent's that way).

`drive_world` reproduces a recording with a live world in lockstep (a fresh world from
the recorded scenario and seed): it declares each recorded agent's liveliness token and
attaches it at its recorded tick, applies the recorded perturbations before their tick's
step, sends each recorded command at the tick the world was at when it first came
(`conag.recording.replay.LockstepScript`), and compares each frame the world sends with the recorded one, byte for byte
(`conag.recording.replay.Comparison`): a frame the recorder missed is not a difference.
"""

from __future__ import annotations

import logging
import os
import threading
import time
from collections.abc import Callable, Iterable

import zenoh

from conag.recording.mcap_log import Entry
from conag.recording.replay import Comparison, LockstepScript, paced
from protocol import keys
from protocol.bus import Declarations, Inbox
from protocol.codec import ProtocolError, decode, encode
from protocol.messages import Hello, LockstepTimeout, PerturbResult, SensorFrame

log = logging.getLogger("conag.replay")


def publish_recording(session: zenoh.Session, entries: list[Entry], stop: threading.Event, *, rate: float = 1.0,
                      from_tick: int = 0, wait: float = 2.0, clock: Callable[[], float] = time.monotonic,
                      on_message: Callable[[Entry], None] | None = None) -> int:
    """Re-publish `entries` on their keys (see the module); returns how many went out."""
    sent = 0
    with Declarations() as declared:
        publishers = {key: declared.add(session.declare_publisher(
            key, reliability=zenoh.Reliability.RELIABLE, congestion_control=zenoh.CongestionControl.BLOCK))
            for key in dict.fromkeys(e.key for e in entries if e.tick >= from_tick)}
        # The last Decision re-published on each decision key (None: none yet), to answer queries.
        newest: dict[str, bytes | None] = {key: None for key in publishers if key.endswith("/decision")}
        for key in newest:
            declared.add(session.declare_queryable(key, _answer_with_newest(key, newest)))
        deadline = clock() + wait
        while clock() < deadline and not stop.is_set() and not any(
                p.matching_status.matching for p in publishers.values()):
            stop.wait(0.02)
        start = clock()
        for due, entry in paced(entries, rate, from_tick):
            delay = start + due - clock()
            if delay > 0 and stop.wait(delay):
                break
            if stop.is_set():
                break
            publishers[entry.key].put(entry.data)
            if entry.key in newest:
                newest[entry.key] = entry.data
            sent += 1
            if on_message is not None:
                on_message(entry)
    return sent


def _answer_with_newest(key: str, newest: dict[str, bytes | None]) -> Callable[[zenoh.Query], None]:
    def answer(query: zenoh.Query) -> None:
        data = newest.get(key)
        if data is not None:
            query.reply(key, data)

    return answer


DROP_GRACE = 2.0  # seconds to wait for the rest of a tick's frames once one has come


class DriveError(RuntimeError):
    """The world did not answer in time (no attach reply, no frame)."""


def drive_world(session: zenoh.Session, script: LockstepScript, world_id: str, stop: threading.Event | None = None,
                *, timeout: float = 10.0, to_tick: int | None = None,
                on_tick: Callable[[int], None] | None = None, tokens: Iterable[str] = ()) -> Comparison:
    """Feed a lockstep world the recorded attaches, perturbations and commands from the
    script's first tick up to `to_tick` (default: the recording's last), comparing its frames
    (see the module). `tokens`: agents whose liveliness tokens the caller has declared on
    `session` already (those of a resumed world, declared before it starts)."""
    stop = stop or threading.Event()
    last = script.last_tick if to_tick is None else min(to_tick, script.last_tick)
    result = Comparison()
    with Declarations() as declared:
        frames = declared.add(Inbox(1 << 16).subscribe(session, keys.all_agents(world_id, "sensors")))
        timeouts = declared.add(Inbox(1024).subscribe(session, keys.lockstep_timeouts(world_id)))
        commands: dict[str, zenoh.Publisher] = {}
        have_token = set(tokens)
        for tick in range(script.first_tick, last + 2):   # the frames of last + 1 answer the commands of last
            if tick == last + 1 and not script.commands.get(last):
                # None there (a recording cut short after the attaches, before any command):
                # the world cannot step, and its frames of last + 1 would be waited for in vain.
                break
            # The step to `tick` (the world takes it once every attached agent's command came,
            # or after its lockstep timeout where the recording holds none), then the attaches
            # and perturbations of `tick`, each as the world met them, then the commands.
            ok = _collect(frames, script, dict.fromkeys(commands, tick), result, timeout, stop)
            if _timed_out(timeouts, script, result) or not ok:
                break
            if tick > last:
                break
            if not _feed_tick(session, script, world_id, tick, commands, declared, frames, result, timeout, stop,
                              have_token):
                break
            if on_tick is not None:
                on_tick(tick)
    result.settle()
    return result


def _feed_tick(session: zenoh.Session, script: LockstepScript, world_id: str, tick: int,
               commands: dict[str, zenoh.Publisher], declared: Declarations, frames: Inbox, result: Comparison,
               timeout: float, stop: threading.Event, have_token: set[str]) -> bool:
    """The attaches, perturbations and commands of `tick`, as the world met them; False if an
    attach's frame did not come (stopped, or a bad frame)."""
    for welcome in script.attaches.get(tick, ()):
        a = welcome.agent_id
        if a not in commands:
            if a not in have_token:
                declared.add(session.liveliness().declare_token(keys.agent_token(world_id, a)))
                have_token.add(a)
            commands[a] = declared.add(session.declare_publisher(
                keys.command(world_id, a), reliability=zenoh.Reliability.RELIABLE,
                congestion_control=zenoh.CongestionControl.BLOCK))
        _attach(session, world_id, a, timeout)
        if not _collect(frames, script, {a: tick}, result, timeout, stop):
            return False
    for p in script.perturbations.get(tick, ()):
        _perturb(session, world_id, p, timeout)
    for cmd in script.commands.get(tick, ()):
        if cmd.agent_id in commands:
            commands[cmd.agent_id].put(encode(cmd))
    return True


def _timed_out(timeouts: Inbox, script: LockstepScript, result: Comparison) -> bool:
    """Whether the replayed world stepped without a command where the recorded one did not
    (this process fell a lockstep timeout behind: the replay can no longer be exact)."""
    while (sample := timeouts.get(0)) is not None:
        try:
            t = decode(sample.payload.to_bytes(), LockstepTimeout)
        except ProtocolError:
            continue
        extra = [a for a in t.agent_ids if (t.tick, a) not in script.missed]
        if extra:
            result.first_difference = (
                f"the replayed world stepped from tick {t.tick} without the command of {', '.join(extra)}: its "
                "lockstep timeout passed before the replay sent it (this machine too busy?)")
            return True
    return False


def _attach(session: zenoh.Session, world_id: str, agent: str, timeout: float) -> None:
    """Attach `agent` (its token is declared); retry until the world has seen the token."""
    hello = encode(Hello(agent, os.getpid()))
    deadline = time.monotonic() + timeout
    error = "no world answered"
    while time.monotonic() < deadline:
        # One Hello at a time, answered or refused: a Hello sent again while a slow world is still
        # on the first one would be answered twice, and each attach draws on the world's generator.
        wait = max(deadline - time.monotonic(), 0.1)
        for reply in session.get(keys.attach(world_id, agent), payload=hello, timeout=wait):
            if reply.ok is not None:
                return
            error = reply.err.payload.to_bytes().decode(errors="replace")
        time.sleep(0.02)  # the world has not seen the token yet: ask again
    raise DriveError(f"could not attach {agent} to world {world_id}: {error}")


def _perturb(session: zenoh.Session, world_id: str, p, timeout: float) -> None:
    for reply in session.get(keys.perturb(world_id), payload=encode(p), timeout=timeout):
        if reply.ok is not None:
            decode(reply.ok.payload.to_bytes(), PerturbResult)
            return
    raise DriveError(f"world {world_id} did not answer the perturbation {p}")


def _collect(frames: Inbox, script: LockstepScript, pending: dict[str, int], result: Comparison,
             timeout: float, stop: threading.Event) -> bool:
    """Take frames until every attached agent's frame of its pending tick has come, comparing
    each; False at the first difference (or when stopped)."""
    waiting = set(pending)
    deadline = time.monotonic() + timeout
    while waiting:
        if stop.is_set():
            return False
        sample = frames.get(min(0.1, max(deadline - time.monotonic(), 0)))
        if sample is None:
            if len(waiting) < len(pending) and time.monotonic() >= deadline - timeout + DROP_GRACE:
                # The world sent this tick's frames together and some came: the rest were dropped
                # on the way (frames are "latest wins", congestion control DROP). Not compared.
                result.dropped += len(waiting)
                return True
            if time.monotonic() >= deadline:
                raise DriveError(f"no frame for tick {min(pending.values())} from the world within {timeout:g} s "
                                 f"(waiting for {', '.join(sorted(waiting))})")
            continue
        data = sample.payload.to_bytes()
        try:
            frame = decode(data, SensorFrame)
        except ProtocolError as exc:
            result.first_difference = result.first_difference or f"the world sent a bad frame: {exc}"
            return False
        if not result.check(frame.tick, frame.agent_id, data, script.frames.get((frame.tick, frame.agent_id), [])):
            return False
        if pending.get(frame.agent_id) == frame.tick:
            waiting.discard(frame.agent_id)
    return True


def entries_for(entries: Iterable[Entry], world_id: str) -> list[Entry]:
    """The entries published under world `world_id`'s root."""
    root = keys.world_root(world_id) + "/"
    return [e for e in entries if e.key.startswith(root)]

"""`conag echo KEY_EXPR`: the zenoh shell around `conag.recording.echo`.

Subscribes to any key expression (`conag/v8/world/w0/agent/a1/command`, or a wildcard),
and prints each message decoded (`conag.recording.echo.describe`) or, with `hz`, a rate line
every `period` seconds instead (`conag.recording.echo.RateMeter`, like `ros2 topic hz`).
Samples are queued by zenoh's callback and printed by the caller's thread, so output is
never interleaved; `once` stops after the first message.
"""

from __future__ import annotations

import queue
import threading
import time
from collections.abc import Callable

import zenoh

from conag.recording.echo import RateMeter, describe
from protocol.bus import Declarations


def run_echo(session: zenoh.Session, key_expr: str, stop: threading.Event, *, once: bool = False,
             as_json: bool = False, hz: bool = False, period: float = 1.0, window: int = 1000,
             out: Callable[[str], None] = print, clock: Callable[[], float] = time.monotonic) -> int:
    """Echo `key_expr` until `stop` is set (or after one message with `once`); returns the
    number of messages seen."""
    samples: queue.SimpleQueue = queue.SimpleQueue()
    meter = RateMeter(window)
    next_report = clock() + period
    with Declarations() as declared:
        declared.add(session.declare_subscriber(
            key_expr, lambda s: samples.put((str(s.key_expr), s.payload.to_bytes(), clock()))))
        while not stop.is_set():
            try:
                key, data, t = samples.get(timeout=min(0.1, period))
            except queue.Empty:
                key = None
            if key is not None:
                meter.add(t)
                if not hz:
                    out(describe(key, data, as_json))
                    if once:
                        break
            if hz and clock() >= next_report:
                rate = meter.rate()
                out(rate.line() if rate is not None else f"no rate yet ({meter.count} messages on {key_expr})")
                next_report = clock() + period
                if once and rate is not None:
                    break
    return meter.count

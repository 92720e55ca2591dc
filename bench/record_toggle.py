"""A recorder that listens and stops listening in turns: `bench.bench_record_windows` puts a
copy of this file beside a `sitecustomize` on a run's PYTHONPATH, which makes it the run's
recorder (`conag.recording.recorder.run_recorder`) in the recorder's process. It uses only
what the tree under test has (its recorder's parts), so either side of a side-by-side run
can take it; nothing in the product knows of it.

Once the world is past `START_TICK`, windows of `$CONAG_BENCH_WINDOW` seconds take turns: the
first without a subscription to the world's keys, the next with one (its messages written as
a recorder writes them), and so on. The world's views and statuses are subscribed to all
along; each view's arrival time and tick, and the windows, go to `$CONAG_BENCH_WINDOWS` (JSON)
as the recorder stops.
"""

from __future__ import annotations

import json
import os
import threading
import time
from collections.abc import Mapping
from pathlib import Path

ENV_OUT = "CONAG_BENCH_WINDOWS"       # where the windows go (JSON)
ENV_WINDOW = "CONAG_BENCH_WINDOW"     # seconds per window
START_TICK = 100                      # the first window opens once the world is past this tick


def toggled_recorder(session, world_id: str, out, stop: threading.Event, *, metadata: Mapping[str, str] | None = None,
                     tick_ns: int | None = None, recorder_id: str = "recorder", report=None, foxglove: bool = True,
                     idle: bool = False, **_ignored):
    """`run_recorder` (the same arguments) that takes turns listening (see the module)."""
    import zenoh

    from conag.foxglove.convert import Translator
    from conag.recording import recorder as r
    from conag.recording.mcap_log import DEFAULT_TICK_NS, McapRecorder, peek
    from protocol import keys
    from protocol.codec import decode
    from protocol.messages import WorldStatus

    window = float(os.environ.get(ENV_WINDOW, "1.0"))
    report = report if report is not None else r.RecordReport()
    status_key = keys.status(world_id)
    rec = McapRecorder(out, metadata, tick_ns=tick_ns or DEFAULT_TICK_NS,
                       derive=Translator().feed if foxglove else None)
    views: list[tuple[float, int]] = []   # (monotonic time, tick) of each view heard
    heard = threading.Event()

    def on_view(sample) -> None:
        tick = peek(sample.payload.to_bytes())[1]
        if tick is not None:
            views.append((time.monotonic(), tick))

    def on_status(sample) -> None:  # the newest status goes into the file's closing metadata, as always
        report.status = decode(sample.payload.to_bytes(), WorldStatus)
        heard.set()

    windows: list[dict] = []
    subs = [session.declare_subscriber(keys.view(world_id), on_view),
            session.declare_subscriber(status_key, on_status)]
    token = listening = None
    guard = r.PriorityGuard(idle, report)
    opened = last_flush = 0.0
    try:
        while not stop.is_set():
            guard.turn()
            now = time.monotonic()
            if token is None and heard.is_set():
                token = session.liveliness().declare_token(keys.recorder_token(world_id, recorder_id))
            ticking = bool(views) and views[-1][1] >= START_TICK
            if ticking and not opened:
                opened = now          # the first window: without the recorder
            elif opened and now >= opened + window:
                windows.append({"start": opened, "end": now, "listening": listening is not None})
                if listening is not None:
                    inbox = listening.handler
                    listening.undeclare()   # what is still in its channel is written, as a recorder would
                    r._drain(inbox, rec, status_key, report, time.time_ns)
                    listening = None
                else:
                    listening = session.declare_subscriber(f"{keys.world_root(world_id)}/**",
                                                           zenoh.handlers.FifoChannel(r.QUEUE_DEPTH))
                opened = now
            written = 0 if listening is None else r._drain(listening.handler, rec, status_key, report, time.time_ns,
                                                            guard.turn, most=r.DRAIN_BATCH)
            if not written:
                time.sleep(r.IDLE_SLEEP)
            if now - last_flush >= 1.0:
                rec.flush()
                last_flush = now
    finally:
        for s in [*subs, *([listening] if listening is not None else []), *([token] if token is not None else [])]:
            try:
                s.undeclare()
            except zenoh.ZError:  # the session is closing
                pass
        Path(os.environ[ENV_OUT]).write_text(json.dumps({"windows": windows, "views": views}), encoding="utf-8")
        st = report.status
        end = {} if st is None else {"scenario_name": st.scenario, "seed": st.seed, "mode": st.mode, "ticks": st.tick,
                                     "completed": st.completed}
        report.path = rec.close({**end, "bench": "toggled"})
        report.messages, report.last_tick = rec.messages, rec.tick
    return report

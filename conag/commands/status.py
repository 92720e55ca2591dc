"""`conag status`: print what a running world reports, once or (--watch) as it changes."""

from __future__ import annotations

import argparse
import json
import sys
import threading
import time
from dataclasses import asdict
from typing import cast

from conag.common import bus_args, bus_options, query, status_line, stop_on_signals
from protocol import keys
from protocol.bus import Declarations, open_session
from protocol.codec import ProtocolError, decode
from protocol.messages import WorldStatus


def configure(s: argparse.ArgumentParser) -> None:
    s.add_argument("--watch", action="store_true", help="keep printing each status update")
    s.add_argument("--json", action="store_true", help="print the status as JSON")
    s.add_argument("--timeout", type=float, default=5.0, help="seconds to wait for the world")
    bus_args(s, find_run=True)


def run(args: argparse.Namespace) -> int:
    shown: list[WorldStatus | None] = [None]  # the last status printed
    lock = threading.Lock()

    def show(st: WorldStatus) -> None:
        # The query's answer and the subscription's samples can arrive in either order:
        # print a status only if it is newer than the last one printed (WorldStatus.seq).
        with lock:
            if not is_newer_status(st, shown[0]):
                return
            shown[0] = st
            print(json.dumps(asdict(st)) if args.json else status_line(st), flush=True)

    session = open_session(bus_options(args))
    try:
        deadline = time.monotonic() + args.timeout
        data = None
        while data is None and time.monotonic() < deadline:
            data, _ = query(session, keys.status(args.world_id), None, min(1.0, args.timeout))
        if data is None:
            print(f"error: no world {args.world_id!r} answered within {args.timeout:g} s", file=sys.stderr)
            return 1
        try:
            show(cast(WorldStatus, decode(data, WorldStatus)))
        except ProtocolError as exc:
            print(f"error: the world sent a bad status: {exc}", file=sys.stderr)
            return 1
        if args.watch:
            with stop_on_signals() as stop:
                def on_status(sample) -> None:
                    try:
                        show(cast(WorldStatus, decode(sample.payload.to_bytes(), WorldStatus)))
                    except ProtocolError as exc:
                        print(f"warning: ignored a bad status: {exc}", file=sys.stderr)

                with Declarations() as declared:
                    declared.add(session.declare_subscriber(keys.status(args.world_id), on_status))
                    stop.wait()
        return 0
    finally:
        session.close()


def is_newer_status(st: WorldStatus, last: WorldStatus | None) -> bool:
    """Whether status `st` is newer than `last` (None: nothing seen yet). Within one world's
    run `seq` grows by one per publication; a lower tick as well means the world was started
    again, whose statuses count from 1 anew."""
    return last is None or st.seq > last.seq or st.tick < last.tick

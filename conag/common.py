"""What every `conag` subcommand on the bus shares: the bus flags, and stopping on signals."""

from __future__ import annotations

import argparse
import signal
import threading
from contextlib import contextmanager

from bus import MODES, BusOptions


def bus_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("bus")
    g.add_argument("--zenoh-config", metavar="FILE", help="a zenoh JSON5 configuration file")
    g.add_argument("--connect", metavar="ENDPOINT", action="append", default=[],
                   help="zenoh endpoint to connect to, e.g. tcp/127.0.0.1:7447 (repeatable)")
    g.add_argument("--listen", metavar="ENDPOINT", action="append", default=[],
                   help="zenoh endpoint to listen on (repeatable)")
    g.add_argument("--mode", choices=MODES, help="zenoh mode (default peer)")
    g.add_argument("--world-id", default="w0", help="which world on the bus (default w0)")


def bus_options(args) -> BusOptions:
    return BusOptions(args.zenoh_config, tuple(args.connect), tuple(args.listen), args.mode)


@contextmanager
def stop_on_signals():
    """An Event set by SIGINT or SIGTERM, so loops finish their tick and close the session."""
    stop = threading.Event()

    def handler(_signum, _frame):
        stop.set()

    previous = {s: signal.signal(s, handler) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield stop
    finally:
        for s, h in previous.items():
            signal.signal(s, h)

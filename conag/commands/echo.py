"""`conag echo KEY_EXPR`: print the decoded messages on a key (relative to the world's root),
or their rate (--hz). The shell is `conag/recording/echo_node.py`."""

from __future__ import annotations

import argparse

from conag.common import bus_args, bus_options, stop_on_signals
from conag.recording.echo_node import run_echo
from protocol import keys
from protocol.bus import open_session


def configure(e: argparse.ArgumentParser) -> None:
    e.add_argument("key", metavar="KEY_EXPR",
                   help="e.g. 'agent/a1/command', 'agent/*/sensors' or '**' (relative to the world's root, "
                        f"{keys.ROOT}/world/<id>/), or a full key starting with conag/")
    e.add_argument("--once", action="store_true", help="stop after the first message (with --hz: the first rate)")
    e.add_argument("--json", action="store_true", help="one JSON object per message")
    e.add_argument("--hz", action="store_true", help="print the rate of the messages instead, like ros2 topic hz")
    e.add_argument("--period", type=float, default=1.0, metavar="S", help="seconds between rate lines (default 1)")
    e.add_argument("--window", type=int, default=1000, metavar="N", help="messages the rate is taken over")
    bus_args(e, find_run=True)


def echo_key(key: str, world_id: str) -> str:
    """A key expression as `conag echo` takes it: relative to the world's root unless it
    starts with conag/."""
    return key if key.startswith("conag/") else f"{keys.world_root(world_id)}/{key.lstrip('/')}"


def run(args: argparse.Namespace) -> int:
    key = echo_key(args.key, args.world_id)
    with stop_on_signals() as stop:
        session = open_session(bus_options(args))
        try:
            run_echo(session, key, stop, once=args.once, as_json=args.json, hz=args.hz, period=args.period,
                     window=args.window, out=lambda line: print(line, flush=True))
        finally:
            session.close()
    return 0

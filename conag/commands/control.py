"""`conag kill ID` and `conag restart ID`: kill, or kill and start again, one agent process
of a running `conag run` (the subcommand's name is the request)."""

from __future__ import annotations

import argparse
import sys

from conag.common import bus_args, bus_options
from conag.run import control
from protocol.bus import open_session


def configure(k: argparse.ArgumentParser) -> None:
    k.add_argument("id", help="agent id, e.g. a2")
    k.add_argument("--timeout", type=float, default=5.0)
    bus_args(k, find_run=True)


def run(args: argparse.Namespace) -> int:
    session = open_session(bus_options(args))
    try:
        result = control(session, args.world_id, args.command, args.id, args.timeout)
    finally:
        session.close()
    print(result.message, file=sys.stdout if result.ok else sys.stderr)
    return 0 if result.ok else 1

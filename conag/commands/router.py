"""`conag router`: run a zenoh router, for worlds and agents on several hosts."""

from __future__ import annotations

import argparse

from conag.common import stop_on_signals
from protocol.bus import BusOptions, open_session

DEFAULT_LISTEN = "tcp/127.0.0.1:7447"  # without --listen or a config file: loopback only


def configure(z: argparse.ArgumentParser) -> None:
    z.add_argument("--zenoh-config", metavar="FILE")
    z.add_argument("--listen", action="append", default=[], metavar="ENDPOINT")
    z.add_argument("--connect", action="append", default=[], metavar="ENDPOINT")


def run(args: argparse.Namespace) -> int:
    # The loopback default applies only without a config file: it must not replace the file's endpoints.
    listen = tuple(args.listen) or (() if args.zenoh_config else (DEFAULT_LISTEN,))
    opts = BusOptions(args.zenoh_config, tuple(args.connect), listen, "router")
    with stop_on_signals() as stop:
        session = open_session(opts, serve=True)
        try:
            where = ", ".join(opts.listen) or f"the endpoints in {args.zenoh_config}"
            print(f"zenoh router listening on {where}", flush=True)
            stop.wait()
        finally:
            session.close()
    return 0

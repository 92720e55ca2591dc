"""`conag agents --ids a1..a20`: several agents in one process, each its own token and state."""

from __future__ import annotations

import argparse
import sys

from agent_runtime.host import AgentHost, host_options, parse_ids, read_stop_requests
from agent_runtime.node import AgentOptions
from agent_runtime.world_link import AttachError
from conag.agent_settings import AgentSettings, add_attach_args, add_correction_args, add_kind_args
from conag.common import bus_args, bus_options, stopped_by_signal
from protocol.bus import open_session

DESCRIPTION = ("Several agents in one process: the interpreter and the compiled kernels are loaded once (less "
               "memory, quicker start-up); the agents take turns on one core, and a crash of the process takes "
               "them all. A line `stop ID` on stdin (with --stdin-control) stops one agent alone.")


def configure(a: argparse.ArgumentParser) -> None:
    a.description = DESCRIPTION
    a.add_argument("--ids", required=True, metavar="IDS", help="agent ids: ranges and commas, e.g. a1..a20 or a1,a3")
    a.add_argument("--seed", type=int, default=0, help="seed of every agent's own randomness (as conag agent)")
    add_attach_args(a)
    a.add_argument("--map-size", type=int, default=AgentSettings.map_size, metavar="N",
                   help=f"cells per side of the agents' maps, odd (default {AgentSettings.map_size})")
    a.add_argument("--nearest-first", action="store_true", help="no goal sequencing (as conag agent)")
    add_kind_args(a)
    add_correction_args(a)
    a.add_argument("--stdin-control", action="store_true",
                   help="read `stop ID` lines on stdin: stop that agent alone (conag run uses it for conag kill)")
    bus_args(a)


def run(args: argparse.Namespace) -> int:
    ids = parse_ids(args.ids)
    base = AgentOptions(args.world_id, ids[0], AgentSettings.from_args(args).config(), args.seed,
                        attach_timeout=args.attach_timeout, recorded=args.recorded)

    with stopped_by_signal():
        session = open_session(bus_options(args), leaf=True)
        try:
            host = AgentHost(session, host_options(base, ids))
            try:
                if args.stdin_control:
                    read_stop_requests(host)
                host.attach()
                host.serve()
            except AttachError as exc:
                print(f"error: {exc}", file=sys.stderr)
                return 1
            finally:
                host.close()
        finally:
            session.close()
    return 0

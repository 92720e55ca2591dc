"""`conag perturb OP`: remove, add or move a disc, add or remove a drop site, in a running world."""

from __future__ import annotations

import argparse
import sys
import time
from typing import cast

from conag.argtypes import point
from conag.common import bus_args, bus_options, query
from conag.exit_codes import EXIT_USAGE
from protocol import keys
from protocol.bus import open_session
from protocol.codec import ProtocolError, decode, encode
from protocol.messages import Perturbation, PerturbResult


def configure(q: argparse.ArgumentParser) -> None:
    q.add_argument("op", choices=("remove", "add", "move", "add-site", "remove-site"),
                   help="add-site: the cell holding --at becomes a drop site; remove-site: its site leaves "
                        "the blueprint (a brick on it stays, a free brick now)")
    q.add_argument("--at", type=point, required=True, metavar="X,Y", help="world position (cell centres are at .5)")
    q.add_argument("--to", type=point, metavar="X,Y", help="target position for move")
    q.add_argument("--kind", choices=("food", "water", "brick"), default="brick", help="kind for add")
    q.add_argument("--force", action="store_true",
                   help="add even in a drop site's cell (a brick there fills the site) or onto an agent's body")
    q.add_argument("--timeout", type=float, default=5.0, help="seconds to wait for the world")
    bus_args(q, find_run=True)


def run(args: argparse.Namespace) -> int:
    if args.op == "move" and args.to is None:
        print("error: move needs --to X,Y", file=sys.stderr)
        return EXIT_USAGE
    to = args.to or (0.0, 0.0)
    msg = Perturbation(args.op.replace("-", "_"), args.at[0], args.at[1], args.kind, to[0], to[1], args.force)
    session = open_session(bus_options(args))
    try:
        deadline = time.monotonic() + args.timeout
        data = err = None
        while data is None and err is None and time.monotonic() < deadline:
            data, err = query(session, keys.perturb(args.world_id), encode(msg), min(1.0, args.timeout))
    finally:
        session.close()
    if err:
        print(f"error: {err}", file=sys.stderr)
        return 1
    if data is None:
        print(f"error: no world {args.world_id!r} answered within {args.timeout:g} s", file=sys.stderr)
        return 1
    try:
        result = cast(PerturbResult, decode(data, PerturbResult))
    except ProtocolError as exc:
        print(f"error: bad reply: {exc}", file=sys.stderr)
        return 1
    print(f"tick {result.tick}: {result.message}")
    return 0 if result.ok else 1

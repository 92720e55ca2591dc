"""`conag keys OUTDIR`: write a secure deployment, a router with access control and one
credential per process (`protocol.bus.deployment`; `conag run --secure` uses one).

    conag keys OUTDIR --agents N [--world-id W] [--router tcp/HOST:7447] [--router-listen EP]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from conag.exit_codes import EXIT_USAGE
from conag.secure import agent_ids
from protocol.bus.deployment import DEFAULT_ROUTER, ROUTER_FILE, DeploymentSpec, client_file, users, write_deployment

HELP = "write a secure deployment: a router with access control and one credential per process"


def configure(k: argparse.ArgumentParser) -> None:
    k.description = HELP + " (files 0600; see deploy/README.md)"
    k.add_argument("outdir", metavar="OUTDIR", help="directory to write (created 0700)")
    k.add_argument("--agents", type=int, default=3, metavar="N", help="agent ids a1..aN (default 3)")
    k.add_argument("--agent-id", action="append", default=[], metavar="ID",
                   help="an agent id of its own (repeatable; instead of a1..aN)")
    k.add_argument("--world-id", default="w0", help="the world these credentials are for (default w0)")
    k.add_argument("--router", default=DEFAULT_ROUTER, metavar="ENDPOINT",
                   help=f"where the clients connect (default {DEFAULT_ROUTER}; e.g. tcp/ROUTER_HOST:7447)")
    k.add_argument("--router-listen", metavar="ENDPOINT",
                   help="where the router listens (default: --router; e.g. tcp/0.0.0.0:7447 for several hosts)")
    k.add_argument("--force", action="store_true", help="replace a deployment already in OUTDIR")


def run(args: argparse.Namespace) -> int:
    if args.agents < 1 and not args.agent_id:
        raise ValueError("--agents must be at least 1")
    spec = DeploymentSpec(tuple(args.agent_id) or agent_ids(args.agents), args.world_id, args.router,
                          args.router_listen)
    try:
        manifest = write_deployment(args.outdir, spec, force=args.force)
    except FileExistsError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    out = Path(args.outdir)
    print(f"wrote a secure deployment for world {spec.world_id} to {out}/ (files 0600):")
    print(f"  {ROUTER_FILE} + {manifest['dictionary_file']}: the router, listening on {manifest['listen']}")
    for user in users(spec):
        print(f"  {client_file(user)}: {user}")
    print(f"start the router:  conag router --zenoh-config {out / ROUTER_FILE}")
    print(f"then each process: conag agent --id a1 --zenoh-config {out / client_file('agent-a1')}  (and so on)")
    return 0

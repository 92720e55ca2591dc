"""`conag keys OUTDIR` and the secure bus of `conag run --secure`.

    conag keys OUTDIR --agents N [--world-id W] [--router tcp/HOST:7447] [--router-listen EP]

writes a deployment (`protocol.bus.deployment`): a router configuration with user/password
authentication and the access control of `protocol.bus.acl`, its credentials dictionary, and one
client configuration per process (world, teacher, operator, observer, agent-a1..aN), all
0600. `conag run --secure [DIR]` uses one (DIR, or a fresh one in the run's temporary
directory): it starts `conag router` with it on the run's endpoint and starts every process
as a client of that router with its own credential; its own session (progress, stall watch,
`conag kill` / `restart`) is the operator.
"""

from __future__ import annotations

import json
import subprocess
import sys
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import replace
from pathlib import Path

from protocol.bus import BusOptions, make_config
from protocol.bus.acl import OPERATOR, agent_user
from protocol.bus.deployment import (
    DEFAULT_ROUTER,
    ROUTER_FILE,
    DeploymentSpec,
    client_file,
    read_manifest,
    users,
    write_deployment,
)

KEYS_HELP = "write a secure deployment: a router with access control and one credential per process"


def add_commands(sub) -> None:
    """Register `keys` on the main parser's subparsers."""
    k = sub.add_parser("keys", help=KEYS_HELP, description=KEYS_HELP + " (files 0600; see deploy/README.md)")
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
    k.set_defaults(func=cmd_keys)


def agent_ids(n: int) -> tuple[str, ...]:
    """The ids `conag run` gives its agents: a1..aN."""
    return tuple(f"a{i + 1}" for i in range(n))


def cmd_keys(args) -> int:
    if args.agents < 1 and not args.agent_id:
        raise ValueError("--agents must be at least 1")
    spec = DeploymentSpec(tuple(args.agent_id) or agent_ids(args.agents), args.world_id, args.router,
                          args.router_listen)
    try:
        manifest = write_deployment(args.outdir, spec, force=args.force)
    except FileExistsError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2  # a usage error, as the CLI's others
    out = Path(args.outdir)
    print(f"wrote a secure deployment for world {spec.world_id} to {out}/ (files 0600):")
    print(f"  {ROUTER_FILE} + {manifest['dictionary_file']}: the router, listening on {manifest['listen']}")
    for user in users(spec):
        print(f"  {client_file(user)}: {user}")
    print(f"start the router:  conag router --zenoh-config {out / ROUTER_FILE}")
    print(f"then each process: conag agent --id a1 --zenoh-config {out / client_file('agent-a1')}  (and so on)")
    return 0


def check_agent_credential(zenoh_config: str | None, agent_id: str) -> None:
    """Refuse (ValueError) a configuration file holding another agent's credential than
    `agent_id`'s: the router would silently drop everything the agent does."""
    if not zenoh_config:
        return
    user = json.loads(make_config(BusOptions(zenoh_config=zenoh_config)).get_json("transport/auth/usrpwd/user"))
    if isinstance(user, str) and user.startswith("agent-") and user != agent_user(agent_id):
        raise ValueError(f"{zenoh_config} holds the credential of {user}, not of {agent_user(agent_id)}: "
                         f"on a secure bus agent {agent_id} must use its own")


def bus_flags(opts, user: str, *, world: bool = False) -> list[str]:
    """The bus flags of a process `conag run` starts as `user`: on a secure run its own
    credential file and the router's endpoint; otherwise loopback peers (the world listens
    on the run's endpoint, everyone else connects to it)."""
    if opts.secure is None:
        return ["--listen" if world else "--connect", opts.endpoint]
    return ["--zenoh-config", str(Path(opts.secure) / client_file(user)), "--connect", opts.endpoint]


def run_bus_options(opts) -> BusOptions:
    """The options of `conag run`'s own session: the operator on a secure run."""
    if opts.secure is None:
        return BusOptions(connect=(opts.endpoint,))
    return BusOptions(zenoh_config=str(Path(opts.secure) / client_file(OPERATOR)), connect=(opts.endpoint,))


def _deployment_for(opts, n_agents: int, tmp: Path) -> Path:
    """The deployment directory of a secure run: `opts.secure`, checked to cover the run's
    world and agents, or a fresh one in `tmp` when `opts.secure` is empty."""
    wanted = agent_ids(n_agents)
    if not opts.secure:
        out = tmp / "keys"
        write_deployment(out, DeploymentSpec(wanted, opts.world_id, opts.endpoint))
        return out
    manifest = read_manifest(opts.secure)
    if manifest.get("world_id") != opts.world_id:
        raise ValueError(f"{opts.secure} holds credentials for world {manifest.get('world_id')!r}, "
                         f"not {opts.world_id!r}")
    missing = [a for a in wanted if a not in manifest.get("agents", [])]
    if missing:
        raise ValueError(f"{opts.secure} holds no credentials for agent(s) {', '.join(missing)} "
                         f"(conag keys {opts.secure} --agents {n_agents} --force)")
    return Path(opts.secure)


def start_router(config: Path, endpoint: str) -> subprocess.Popen:
    """`conag router --zenoh-config config --listen endpoint`, once it says it listens."""
    proc = subprocess.Popen([sys.executable, "-m", "conag", "router", "--zenoh-config", str(config),
                             "--listen", endpoint], stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, text=True)
    line = proc.stdout.readline() if proc.stdout is not None else ""  # the router prints one line, then waits
    if "listening" not in line:
        stop_router(proc)
        raise RuntimeError(f"the secure router did not start on {endpoint} (exit {proc.returncode})")
    return proc


def stop_router(proc: subprocess.Popen, grace: float = 5.0) -> None:
    if proc.poll() is None:
        proc.terminate()
    try:
        proc.wait(grace)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait(5)
    if proc.stdout is not None:
        proc.stdout.close()


@contextmanager
def secure_bus(opts, n_agents: int, tmp: Path) -> Iterator:
    """The run's options on the bus they use: unchanged without `opts.secure`; else with
    `secure` set to the deployment in use and its router running on `opts.endpoint` until
    the block ends (after every other process of the run has stopped)."""
    if opts.secure is None:
        yield opts
        return
    deployment = _deployment_for(opts, n_agents, tmp)
    router = start_router(deployment / ROUTER_FILE, opts.endpoint)
    try:
        if not opts.quiet:
            where = ("fresh credentials, deleted with the run" if not opts.secure else
                     f"conag kill/restart need --zenoh-config {deployment / client_file(OPERATOR)}")
            print(f"secure bus: router on {opts.endpoint}, every process its own credential ({where})", flush=True)
        yield replace(opts, secure=str(deployment))
    finally:
        stop_router(router)

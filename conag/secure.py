"""The secure bus of `conag run --secure`, and the agent's check of its credential.

`conag keys OUTDIR` (`conag.commands.keys`) writes a deployment (`protocol.bus.deployment`):
a router configuration with user/password authentication and the access control of
`protocol.bus.acl`, its credentials dictionary, and one client configuration per process
(world, teacher, operator, observer, agent-a1..aN), all 0600. `conag run --secure [DIR]`
uses one (DIR, or a fresh one in the run's temporary directory): it starts `conag router`
with it on the run's endpoint and starts every process as a client of that router with its
own credential; its own session (progress, stall watch, `conag kill` / `restart`) is the
operator.
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
    ROUTER_FILE,
    DeploymentSpec,
    client_file,
    read_manifest,
    write_deployment,
)


def agent_ids(n: int) -> tuple[str, ...]:
    """The ids `conag run` gives its agents: a1..aN."""
    return tuple(f"a{i + 1}" for i in range(n))


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

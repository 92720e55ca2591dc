"""How every ConAg process opens its zenoh session.

One host, no server to install (the default): the world listens on DEFAULT_ENDPOINT in
peer mode and every other process connects to it as a peer, listening on a free
loopback port so that peers can also reach each other (gossip scouting, no multicast);
agent processes only accept such links, they open none (`LEAF_AUTOCONNECT`).
(`conag run` gives its world a free endpoint of its own instead: conag/runs.py.) A world
asked to listen where another process does fails at once with `EndpointInUse`.
Several hosts: pass `--zenoh-config deploy/multi-host/client.json5` (or `--connect
tcp/ROUTER:7447 --mode client`) to every process and run a zenoh router.
Sessions are opened inside the process that uses them, never before a fork.

A router gets more receive workers than zenoh's 2 (`ROUTER_RUNTIME`, through zenoh's
`ZENOH_RUNTIME` variable, unless it is set already): when a client's host is cut off and
its link is closed with bytes still unsent, the close blocks a receive worker for up to
10 s (SO_LINGER, fixed when zenoh is compiled; zenoh issue #1101). With two agents on the
cut host that took both workers, and the router routed nothing at all, the world's own
traffic included, until the link came back (docs/results/reliability.md, "Partition survived").
"""

from __future__ import annotations

import json
import os
import re
import threading
import time
from dataclasses import dataclass

CALLBACK_THREAD = "(pyo3-closure)"   # how zenoh-python names the thread that runs a Python callback
DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
MODES = ("peer", "client", "router")
ROUTER_RUNTIME = "(rx: (worker_threads: 16))"
# An agent process connects to the world (its connect endpoint) and to routers, never to the
# other agents gossip tells it of: nothing flows between agents, and N agent peers that all
# connect to each other make N^2 links (100 agent processes: about 10,000 sockets, each with
# its buffers and keep-alives, and a minute of connecting before the first tick). The
# processes that do want an agent's messages (recorder, teacher, viewer, the run's
# supervisor) still connect to it: their sessions keep zenoh's default.
LEAF_AUTOCONNECT = '["router"]'



@dataclass(frozen=True)
class BusOptions:
    """What the command line says about the bus; `None` means the role's default."""

    zenoh_config: str | None = None
    connect: tuple[str, ...] = ()
    listen: tuple[str, ...] = ()
    mode: str | None = None


CONNECT_RETRY = {"period_init_ms": 100, "period_max_ms": 1000, "period_increase_factor": 2}


def make_config(opts: BusOptions, *, serve: bool = False, leaf: bool = False, lease_ms: int | None = None):
    """A zenoh.Config for a process; `serve` is True for the world (it listens by default),
    `leaf` for an agent process (see LEAF_AUTOCONNECT; a configuration file is taken as it is).
    `lease_ms`: the link lease the session announces (zenoh's default 10 s), how long the
    processes linked to it wait for it when it is silent (a starved recorder's)."""
    import zenoh

    if opts.zenoh_config:
        config = zenoh.Config.from_file(opts.zenoh_config)
        _resolve_dictionary(config, opts.zenoh_config)
        if opts.connect:
            config.insert_json5("connect/endpoints", json.dumps(list(opts.connect)))
        if opts.listen:
            config.insert_json5("listen/endpoints", json.dumps(list(opts.listen)))
        if opts.mode:
            config.insert_json5("mode", json.dumps(opts.mode))
        _set_lease(config, lease_ms)
        return config
    mode = opts.mode or "peer"
    if mode not in MODES:
        raise ValueError(f"unknown zenoh mode {mode!r}; expected one of {', '.join(MODES)}")
    if serve:
        listen = list(opts.listen) or ([] if opts.connect else [DEFAULT_ENDPOINT])
        connect = list(opts.connect)
    else:
        listen = list(opts.listen) or (["tcp/127.0.0.1:0"] if mode == "peer" else [])
        connect = list(opts.connect) or [DEFAULT_ENDPOINT]
    config = zenoh.Config()
    config.insert_json5("mode", json.dumps(mode))
    config.insert_json5("scouting/multicast/enabled", "false")
    config.insert_json5("listen/endpoints", json.dumps(listen))
    config.insert_json5("connect/endpoints", json.dumps(connect))
    if mode == "client":
        config.insert_json5("listen/endpoints", "[]")
    if leaf and mode == "peer":
        config.insert_json5("scouting/gossip/autoconnect", LEAF_AUTOCONNECT)
    # A process started beside the world (conag run starts them together) may find it not yet
    # listening: try again within a tenth of a second, not after zenoh's 1 s, 2 s, 4 s backoff,
    # by which time a short lockstep build can be over.
    config.insert_json5("connect/retry", json.dumps(CONNECT_RETRY))
    _set_lease(config, lease_ms)
    return config


def _set_lease(config, lease_ms: int | None) -> None:
    if lease_ms is not None:
        config.insert_json5("transport/link/tx/lease", json.dumps(int(lease_ms)))


def is_client(opts: BusOptions, *, serve: bool = False) -> bool:
    """Whether these options make a zenoh client (of a router: a multi-host or secure bus)."""
    return json.loads(make_config(opts, serve=serve).get_json("mode")) == "client"


def _resolve_dictionary(config, path: str) -> None:
    """A relative user/password `dictionary_file` (a secure router's, `protocol.bus.deployment`) is
    relative to its configuration file, not to wherever the router is started from."""
    value = json.loads(config.get_json("transport/auth/usrpwd/dictionary_file"))
    if isinstance(value, str) and value and not os.path.isabs(value):
        resolved = os.path.join(os.path.dirname(os.path.abspath(path)), value)
        config.insert_json5("transport/auth/usrpwd/dictionary_file", json.dumps(resolved))


class EndpointInUse(ValueError):
    """A session could not listen where it was asked to: something listens there already."""


def open_session(opts: BusOptions, *, serve: bool = False, leaf: bool = False, lease_ms: int | None = None):
    """Open a zenoh session (quiet logs unless RUST_LOG says otherwise); `serve`, `leaf` and
    `lease_ms` as in `make_config`. EndpointInUse, naming the endpoint, where another process
    listens already (zenoh's ZError otherwise)."""
    import zenoh

    if opts.mode == "router":
        # Read once, when zenoh first starts its receive runtime: before the first session.
        os.environ.setdefault("ZENOH_RUNTIME", ROUTER_RUNTIME)
    zenoh.init_log_from_env_or("error")
    try:
        return zenoh.open(make_config(opts, serve=serve, leaf=leaf, lease_ms=lease_ms))
    except zenoh.ZError as exc:
        m = re.search(r"listener bound to (\S+?): \[.*Address already in use", str(exc))
        if m is None:
            raise
        raise EndpointInUse(f"cannot listen on {m.group(1)}: another process listens there (another world or "
                            "`conag run`?); choose another endpoint with --listen") from None


def join_callback_threads(timeout: float = 2.0) -> bool:
    """Wait (up to `timeout` seconds in all) for zenoh's callback threads to end, once their
    sessions are closed; False if some did not. Call it before a process whose callbacks
    were declared from a daemon thread exits.

    zenoh-python runs each Python callback (a subscriber's, a queryable's) in a Python thread
    of its own, started when the callback is declared, and a Python thread is a daemon if its
    starter is: a WorldServer running in a daemon thread (`conag replay --verify`, the Gym
    env) makes daemon callback threads, which Python's exit does not wait for. One woken by
    its closed session while the interpreter was finalising could not take the GIL and was
    unwound through zenoh's Rust frames: the process aborted ("FATAL: exception not
    rethrown", exit 134) after its work was done.
    """
    deadline = time.monotonic() + timeout
    for thread in threading.enumerate():
        if thread is not threading.current_thread() and thread.name.endswith(CALLBACK_THREAD):
            thread.join(max(deadline - time.monotonic(), 0.0))
    return not any(t.is_alive() and t.name.endswith(CALLBACK_THREAD) for t in threading.enumerate())

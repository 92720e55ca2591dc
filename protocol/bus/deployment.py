"""A secure deployment on disk: a router with the ACL, and one credential per process.

`write_deployment(outdir, spec)` writes (files with secrets 0600, the directory 0700):

* `router.json5`: a zenoh router listening on `spec.listen`, multicast and gossip scouting
  off, user/password authentication against `credentials.txt`, and the access control of
  `protocol.bus.acl` (default deny);
* `credentials.txt`: the router's dictionary, one `user:password` line per identity (zenoh
  reads it in plain text: keep it on the router's host only);
* one client configuration per identity, `<user>.json5` (`world.json5`, `teacher.json5`,
  `operator.json5`, `observer.json5`, `agent-a1.json5`, ...): client mode, connecting to
  `spec.router`, scouting off, with the identity's user name and password. Hand each
  process its own file only (`--zenoh-config FILE`); `--connect` may still replace the
  router's address;
* `deployment.json`: what was generated (world id, agents, endpoints, which file is whose),
  no secrets.

Passwords come from `secrets.token_urlsafe` (injectable for tests). The router's
`dictionary_file` is written relative to the router file; `protocol.bus.session.make_config`
resolves it against the file's directory, so the directory can be moved or copied whole.
"""

from __future__ import annotations

import json
import os
import secrets
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from protocol import keys
from protocol.bus.acl import OBSERVER, OPERATOR, TEACHER, WORLD, access_control, agent_user, roles

ROUTER_FILE = "router.json5"
DICTIONARY_FILE = "credentials.txt"
MANIFEST_FILE = "deployment.json"
DEFAULT_ROUTER = "tcp/127.0.0.1:7447"


@dataclass(frozen=True)
class DeploymentSpec:
    """What to generate: the world, its agents, where the router is and where it listens."""

    agents: tuple[str, ...]
    world_id: str = "w0"
    router: str = DEFAULT_ROUTER      # what clients connect to
    listen: str | None = None         # what the router listens on (None: `router`)

    def __post_init__(self) -> None:
        keys.check_id(self.world_id, "world id")
        for a in self.agents:
            keys.check_id(a, "agent id")
        if len(set(self.agents)) != len(self.agents):
            raise ValueError("agent ids must be distinct")


def users(spec: DeploymentSpec) -> tuple[str, ...]:
    """Every identity's user name, in the order the files are written."""
    return (WORLD, TEACHER, OPERATOR, OBSERVER, *(agent_user(a) for a in spec.agents))


def client_file(user: str) -> str:
    """The file name of `user`'s client configuration inside a deployment directory."""
    return f"{user}.json5"


def _scouting_off() -> dict:
    # No multicast, no gossip: nobody finds anybody but the router it is told to connect to.
    return {"multicast": {"enabled": False}, "gossip": {"enabled": False}}


def router_config(spec: DeploymentSpec, password: str) -> dict:
    """The router's configuration: listen, scouting off, the dictionary, the ACL."""
    return {
        "mode": "router",
        "listen": {"endpoints": [spec.listen or spec.router]},
        "connect": {"endpoints": []},
        "scouting": _scouting_off(),
        "transport": {"auth": {"usrpwd": {"user": "router", "password": password,
                                          "dictionary_file": DICTIONARY_FILE}}},
        "access_control": access_control(roles(spec.world_id, spec.agents)),
    }


def client_config(spec: DeploymentSpec, user: str, password: str) -> dict:
    """`user`'s client configuration: connect to the router with its credential, scouting off."""
    return {
        "mode": "client",
        "connect": {"endpoints": [spec.router]},
        "listen": {"endpoints": []},
        "scouting": _scouting_off(),
        "transport": {"auth": {"usrpwd": {"user": user, "password": password}}},
    }


def _write_private(path: Path, text: str) -> None:
    """Write `text` to a new file readable by its owner only (0600 from the start)."""
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w", encoding="utf-8") as f:
        f.write(text)
    os.chmod(path, 0o600)  # O_CREAT's mode does not apply to a file that was already there


def _json5(comment: str, config: dict) -> str:
    return f"// {comment}\n{json.dumps(config, indent=2)}\n"


def write_deployment(outdir: str | Path, spec: DeploymentSpec, *, force: bool = False,
                     password: Callable[[], str] = lambda: secrets.token_urlsafe(24)) -> dict:
    """Write a deployment to `outdir` (see the module); returns the manifest. Refuses a
    directory that already holds one unless `force`."""
    out = Path(outdir)
    if (out / MANIFEST_FILE).exists() and not force:
        raise FileExistsError(f"{out} already holds a deployment ({MANIFEST_FILE}); pass --force to replace it")
    out.mkdir(parents=True, exist_ok=True)
    os.chmod(out, 0o700)
    passwords = {user: password() for user in users(spec)}
    for user, pw in passwords.items():
        if not pw or any(c in pw for c in ":\n\r"):
            raise ValueError(f"password for {user} is empty or holds ':' or a line break")
    _write_private(out / DICTIONARY_FILE, "".join(f"{u}:{pw}\n" for u, pw in passwords.items()))
    _write_private(out / ROUTER_FILE, _json5(
        f"ConAg secure router for world {spec.world_id}: conag router --zenoh-config {ROUTER_FILE}",
        router_config(spec, password())))
    for user, pw in passwords.items():
        _write_private(out / client_file(user), _json5(
            f"ConAg identity {user!r}: give this file to that process only (--zenoh-config)",
            client_config(spec, user, pw)))
    manifest = {"format": "conag-deployment", "version": 1, "world_id": spec.world_id,
                "agents": list(spec.agents), "router": spec.router, "listen": spec.listen or spec.router,
                "router_file": ROUTER_FILE, "dictionary_file": DICTIONARY_FILE,
                "clients": {u: client_file(u) for u in users(spec)}}
    (out / MANIFEST_FILE).write_text(json.dumps(manifest, indent=2) + "\n", encoding="utf-8")
    return manifest


def read_manifest(outdir: str | Path) -> dict:
    """The manifest of the deployment in `outdir` (ValueError if it is not one)."""
    path = Path(outdir) / MANIFEST_FILE
    try:
        manifest = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ValueError(f"{outdir} holds no deployment ({MANIFEST_FILE} missing; make one with conag keys)") from None
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not JSON: {exc}") from None
    if not isinstance(manifest, dict) or manifest.get("format") != "conag-deployment":
        raise ValueError(f"{path}: not a conag deployment manifest")
    return manifest

"""Runs on this machine, by name: where `conag run` registers, and how the verbs find a run.

Each `conag run` listens on a loopback endpoint of its own (a free port, unless --listen
names one), so two runs on one machine never exchange a message. While it runs it is
registered as `NAME.json` in the runs directory (`$CONAG_RUNS_DIR`, else
`/tmp/conag-UID/runs`): its name (the scenario's, `-2`, `-3`... while that is taken,
or --name), endpoint, world id, scenario and pid. A file whose process is gone is stale
and skipped (and removed).

The verbs that talk to a run (status, kill, restart, perturb, record, view, echo) take
`--run NAME`. Without it, and without bus flags (--connect, --listen, --zenoh-config),
they use the one run going; with several going they list them and ask for a name; with
none, the default endpoint (a `conag world` started alone listens there).
"""

from __future__ import annotations

import errno
import json
import os
import re
import socket
from dataclasses import asdict, dataclass
from pathlib import Path

_NAME = re.compile(r"^[A-Za-z0-9_.\-]{1,64}\Z")


class RunNotFound(ValueError):
    """No run by that name, or no name among several runs (the message lists them)."""


@dataclass(frozen=True)
class RunEntry:
    """One registered run."""

    name: str
    endpoint: str
    world_id: str
    scenario: str
    pid: int

    def describe(self) -> str:
        return f"{self.name} ({self.scenario}, world {self.world_id} on {self.endpoint}, pid {self.pid})"


def runs_dir() -> Path:
    """Where runs register: $CONAG_RUNS_DIR, else /tmp/conag-UID/runs (not $TMPDIR: a run
    started with another TMPDIR is still found)."""
    env = os.environ.get("CONAG_RUNS_DIR")
    return Path(env) if env else Path("/tmp") / f"conag-{os.getuid()}" / "runs"


def _make_dir(directory: Path) -> None:
    """Create the runs directory, private to this user; ValueError if someone else owns it."""
    directory.mkdir(parents=True, exist_ok=True, mode=0o700)
    if directory.stat().st_uid != os.getuid():
        raise ValueError(f"{directory} belongs to another user: set CONAG_RUNS_DIR to a directory of yours")


def check_name(name: str) -> str:
    """`name` if it can name a run (1-64 of A-Z a-z 0-9 _ . -), else ValueError."""
    if not _NAME.match(name):
        raise ValueError(f"invalid run name {name!r}: expected 1-64 characters from A-Z a-z 0-9 _ . -")
    return name


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True  # someone else's process: it exists
    return True


def _read(path: Path) -> RunEntry | None:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
        return RunEntry(str(data["name"]), str(data["endpoint"]), str(data["world_id"]), str(data["scenario"]),
                        int(data["pid"]))
    except (OSError, ValueError, KeyError, TypeError):
        return None  # being written, or not ours: not a run


def register(name: str, endpoint: str, world_id: str, scenario: str, pid: int | None = None,
             directory: Path | None = None, *, exact: bool = False) -> RunEntry:
    """Register a run as `name`, or (unless `exact`) as `name-2`, `name-3`... while a live
    run holds it; ValueError if `exact` and it is taken. Created exclusively: two runs
    started at once get two names."""
    directory = directory or runs_dir()
    _make_dir(directory)
    pid = os.getpid() if pid is None else pid
    check_name(name)
    for n in range(1, 1000):
        candidate = name if n == 1 else f"{name}-{n}"
        path = directory / f"{candidate}.json"
        entry = RunEntry(candidate, endpoint, world_id, scenario, pid)
        for _ in range(2):  # a stale file is removed, then the name tried once more
            try:
                with open(path, "x", encoding="utf-8") as f:
                    json.dump(asdict(entry), f)
                return entry
            except FileExistsError:
                held = _read(path)
                if held is not None and _alive(held.pid):
                    break
                if held is None and path.exists():
                    break  # being written by a run starting now
                path.unlink(missing_ok=True)
        if exact:
            raise ValueError(f"a run named {name!r} is going already: choose another --name")
    raise ValueError(f"too many runs named {name!r}")


def unregister(entry: RunEntry, directory: Path | None = None) -> None:
    """Remove the run's file (only if it is still this run's)."""
    path = (directory or runs_dir()) / f"{entry.name}.json"
    if _read(path) == entry:
        path.unlink(missing_ok=True)


def live_runs(directory: Path | None = None) -> list[RunEntry]:
    """The runs going, by name; files of runs whose process is gone are removed."""
    directory = directory or runs_dir()
    out = []
    for path in sorted(directory.glob("*.json")) if directory.is_dir() else []:
        entry = _read(path)
        if entry is None:
            continue
        if _alive(entry.pid):
            out.append(entry)
        else:
            path.unlink(missing_ok=True)
    return sorted(out, key=lambda e: e.name)


def find_run(name: str | None, directory: Path | None = None) -> RunEntry | None:
    """The run named `name`; with no name, the one run going (None if none is). RunNotFound,
    saying which runs there are, for a name no run has or for no name among several."""
    runs = live_runs(directory)
    if name is not None:
        for entry in runs:
            if entry.name == name:
                return entry
        going = "; ".join(e.describe() for e in runs) or "none"
        raise RunNotFound(f"no run named {name!r} is going (runs: {going})")
    if len(runs) > 1:
        raise RunNotFound(f"{len(runs)} runs are going: " + "; ".join(e.describe() for e in runs)
                          + ". Name one with --run NAME")
    return runs[0] if runs else None


def apply_run(args) -> RunEntry | None:
    """Point a verb's bus flags at the run it means (see the module): `args.connect` and
    `args.world_id` (left alone if --world-id named another than w0) are set from the run
    named by `args.run`, or the one run going. Returns it (None: the flags as given)."""
    name = getattr(args, "run", None)
    explicit = bool(args.connect or args.listen or args.zenoh_config)
    if explicit:
        if name is not None:
            raise ValueError("--run cannot be used with --connect, --listen or --zenoh-config")
        return None
    entry = find_run(name)
    if entry is not None:
        args.connect = [entry.endpoint]
        if args.world_id == "w0":
            args.world_id = entry.world_id
    return entry


def free_endpoint(host: str = "127.0.0.1") -> str:
    """A TCP endpoint on a port free now (the kernel's choice)."""
    with socket.socket() as s:
        s.bind((host, 0))
        return f"tcp/{host}:{s.getsockname()[1]}"


def endpoint_in_use(endpoint: str) -> bool:
    """Whether something listens on a `tcp/HOST:PORT` endpoint of this machine now (False for
    any other kind of endpoint: zenoh says so itself when it opens)."""
    m = re.match(r"^tcp/(\[[^\]]+\]|[^:/]+):(\d+)$", endpoint)
    if not m or m.group(2) == "0":
        return False
    host = m.group(1).strip("[]")
    family = socket.AF_INET6 if ":" in host else socket.AF_INET
    with socket.socket(family, socket.SOCK_STREAM) as s:
        # As a listener binds: a port with only closed connections of a dead process is free.
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            s.bind((host, int(m.group(2))))
        except OSError as exc:
            return exc.errno == errno.EADDRINUSE
    return False

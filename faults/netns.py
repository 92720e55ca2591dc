"""Hosts on one machine: Linux network namespaces joined by veth links to a bridge.

`Hosts(prefix, n)` stands for `n` machines on one switch: namespace `<prefix>1` (the hub)
holds a bridge with address `<subnet>.1/24`; each other namespace `<prefix>k` has one
interface `eth0` with `<subnet>.k/24`, a veth link whose other end (`h<k>`) is a port of
the bridge. Everything lives inside the namespaces it creates: nothing is added to the
machine's own network namespace, so the subnet cannot clash with the machine's, and
deleting the namespaces removes every link. `cut(k)` sets the hub's end of host k's
link down (host k hears nothing and is heard by no one, as with a pulled cable);
`restore(k)` sets it up again.

Creating namespaces needs root (CAP_SYS_ADMIN and CAP_NET_ADMIN) and iproute2's `ip`;
`unavailable()` says why they cannot be made here, or None. Used by `faults.partition`.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import time


class NetnsError(RuntimeError):
    """An `ip` command failed."""


def _ip(*args: str) -> None:
    done = subprocess.run(["ip", *args], check=False, capture_output=True, text=True, timeout=30)
    if done.returncode != 0:
        raise NetnsError(f"ip {' '.join(args)}: {done.stderr.strip() or f'exit {done.returncode}'}")


def unavailable() -> str | None:
    """Why network namespaces cannot be created here (None: they can): not root, no `ip`, or
    the kernel or a container refuses (tried with a namespace made and deleted at once)."""
    if os.geteuid() != 0:
        return "network namespaces need root (ip netns add)"
    if shutil.which("ip") is None:
        return "no `ip` command (iproute2) on PATH"
    probe = f"conag-probe-{os.getpid()}"
    try:
        _ip("netns", "add", probe)
    except (NetnsError, OSError) as exc:
        return f"cannot create a network namespace: {exc}"
    try:
        _ip("-n", probe, "link", "add", "p0", "type", "veth", "peer", "name", "p1")
    except NetnsError as exc:
        return f"cannot create a veth link: {exc}"
    finally:
        _ip("netns", "del", probe)
    return None


class Hosts:
    """`n` namespaces on one bridge (see the module); a context manager that deletes them."""

    def __init__(self, prefix: str, n: int = 3, subnet: str = "10.231.0"):
        if n < 2:
            raise ValueError("Hosts needs a hub and at least one more host")
        self.prefix, self.n, self.subnet = prefix, n, subnet
        self.names = [f"{prefix}{k}" for k in range(1, n + 1)]
        self._made: list[str] = []

    def name(self, k: int) -> str:
        """Namespace of host `k` (1 is the hub)."""
        return self.names[k - 1]

    def address(self, k: int) -> str:
        """IPv4 address of host `k` (the hub's is its bridge's)."""
        return f"{self.subnet}.{k}"

    def create(self) -> Hosts:
        """Make the namespaces, the bridge and the links; on failure, remove what was made."""
        try:
            for name in self.names:
                _ip("netns", "add", name)
                self._made.append(name)
                _ip("-n", name, "link", "set", "lo", "up")
            hub = self.names[0]
            _ip("-n", hub, "link", "add", "br0", "type", "bridge")
            _ip("-n", hub, "addr", "add", f"{self.address(1)}/24", "dev", "br0")
            _ip("-n", hub, "link", "set", "br0", "up")
            for k in range(2, self.n + 1):
                # Both ends are created straight inside their namespaces.
                _ip("-n", hub, "link", "add", f"h{k}", "type", "veth", "peer", "name", "eth0", "netns", self.name(k))
                _ip("-n", hub, "link", "set", f"h{k}", "master", "br0")
                _ip("-n", hub, "link", "set", f"h{k}", "up")
                _ip("-n", self.name(k), "addr", "add", f"{self.address(k)}/24", "dev", "eth0")
                _ip("-n", self.name(k), "link", "set", "eth0", "up")
        except BaseException:
            self.delete()
            raise
        return self

    def argv(self, k: int, argv: list[str]) -> list[str]:
        """`argv` run inside host `k`'s namespace."""
        return ["ip", "netns", "exec", self.name(k), *argv]

    def cut(self, k: int) -> None:
        """Pull host `k`'s cable: the hub's end of its link goes down."""
        _ip("-n", self.name(1), "link", "set", f"h{k}", "down")

    def restore(self, k: int) -> None:
        """Plug host `k`'s cable back in."""
        _ip("-n", self.name(1), "link", "set", f"h{k}", "up")

    def delete(self) -> None:
        """Kill whatever still runs in the namespaces made here, then delete them (their links
        go with them). Never raises: it runs on the way out of a failure too."""
        for name in self._made:
            for pid in self._pids(name):
                try:
                    os.kill(pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
        for name in reversed(self._made):
            for _ in range(50):  # a namespace whose last process is still exiting may refuse at first
                try:
                    _ip("netns", "del", name)
                    break
                except (NetnsError, OSError):
                    time.sleep(0.1)
        self._made = []

    @staticmethod
    def _pids(name: str) -> list[int]:
        done = subprocess.run(["ip", "netns", "pids", name], check=False, capture_output=True, text=True,
                              timeout=30)
        return [int(p) for p in done.stdout.split()] if done.returncode == 0 else []

    def __enter__(self) -> Hosts:
        return self.create()

    def __exit__(self, *exc) -> None:
        self.delete()

"""A world process fed thousands of malformed messages (issue 12: "keep that as a test").

A `conag world` process in realtime mode (it ticks with no agent) gets random garbage on
every key it listens to: commands (of an attached-looking id and of others), agent states,
attach and perturb queries; payloads from a few bytes to 10 MB, random bytes and msgpack
shapes that are no ConAg message. Every one must be counted in `bad_messages` and ignored:
the world keeps ticking, its memory plateaus (the second half of the fuzz does not grow it
further than the first did), and a good perturbation still works afterwards.
"""

from __future__ import annotations

import signal
import subprocess
import sys

import msgpack
import numpy as np
import pytest
import zenoh

from protocol import keys
from protocol.bus import BusOptions, open_session
from protocol.codec import decode, encode
from protocol.messages import Perturbation, PerturbResult, WorldStatus
from tests.conftest import ROOT, free_port, wait_until

HALF = 4200            # messages per half of the fuzz
HUGE = 10_000_000      # bytes of the few largest payloads


def _payload(rng: np.random.Generator) -> bytes:
    """Garbage that is no ConAg message: random bytes (of a size spread from 1 B to 1 MB) or
    msgpack values of the wrong shape."""
    kind = rng.integers(4)
    if kind == 0:
        return rng.bytes(int(10 ** rng.uniform(0, 6)))
    if kind == 1:
        return msgpack.packb([int(x) for x in rng.integers(0, 1000, rng.integers(0, 50))])
    if kind == 2:
        return msgpack.packb({"v": int(rng.integers(0, 200)), "t": "AgentCommand", "f": rng.bytes(8)})
    return msgpack.packb({"t": rng.bytes(int(rng.integers(1, 30))), "f": None})


def _rss_mb(pid: int) -> float:
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    raise RuntimeError("no VmRSS")


def _status(session: zenoh.Session) -> WorldStatus | None:
    for reply in session.get(keys.status("w0"), timeout=10.0):
        if reply.ok is not None:
            return decode(reply.ok.payload.to_bytes(), WorldStatus)
    return None


def _fuzz(session: zenoh.Session, rng: np.random.Generator, n: int, huge: int) -> int:
    """Send `n` garbage messages (`huge` of them HUGE bytes); returns how many the world must count."""
    block = zenoh.CongestionControl.BLOCK  # the point is what the world does with each, not the bus
    counted = 0
    for i in range(n):
        data = rng.bytes(HUGE) if i < huge else _payload(rng)
        target = rng.integers(5)
        if target < 4:
            agent = "a1" if target == 0 else f"x{int(rng.integers(1000))}"
            key = keys.command("w0", agent) if target < 3 else keys.agent_state("w0", agent)
            session.put(key, data, congestion_control=block)
        else:
            query = keys.attach("w0", "a1") if rng.random() < 0.5 else keys.perturb("w0")
            replies = list(session.get(query, payload=data, timeout=15.0))
            assert replies and replies[0].err is not None, "the world accepted garbage"
        counted += 1
    return counted


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_a_world_fed_thousands_of_malformed_messages_counts_them_keeps_ticking_and_plateaus(tmp_path):
    endpoint = f"tcp/127.0.0.1:{free_port()}"
    world = subprocess.Popen([sys.executable, "-m", "conag", "world", "scenarios/quick_wall.toml", "--tick-mode",
                              "realtime", "--quiet", "--listen", endpoint], cwd=ROOT, stdout=subprocess.DEVNULL)
    session = open_session(BusOptions(connect=(endpoint,)))
    rng = np.random.default_rng(12)
    try:
        first = wait_until(lambda: _status(session), 60, what="the world's first status")
        expected = _fuzz(session, rng, HALF, huge=3)
        wait_until(lambda: (s := _status(session)) and s.bad_messages >= expected, 120,
                   what=f"{expected} bad messages counted")
        after_first = _rss_mb(world.pid)
        expected += _fuzz(session, rng, HALF, huge=3)
        status = wait_until(lambda: (s := _status(session)) and s.bad_messages >= expected and s, 120,
                            what=f"{expected} bad messages counted")
        after_second = _rss_mb(world.pid)
        print(f"fuzz: {expected} malformed messages counted; world RSS {after_first:.0f} MB after the first half, "
              f"{after_second:.0f} MB after the second; ticks {first.tick} -> {status.tick}")
        assert status.bad_messages == expected  # every one counted, nothing else
        assert status.tick > first.tick  # it kept ticking
        # Memory plateaus: the second half costs no more than a margin over the first.
        assert after_second <= after_first + 50, f"RSS {after_first:.0f} MB -> {after_second:.0f} MB"
        reply = list(session.get(keys.perturb("w0"), payload=encode(Perturbation("add", 0.5, 0.5, "food")),
                                 timeout=15.0))
        assert reply[0].ok is not None and decode(reply[0].ok.payload.to_bytes(), PerturbResult).ok
        assert world.poll() is None
    finally:
        session.close()
        world.send_signal(signal.SIGTERM)
        try:
            world.wait(30)
        except subprocess.TimeoutExpired:
            world.kill()
            world.wait(10)

"""A Foxglove WebSocket client that watches everything: bench/bench_view.py's `--foxglove` page.

    python3 -m bench.foxglove_client ws://127.0.0.1:8766 [--seconds S] [--world-only]

Subscribes to every channel the server advertises, as it advertises them (as a Foxglove or
Lichtblick layout with every topic shown would; with `--world-only`, the world's topics
alone: the scene, walls, poses, log and progress, no agent's scans or maps), and receives their messages until stopped
(SIGTERM, Ctrl-C, or after S seconds); then prints how many messages and bytes came per
topic group. It decodes nothing: the CPU it takes is the transport's, a real app's rendering
is not modelled.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import time
from collections import Counter

from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

SUBPROTOCOL = "foxglove.sdk.v1"


def watch(url: str, seconds: float, world_only: bool = False) -> Counter:
    """Subscribe to everything at `url` (or its world's topics) for `seconds`; messages and
    bytes per topic group."""
    got: Counter = Counter()
    topics: dict[int, str] = {}
    deadline = time.monotonic() + seconds
    with connect(url, subprotocols=[SUBPROTOCOL], open_timeout=30, max_size=None) as ws:
        try:
            while time.monotonic() < deadline:
                try:
                    m = ws.recv(timeout=0.5)
                except TimeoutError:
                    continue
                if isinstance(m, str):
                    op = json.loads(m)
                    if op["op"] == "advertise":
                        subs = []
                        for c in op["channels"]:
                            if world_only and c["topic"].startswith("/agents/"):
                                continue
                            topics[c["id"]] = c["topic"]
                            subs.append({"id": c["id"], "channelId": c["id"]})
                        if subs:
                            ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))
                elif m[0] == 1:
                    group = topics.get(int.from_bytes(m[1:5], "little"), "?").split("/")
                    key = "/".join(group[:2] if group[1] != "agents" else ["", "agents", "*", group[3]])
                    got[key + " messages"] += 1
                    got[key + " bytes"] += len(m)
        except ConnectionClosed:
            pass
    return got


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("url")
    p.add_argument("--seconds", type=float, default=float("inf"))
    p.add_argument("--world-only", action="store_true", help="no agent's scans or maps")
    args = p.parse_args(argv)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(0))
    got: Counter = Counter()
    try:
        got = watch(args.url, args.seconds, args.world_only)
    finally:
        for key, n in sorted(got.items()):
            print(f"{key}: {n}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""A scripted test controller: a few lines that drive one body through the bus.

It knows its pose only as an agent would: the Welcome pose plus the odometry of every
frame (dead reckoning). Run as a module it is a separate agent process for the tests
that kill processes: `python -m tests.scripted --connect EP --id a1 --grab-at X,Y`.
"""

from __future__ import annotations

import argparse
import math
import sys

from agent_runtime.world_link import WorldLink
from protocol.bus import BusOptions, open_session


class ScriptedBody:
    def __init__(self, link: WorldLink, timeout: float = 10.0):
        self.link = link
        self.welcome = link.attach(timeout=timeout)
        self.x, self.y = self.welcome.x, self.welcome.y
        self.frame = link.next_frame(self.welcome.tick - 1, timeout=timeout)
        assert self.frame is not None, "no sensor frame after attach"

    def act(self, speed: float = 0.0, turn: float = 0.0, action: str = "none"):
        """Send one command for the current frame and wait for the next frame."""
        self.link.send(self.frame.tick, speed, turn, action)
        frame = self.link.next_frame(self.frame.tick, timeout=10.0)
        assert frame is not None, f"no frame after tick {self.frame.tick}"
        self.x += frame.odom_dx
        self.y += frame.odom_dy
        self.frame = frame
        return frame

    def drive_to(self, x: float, y: float, tol: float = 0.1, max_ticks: int = 400) -> bool:
        """Turn towards (x, y) and go, slowing down near it; True once within `tol`."""
        for _ in range(max_ticks):
            dx, dy = x - self.x, y - self.y
            dist = math.hypot(dx, dy)
            if dist < tol:
                self.stop()
                return True
            err = (math.atan2(dy, dx) - self.frame.heading + math.pi) % (2 * math.pi) - math.pi
            # Slow enough near the goal that inertia does not carry the body past it.
            speed = 0.0 if abs(err) > 0.5 else min(3.0, 1.5 * dist)
            self.act(speed, err)
        return False

    def stop(self, ticks: int = 15) -> None:
        for _ in range(ticks):
            self.act(0.0, 0.0)


def main(argv=None) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--connect", required=True)
    p.add_argument("--id", required=True)
    p.add_argument("--world-id", default="w0")
    p.add_argument("--grab-at", help="X,Y: drive next to this brick and grab it, then idle")
    args = p.parse_args(argv)
    session = open_session(BusOptions(connect=(args.connect,)))
    try:
        body = ScriptedBody(WorldLink(session, args.world_id, args.id))
        if args.grab_at:
            bx, by = (float(v) for v in args.grab_at.split(","))
            body.drive_to(bx - 0.9, by)
            frame = body.act(action="grab")
            print("HOLDING" if frame.holding else "NOT-HOLDING", flush=True)
        else:
            print("ATTACHED", flush=True)
        while True:  # keep answering frames until killed
            body.act()
    finally:
        session.close()


if __name__ == "__main__":
    sys.exit(main())

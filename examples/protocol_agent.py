"""The greedy agent of raw_agent.py, written with the project's `protocol` package: keys as
functions of ids, messages as dataclasses, one codec that checks everything it decodes.

    conag world scenarios/quick_wall.toml               # one terminal
    python3 examples/protocol_agent.py --id x1          # another (with the project installed)
"""
import argparse
import json
import math
import os
import sys

import zenoh

from protocol import CHANNELS, keys
from protocol.codec import ProtocolError, decode, encode
from protocol.messages import NO_READING, AgentCommand, CommandRejected, Hello, SensorFrame, Welcome

BRICK = CHANNELS.index("brick")

p = argparse.ArgumentParser()
p.add_argument("--connect", default="tcp/127.0.0.1:7447")
p.add_argument("--id", default="x1")
p.add_argument("--world", default="w0")
args = p.parse_args()
w, me = args.world, args.id


def on_error(sample: zenoh.Sample) -> None:
    """Print why the world rejected a command."""
    print(decode(sample.payload.to_bytes(), CommandRejected).reason, file=sys.stderr)


conf = zenoh.Config()
conf.insert_json5("scouting/multicast/enabled", "false")
conf.insert_json5("connect/endpoints", json.dumps([args.connect]))
with zenoh.open(conf) as session:
    token = session.liveliness().declare_token(keys.agent_token(w, me))  # 1. the token
    frames = session.declare_subscriber(keys.sensors(w, me), zenoh.handlers.RingChannel(1))  # 2. frames first
    errors = session.declare_subscriber(keys.command_error(w, me), on_error)
    welcome = None
    while welcome is None:  # 3. attach, retrying until the world has seen the token
        for reply in session.get(keys.attach(w, me), payload=encode(Hello(me, os.getpid())), timeout=1.0):
            if reply.ok is not None:
                welcome = decode(reply.ok.payload.to_bytes(), Welcome)
    x, y, last, dropped = welcome.x, welcome.y, welcome.tick - 1, False
    sites = list(zip(welcome.site_xs, welcome.site_ys))
    while last < welcome.tick + 3000 and not dropped:
        try:  # 4. answer every frame
            f = decode(frames.recv().payload.to_bytes(), SensorFrame)
        except ProtocolError:
            continue
        if f.tick <= last:
            continue
        if f.tick > welcome.tick:  # the attach frame's odometry is already in the Welcome's pose
            x, y = x + f.odom_dx, y + f.odom_dy
        last, dropped = f.tick, f.dropped
        if dropped:  # done: no more commands (a grab now would take the brick back)
            break
        if f.holding:
            gx, gy = min(sites, key=lambda s: math.hypot(s[0] - x, s[1] - y))
            stop_at = 0.1
        else:
            bricks = f.ranges[BRICK * f.sectors:(BRICK + 1) * f.sectors]
            seen = [k for k in range(f.sectors) if bricks[k] != NO_READING]
            if not seen:  # none in sensor range: turn on the spot and look again
                session.put(keys.command(w, me), encode(AgentCommand(me, f.tick, 0.0, 0.3)))
                continue
            k = min(seen, key=lambda k: bricks[k])
            bearing = (k + 0.5) * 2 * math.pi / f.sectors
            gx, gy = x + bricks[k] * math.cos(bearing), y + bricks[k] * math.sin(bearing)
            stop_at = welcome.grab_reach - 0.2
        dist = math.hypot(gx - x, gy - y)
        err = (math.atan2(gy - y, gx - x) - f.heading + math.pi) % (2 * math.pi) - math.pi
        there = dist < stop_at
        action = "drop" if f.holding and there else "grab" if there and abs(err) < 0.5 else "none"
        speed = 0.0 if there or abs(err) > 0.5 else min(welcome.max_speed, 1.5 * (dist - stop_at) + 0.2)
        session.put(keys.command(w, me), encode(AgentCommand(me, f.tick, speed, err, action)))
    print(f"dropped a brick at ({x:.2f}, {y:.2f}) at tick {last}" if dropped else "gave up", flush=True)
    sys.exit(0 if dropped else 1)

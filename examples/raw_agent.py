"""A greedy ConAg agent with nothing but zenoh and msgpack (docs/protocol.md is all it knows).

It fetches the brick nearest its brick sensors, carries it to the nearest drop site by
dead reckoning and drops it there, then exits. Try it on a world of its own:
    conag world scenarios/quick_wall.toml            # one terminal
    python3 examples/raw_agent.py --id x1            # another
"""
import argparse
import json
import math
import struct
import sys

import msgpack
import zenoh

p = argparse.ArgumentParser()
p.add_argument("--connect", default="tcp/127.0.0.1:7447")
p.add_argument("--id", default="x1")
p.add_argument("--world", default="w0")
args = p.parse_args()
root = f"conag/v8/world/{args.world}/agent/{args.id}"
pack = lambda t, f: msgpack.packb({"v": 8, "t": t, "f": f}, use_bin_type=True)  # noqa: E731
no_mark = [0.0, 0.0, "site"]  # AgentCommand's mark_dx, mark_dy, mark_kind: this agent never marks
floats = lambda b: struct.unpack(f"<{len(b) // 8}d", b)  # noqa: E731 -- a bin of float64s

conf = zenoh.Config()
conf.insert_json5("scouting/multicast/enabled", "false")
conf.insert_json5("connect/endpoints", json.dumps([args.connect]))
with zenoh.open(conf) as session:
    token = session.liveliness().declare_token(f"conag/v8/world/{args.world}/alive/agent/{args.id}")  # 1. token
    frames = session.declare_subscriber(f"{root}/sensors", zenoh.handlers.RingChannel(1))  # 2. frames first
    errors = session.declare_subscriber(  # why the world rejected a command (CommandRejected.reason)
        f"{root}/error", lambda s: print(msgpack.unpackb(s.payload.to_bytes())["f"][2], file=sys.stderr))
    welcome = None
    while welcome is None:  # 3. attach, retrying until the world has seen the token
        for reply in session.get(f"{root}/attach", payload=pack("Hello", [args.id, 0]), timeout=1.0):
            if reply.ok is not None:
                welcome = msgpack.unpackb(reply.ok.payload.to_bytes())["f"]
    x, y, last = welcome[4], welcome[5], welcome[3] - 1
    sites = list(zip(floats(welcome[12]), floats(welcome[13])))
    max_speed, reach = welcome[18], welcome[23]
    while last < welcome[3] + 3000:
        f = msgpack.unpackb(frames.recv().payload.to_bytes())["f"]  # 4. answer every frame
        tick, heading, sectors, holding = f[1], f[2], f[5], f[7]
        if tick <= last or f[12] != welcome[29]:  # an old frame, or not from this world's run (epoch)
            continue
        if tick > welcome[3]:  # the attach frame's odometry is already in the Welcome's pose
            x, y = x + f[3], y + f[4]  # odometry: the last tick's displacement on world axes
        last = tick
        if f[9]:  # `dropped`: done
            break
        if holding:
            gx, gy = min(sites, key=lambda s: math.hypot(s[0] - x, s[1] - y))
            stop_at = 0.1
        else:
            bricks = floats(f[6])[2 * sectors:3 * sectors]  # channel 2 (brick), one reading per sector
            seen = [k for k in range(sectors) if bricks[k] >= 0]
            if not seen:  # none in sensor range: turn on the spot and look again
                session.put(f"{root}/command", pack("AgentCommand", [args.id, tick, 0.0, 0.3, "none", *no_mark]))
                continue
            k = min(seen, key=lambda k: bricks[k])
            bearing = (k + 0.5) * 2 * math.pi / sectors  # sector k: angles [k, k+1) * 2pi/sectors from east
            gx, gy = x + bricks[k] * math.cos(bearing), y + bricks[k] * math.sin(bearing)
            stop_at = reach - 0.2
        dist = math.hypot(gx - x, gy - y)
        err = (math.atan2(gy - y, gx - x) - heading + math.pi) % (2 * math.pi) - math.pi
        there = dist < stop_at
        action = "drop" if holding and there else "grab" if there and abs(err) < 0.5 else "none"
        speed = 0.0 if there or abs(err) > 0.5 else min(max_speed, 1.5 * (dist - stop_at) + 0.2)
        command = [args.id, tick, float(speed), float(err), action, *no_mark]
        session.put(f"{root}/command", pack("AgentCommand", command))
    print(f"dropped a brick at ({x:.2f}, {y:.2f}) at tick {last}" if f[9] else "gave up", flush=True)
    sys.exit(0 if f[9] else 1)

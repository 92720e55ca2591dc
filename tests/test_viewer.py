"""The viewer (`conag view`): its picture of a world, its timeline over a recording, and its
HTTP API fed by a real world on an in-process bus. The page in a real browser:
tests/test_viewer_browser.py."""

from __future__ import annotations

import json
import time
import urllib.request
from collections.abc import Callable

import pytest

from agent_runtime.world_link import WorldLink
from conag.recording.mcap_log import McapRecorder, read_recording
from conag.viewer.scene import MAPS_STEPS, Scene, Timeline, layer_cells, maps_interval
from conag.viewer.server import LiveFeed, ViewerServer
from protocol import encode, keys
from protocol.messages import BEHAVIOURS, AgentState, WorldStatus, WorldView
from tests.conftest import RunningWorld, make, wait_until
from tests.scripted import ScriptedBody

# A filled site (B: a brick on a site) at (2.5, 2.5), an empty one at (4.5, 2.5), a brick, a
# food disc, a wall cell and an agent start.
LAYOUT = """
..B.+.
#.....
A.b..F
"""


def view(tick: int, ax: float, filled: bool = True, **kw) -> WorldView:
    fields = dict(world_id="w0", tick=tick, width=6.0, height=3.0, disc_xs=(2.5, 5.5), disc_ys=(2.5, 0.5),
                  disc_kinds=("brick", "food"), site_xs=(2.5, 4.5), site_ys=(2.5, 2.5), site_filled=(filled, False),
                  agent_ids=("a1",), agent_alive=(True,), agent_x=(ax,), agent_y=(0.5,), agent_heading=(0.0,),
                  agent_holding=(False,), wall_xs=(0.5,), wall_ys=(1.5,))
    fields.update(kw)
    return WorldView(**fields)


def test_the_picture_puts_discs_sites_and_bodies_where_the_view_says():
    scene = Scene()
    scene.apply(view(10, 1.25))
    scene.apply(AgentState("a1", 10, "explore", False, 1, "", tuple(3 if b == "explore" else 0 for b in BEHAVIOURS)))
    p = scene.picture()
    assert p["tick"] == 10 and (p["width"], p["height"]) == (6.0, 3.0)
    assert p["discs"] == [[2.5, 2.5, "brick"], [5.5, 0.5, "food"]]
    assert p["sites"] == [[2.5, 2.5, True], [4.5, 2.5, False]]
    assert p["walls"] == [[0.5, 1.5]]
    (a,) = p["agents"]
    assert (a["id"], a["x"], a["y"], a["alive"], a["behaviour"]) == ("a1", 1.25, 0.5, True, "explore")
    assert a["behaviour_ticks"] == {"explore": 3}
    assert (p["sites_filled"], p["sites_total"], p["agents_alive"]) == (1, 2, 1)
    json.dumps(p)  # what the page gets


def test_progress_keeps_the_ticks_where_the_count_changed_and_an_older_view_changes_nothing():
    scene = Scene()
    for tick, filled in ((0, False), (10, False), (20, False), (30, True), (40, True)):
        scene.apply(view(tick, 1.0, filled))
    assert scene.progress == [[0, 0], [20, 0], [30, 1], [40, 1]]
    assert not scene.apply(view(5, 3.0))
    assert scene.picture()["agents"][0]["x"] == 1.0
    status = WorldStatus("w0", "t", 1, "lockstep", 50, 2, 2, 3, 1, 0, True)
    scene.apply(status)
    assert scene.picture()["completed"] and scene.picture()["tick"] == 50


def test_the_timeline_of_a_recording_shows_the_newest_view_at_or_before_a_tick(tmp_path):
    out = tmp_path / "r.mcap"
    with McapRecorder(out) as rec:
        for tick, x in ((0, 0.5), (10, 1.5), (20, 2.5)):
            rec.add(f"{keys.ROOT}/world/w0/view", encode(view(tick, x, filled=tick >= 20)), tick)
            rec.add(f"{keys.ROOT}/world/w0/agent/a1/command", b"not drawn", tick)
    timeline = Timeline.from_entries(read_recording(out).entries)
    assert timeline.ticks == [0, 10, 20]
    assert json.loads(timeline.at(15))["agents"][0]["x"] == 1.5
    assert json.loads(timeline.at(999))["agents"][0]["x"] == 2.5
    assert json.loads(timeline.at(-5))["tick"] == 0
    assert timeline.summary()["progress"] == [[0, 0], [10, 0], [20, 1]]


def get(url: str):
    with urllib.request.urlopen(url, timeout=10) as r:
        return json.loads(r.read())


def post(url: str, body: dict):
    req = urllib.request.Request(url, data=json.dumps(body).encode(), headers={"Content-Type": "application/json"})
    with urllib.request.urlopen(req, timeout=10) as r:
        return json.loads(r.read())


@pytest.fixture
def live(bus):
    """A world (agent a1 attached, no process: it does not tick) and a viewer of it."""
    world = make(LAYOUT)
    world.attach("a1")
    rw = RunningWorld(world, bus.server_session())
    feed = LiveFeed(bus.client_session(), "w0").start()
    wait_until(lambda: feed.scene.view is not None or feed.refresh(0.5), what="the world's first view")
    server = ViewerServer(feed).serve_in_thread()
    yield server, feed, rw
    server.close()
    feed.close()
    rw.close()


def test_the_live_scene_is_the_world_and_a_click_removes_a_disc(live):
    server, _, _ = live
    p = get(server.url + "api/scene")
    assert [2.5, 2.5, True] in p["sites"] and [4.5, 2.5, False] in p["sites"]
    assert [2.5, 0.5, "brick"] in p["discs"] and [5.5, 0.5, "food"] in p["discs"]
    (a,) = p["agents"]
    assert (a["id"], a["x"], a["y"]) == ("a1", 0.5, 0.5)
    assert get(server.url + "api/info")["mode"] == "live"
    result = post(server.url + "api/perturb", {"op": "remove", "x": 2.5, "y": 0.5, "kind": "brick"})
    assert result["ok"], result
    wait_until(lambda: [2.5, 0.5, "brick"] not in get(server.url + "api/scene")["discs"],
               what="the removed brick to leave the picture")
    result = post(server.url + "api/perturb", {"op": "move", "x": 5.5, "y": 0.5, "to_x": 4.5, "to_y": 0.5})
    assert result["ok"], result
    wait_until(lambda: [4.5, 0.5, "food"] in get(server.url + "api/scene")["discs"], what="the moved food disc")


def test_the_page_asks_for_the_maps_of_the_agent_it_shows_only(bus):
    from protocol import keys

    feed = LiveFeed(bus.server_session(), "w0", maps_every=10, requester="v1").start()
    watcher = bus.client_session()

    def requests(agent):
        return sorted(str(r.ok.key_expr) for key in keys.maps_requests_for("w0", agent)
                      for r in watcher.liveliness().get(key, timeout=1) if r.ok is not None)

    try:
        with ViewerServer(feed).serve_in_thread() as server:
            assert requests("a1") == []  # nobody shown: nobody asked
            assert get(server.url + "api/maps?agent=a1") == {"tick": None, "size": 0, "layers": {}}
            assert feed.selected == "a1"
            wait_until(lambda: requests("a1") == [f"{keys.ROOT}/world/w0/alive/maps/v1/a1/10"], what="a1's request")
            get(server.url + "api/maps?agent=a2")
            wait_until(lambda: requests("a1") == [] and requests("a2"), what="the request to follow the page")
    finally:
        feed.close()


def _maps_events(url: str, until: Callable[[list[dict]], bool], timeout: float = 20.0) -> list[dict]:
    """The `maps` events of the page's event stream, read until `until(events)` holds."""
    events, event = [], "message"
    deadline = time.monotonic() + timeout
    with urllib.request.urlopen(url + "api/events", timeout=timeout) as stream:
        while not until(events):
            assert time.monotonic() < deadline, f"maps events so far: {events}"
            line = stream.readline().decode().rstrip("\n")
            if line.startswith("event: "):
                event = line[len("event: "):]
            elif line.startswith("data: ") and event == "maps":
                events.append(json.loads(line[len("data: "):]))
            elif not line:
                event = "message"
    return events


@pytest.mark.slow   # waits out ten display periods: about 3 s
def test_the_shown_agents_maps_are_pushed_on_the_event_stream_once_each_when_they_change(bus):
    # A page polling /api/maps every second cost it and the viewer more than the maps did: the
    # stream that carries the pictures pushes a snapshot once, when a new one came.
    from protocol import keys
    from protocol.messages import AgentMap

    feed = LiveFeed(bus.server_session(), "w0", maps_every=10, requester="v1").start()
    agent = bus.client_session()
    pub = agent.declare_publisher(keys.agent_maps("w0", "a1"))

    def snapshot(tick: int, value: int) -> None:
        for layer in ("config", "brick"):
            pub.put(encode(AgentMap("a1", tick, layer, 3, (value,) * 9)))

    try:
        with ViewerServer(feed, display_hz=10).serve_in_thread() as server:
            get(server.url + "api/maps?agent=a1")  # the page shows a1
            wait_until(lambda: feed.asked_every == 10, what="a1's maps request")
            snapshot(10, 3)
            start = time.monotonic()
            events = _maps_events(server.url, lambda ev: any(e["tick"] == 10 for e in ev))
            assert events[-1]["agent"] == "a1" and events[-1]["size"] == 3
            assert {k: layer_cells(v) for k, v in events[-1]["layers"].items()} == {"config": [3] * 9, "brick": [3] * 9}
            # nothing new for a second, ten display periods: sent once only (a new stream gets
            # the newest at once)
            quiet = _maps_events(server.url, lambda ev: time.monotonic() > start + 1 and len(ev) >= 1, timeout=10)
            assert [e["tick"] for e in quiet] == [10]
            snapshot(20, 5)
            events = _maps_events(server.url, lambda ev: any(e["tick"] == 20 for e in ev))
            assert {k: layer_cells(v) for k, v in events[-1]["layers"].items()} == {"config": [5] * 9, "brick": [5] * 9}
    finally:
        feed.close()


def test_the_shown_agents_decision_is_asked_for_at_the_display_rate_not_taken_every_tick(bus):
    # A stand-in agent: publishes a Decision every tick, as agents do, and answers queries
    # with its newest. The viewer must take the queried ones only, at most one query per period.
    from protocol import keys
    from protocol.messages import Decision

    agent = bus.client_session()
    newest = {"tick": 7}
    asked = []

    def answer(query):
        asked.append(newest["tick"])
        d = Decision("a1", newest["tick"], (1.0, 0, 0, 0, 0, 0), (0.0,) * 7, "grab", "go-to-brick")
        query.reply(keys.decision("w0", "a1"), encode(d))

    queryable = agent.declare_queryable(keys.decision("w0", "a1"), answer)
    publisher = agent.declare_publisher(keys.decision("w0", "a1"))
    now = [100.0]
    feed = LiveFeed(bus.server_session(), "w0", clock=lambda: now[0], decision_period=0.2).start()
    try:
        feed.scene.apply_bytes(encode(view(5, 0.5)))
        feed.select("a1")  # asks at once (again each period, until the queryable is known here)

        def answered(tick):
            now[0] += 0.2
            return json.loads(feed.picture()[1])["agents"][0].get("decision_tick") == tick

        wait_until(lambda: answered(7), interval=0.2, what="the answer")
        asked.clear()
        for tick in range(8, 40):  # every tick's publication: not taken
            publisher.put(encode(Decision("a1", tick, (0.0,) * 6, (0.0,) * 7, "none", "explore")))
        for _ in range(20):
            feed.picture()  # pictures within one period: no further query
        assert len(asked) <= 1  # the last period's query, answered late at most
        assert json.loads(feed.picture()[1])["agents"][0]["decision_tick"] == 7
        newest["tick"] = 41
        wait_until(lambda: answered(41), interval=0.2, what="the next period's answer")
        assert len(asked) <= 4
    finally:
        feed.close()
        queryable.undeclare()
        publisher.undeclare()


def test_an_agent_answers_a_query_with_its_newest_decision(bus, start_world):
    import threading

    from agent_runtime.node import AgentOptions, AgentReport, run_agent
    from protocol import decode, keys
    from protocol.messages import Decision

    rw = start_world(_one_agent_scenario())
    report, stop = AgentReport(), threading.Event()
    agent = threading.Thread(target=run_agent, args=(bus.client_session(), AgentOptions("w0", "a1")),
                             kwargs=dict(stop=stop, report=report), daemon=True)
    agent.start()
    asker = bus.client_session()
    try:
        wait_until(lambda: report.ticks > 5, what="the agent to be stepping")
        replies = [r.ok for r in asker.get(keys.decision("w0", "a1"), timeout=5) if r.ok is not None]
        assert len(replies) == 1
        d = decode(replies[0].payload.to_bytes(), Decision)
        assert d.agent_id == "a1" and 5 <= d.tick <= rw.world.tick and len(d.state) == 6
    finally:
        stop.set()
        agent.join(10)


def _one_agent_scenario() -> str:
    return 'name = "one"\nseed = 3\nagents = 1\nlayout = """\n' + LAYOUT.strip("\n") + '\n"""\n'


def test_the_maps_interval_gives_about_one_snapshot_a_second_and_never_less_than_asked():
    assert maps_interval(5.0, 10) == 10          # a slow run: every --maps-every ticks
    assert maps_interval(35.0, 10) == 20         # 10 agents in lockstep: not 3.5 a second
    assert maps_interval(300.0, 10) == 200
    assert maps_interval(300.0, 250) == 250      # never more often than asked
    assert maps_interval(1e9, 10) == MAPS_STEPS[-1]
    assert maps_interval(300.0, 0) == 0          # maps off stays off


def test_the_maps_request_follows_the_runs_speed_between_the_pages_asks(bus):
    from protocol import keys

    now = [100.0]
    feed = LiveFeed(bus.server_session(), "w0", maps_every=10, requester="v1", clock=lambda: now[0]).start()
    world = bus.client_session()

    def requests():
        return sorted(str(r.ok.key_expr) for key in keys.maps_requests_for("w0", "a1")
                      for r in world.liveliness().get(key, timeout=1) if r.ok is not None)

    def world_at(tick):
        world.put(keys.view("w0"), encode(view(tick, 1.0)))
        wait_until(lambda: feed.scene.view is not None and feed.scene.view.tick == tick, what=f"the view of {tick}")

    try:
        world_at(0)
        feed.maps("a1")
        wait_until(lambda: requests() == [f"{keys.ROOT}/world/w0/alive/maps/v1/a1/10"], what="the first request")
        now[0] += 2.0
        world_at(120)                                # 60 ticks a second: one snapshot every 50
        feed.maps("a1")
        wait_until(lambda: requests() == [f"{keys.ROOT}/world/w0/alive/maps/v1/a1/50"], what="the request at 50")
        now[0] += 1.0
        world_at(125)                                # it slowed down to 5 a second
        feed.maps("a1")
        wait_until(lambda: requests() == [f"{keys.ROOT}/world/w0/alive/maps/v1/a1/10"], what="the request back at 10")
    finally:
        feed.close()
    wait_until(lambda: requests() == [], what="the request to go with the viewer")


def test_a_recording_cannot_be_perturbed_and_its_frames_are_served_by_tick():
    timeline = Timeline.from_entries([type("E", (), dict(key=f"{keys.ROOT}/world/w0/view", tick=t,
                                                         data=encode(view(t, 0.5 + t / 10))))() for t in (0, 10)])
    with ViewerServer(timeline).serve_in_thread() as server:
        assert get(server.url + "api/info")["ticks"] == [0, 10]
        assert get(server.url + "api/frame?tick=12")["agents"][0]["x"] == 1.5
        with pytest.raises(urllib.error.HTTPError) as err:
            post(server.url + "api/perturb", {"op": "remove", "x": 2.5, "y": 2.5})
        assert err.value.code == 409


def test_a_ticking_world_publishes_views_every_few_ticks_while_watched(bus, start_world):
    from tests.conftest import scenario

    start_world(scenario(LAYOUT), view_every=5)
    feed = LiveFeed(bus.client_session(), "w0").start()
    try:
        body = ScriptedBody(WorldLink(bus.client_session(), "w0", "a1"))
        for _ in range(12):
            body.act(speed=1.0)
        wait_until(lambda: feed.scene.view is not None and feed.scene.view.tick >= 10, what="the view of tick 10")
        v = feed.scene.view
        assert v.tick % 5 == 0 and v.agent_x[0] > 0.5 + 0.3  # it moved off its start
    finally:
        feed.close()


# --- the agents' maps (AgentMap, on request) ----------------------------------------------------

def _brain_after_one_step():
    from agent_runtime.brain import Brain

    world = make(LAYOUT)
    brain = Brain(world.attach("a1"))
    brain.step(world.frame("a1"))
    return brain


def test_a_map_snapshot_holds_the_esms_both_nms_and_the_matching_grid():
    from agent_runtime.snapshot import map_snapshot
    from protocol.messages import MAP_LAYERS, NM_UNREACHABLE

    brain = _brain_after_one_step()
    maps = {m.layer: m for m in map_snapshot(brain, 7)}
    assert set(maps) == set(MAP_LAYERS) and {m.tick for m in maps.values()} == {7}
    n = brain.maps.size
    c = n // 2
    brick = maps["brick"].cells
    assert brick[c * n + c + 2] > 0  # the free brick two cells east of the agent (row 0 north)
    assert maps["brick_nm"].cells[c * n + c] not in (0, NM_UNREACHABLE)  # some way to it, not there yet
    for m in maps.values():
        assert len(encode(m)) < 4 * n * n  # about a byte a cell


def test_agents_publish_their_maps_only_while_someone_asks(bus):
    from agent_runtime.feeds import AgentFeeds
    from protocol import keys
    from protocol.messages import AgentMap

    feeds_session, asker = bus.server_session(), bus.client_session()
    feeds = AgentFeeds(feeds_session, "w0", "a1")
    got = []
    sub = asker.declare_subscriber(keys.agent_maps("w0", "a1"), lambda s: got.append(s.payload.to_bytes()))
    brain = _brain_after_one_step()
    try:
        feeds.after_step(brain, 10)
        assert feeds.maps_every == 0
        other = asker.liveliness().declare_token(keys.maps_request_token("w0", "viewer", 2, agent="a2"))
        token = asker.liveliness().declare_token(keys.maps_request_token("w0", "recorder", 5))  # all agents
        wait_until(lambda: feeds.maps_every == 5, what="the agent to hear the maps request")
        mine = asker.liveliness().declare_token(keys.maps_request_token("w0", "viewer2", 3, agent="a1"))
        wait_until(lambda: feeds.maps_every == 3, what="the agent to hear the request for it alone")
        mine.undeclare()
        wait_until(lambda: feeds.maps_every == 5, what="the request for it alone to go")
        other.undeclare()
        feeds.after_step(brain, 11)  # not a multiple of 5
        feeds.after_step(brain, 15)
        wait_until(lambda: len(got) >= 9, what="one snapshot")
        from protocol import decode

        assert {decode(d, AgentMap).tick for d in got} == {15}
        token.undeclare()
        wait_until(lambda: feeds.maps_every == 0, what="the request to go")
    finally:
        sub.undeclare()
        feeds.close()


def test_the_timeline_gives_an_agents_maps_at_a_tick():
    from agent_runtime.snapshot import map_snapshot

    brain = _brain_after_one_step()
    entries = [type("E", (), dict(key=f"{keys.ROOT}/world/w0/agent/a1/maps", tick=t, data=encode(m)))()
               for t in (10, 20) for m in map_snapshot(brain, t)]
    timeline = Timeline.from_entries(entries)
    assert timeline.maps_at("a1", 15)["tick"] == 10 and timeline.maps_at("a1", 99)["tick"] == 20
    assert timeline.maps_at("a1", 5)["layers"] == {} and timeline.maps_at("a2", 20)["size"] == 0
    assert len(layer_cells(timeline.maps_at("a1", 20)["layers"]["config_nm"])) == brain.maps.size ** 2


def test_a_live_viewer_decodes_only_the_newest_snapshot_of_an_agents_maps():
    from conag.viewer.scene import decode_newest_maps, maps_picture
    from protocol.messages import AgentMap

    def layer(tick: int, name: str, value: int) -> bytes:
        return encode(AgentMap("a1", tick, name, 3, (value,) * 9))

    raw = [layer(10, "config", 1), layer(10, "brick", 2),     # an older snapshot
           layer(20, "config", 3), b"not msgpack", layer(20, "brick", 4)]   # the newest, one bad message
    newest = decode_newest_maps(raw)
    assert [(m.tick, m.layer, m.cells[0]) for m in newest] == [(20, "config", 3), (20, "brick", 4)]
    layers = maps_picture(newest)["layers"]
    assert {name: layer_cells(cells) for name, cells in layers.items()} == {"config": [3] * 9, "brick": [4] * 9}
    assert decode_newest_maps([]) == [] and decode_newest_maps([b"junk"]) == []


def test_a_live_viewer_runs_at_a_lower_cpu_priority_than_the_run(endpoint):
    # `conag view` (and so `conag run --view`) yields the CPU to the run: nice +10 on every
    # thread, zenoh's too, by default; and it still stops at once on SIGTERM.
    import os

    from tests.conftest import Process

    base = os.getpriority(os.PRIO_PROCESS, 0)
    viewer = Process("view", "--port", "0", "--connect", endpoint)
    try:
        viewer.wait_for("viewer at http://127.0.0.1:")
        tasks = os.listdir(f"/proc/{viewer.proc.pid}/task")
        assert len(tasks) > 3  # the zenoh runtime's threads too
        assert {os.getpriority(os.PRIO_PROCESS, int(t)) for t in tasks} == {min(base + 10, 19)}
        assert viewer.stop() == 0
    finally:
        viewer.kill()

"""Runs that Foxglove and Lichtblick open (issue 34), checked by readers nobody here wrote:

* a recording holds Foxglove channels beside the bus's: Foxglove's MCAP protobuf decoder
  (`mcap-protobuf-support`, which builds its classes from the schema in the file) finds the
  world's discs, sites and agents where the world's WorldView of the same tick has them,
  the maps as the agent's grid, the sensors, the log and the progress; a replay reads the
  bus's channels only;
* a live world is served over the Foxglove WebSocket protocol: a client (the `websockets`
  package, decoding with Foxglove's precompiled schemas, `foxglove-schemas-protobuf`)
  subscribes and decodes a SceneUpdate of the world;
* slow: `conag run scenarios/fig19.toml --record` writes a file whose world and map
  channels decode to what the world and the agents published, and `conag run --foxglove`
  serves a client; the Node readers (`@mcap/core` with protobufjs, `@foxglove/ws-protocol`)
  check the same when tests/node has its packages (`npm ci` there; .ci/run does it).
"""

from __future__ import annotations

import json
import math
import shutil
import struct
import subprocess
import threading
import time
from pathlib import Path

import pytest
from mcap.exceptions import EndOfFile
from mcap.reader import make_reader
from mcap.records import Channel

from conag.foxglove.convert import MapLayer, Translator, decode_map
from conag.recording.mcap_log import DEFAULT_TICK_NS, McapRecorder, read_end, read_recording
from protocol import keys
from protocol.codec import ProtocolError, decode, encode
from protocol.messages import (
    CHANNELS,
    MAP_LAYERS,
    SCHEMA_VERSION,
    AgentMap,
    AgentState,
    SensorFrame,
    Welcome,
    WorldView,
)
from tests.conftest import SCENARIOS, Process, conag, free_port, wait_until

W = "w0"
NODE_DIR = Path(__file__).resolve().parent / "node"
SUBPROTOCOL = "foxglove.sdk.v1"  # the SDK's server's name for the Foxglove WebSocket protocol (same as .websocket.v1)


# --- readers from outside -----------------------------------------------------------------------

def read_foxglove(path: Path) -> dict[str, list[tuple[int, object]]]:
    """topic -> [(tick, decoded message)] of every non-msgpack channel: protobuf through
    Foxglove's MCAP decoder (classes built from the file's own schemas), JSON as JSON."""
    from mcap_protobuf.decoder import DecoderFactory

    out: dict[str, list[tuple[int, object]]] = {}
    with open(path, "rb") as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        tick_ns = int(next(m for m in reader.iter_metadata() if m.name == "conag").metadata["tick_ns"])
        channels = reader.get_summary().channels.values()
        protobuf = [c.topic for c in channels if c.message_encoding == "protobuf"]
        for schema, channel, message, msg in reader.iter_decoded_messages(topics=protobuf):
            assert schema.encoding == "protobuf" and schema.name.startswith("foxglove.")
            out.setdefault(channel.topic, []).append((message.publish_time // tick_ns, msg))
        for schema, channel, message in reader.iter_messages(topics=[c.topic for c in channels
                                                                     if c.message_encoding == "json"]):
            assert schema.encoding == "jsonschema" and json.loads(schema.data)["type"] == "object"
            out.setdefault(channel.topic, []).append((message.publish_time // tick_ns, json.loads(message.data)))
    return out


def yaw(q) -> float:
    return 2 * math.atan2(q.z, q.w)


def entities(update) -> dict[str, object]:
    return {e.id: e for e in update.entities}


def cue_marks(entity, kind: str) -> list[tuple[float, float]]:
    """Where a cue entity's marks are: the centre of each cross (two bars) or diamond (four)."""
    per = 2 if kind == "site" else 4
    cubes = list(entity.cubes)
    assert len(cubes) % per == 0
    groups = [cubes[i:i + per] for i in range(0, len(cubes), per)]
    return sorted((round(sum(c.pose.position.x for c in g) / per, 6), round(sum(c.pose.position.y for c in g) / per, 6))
                  for g in groups)


def assert_scene_matches(update, v: WorldView) -> None:
    """The SceneUpdate shows what the WorldView says: each disc, site, cue and body where it is."""
    es = entities(update)
    for kind in ("site", "supply"):
        want = sorted((round(x, 6), round(y, 6)) for x, y, k in zip(v.cue_xs, v.cue_ys, v.cue_kinds) if k == kind)
        if want:
            assert cue_marks(es[f"cues/{kind}"], kind) == want, kind
        else:
            assert f"cues/{kind}" not in es, kind
    for kind in ("food", "water", "brick"):
        got = sorted((round(c.pose.position.x, 6), round(c.pose.position.y, 6)) for c in es[f"discs/{kind}"].cylinders)
        want = sorted((round(x, 6), round(y, 6)) for x, y, k in zip(v.disc_xs, v.disc_ys, v.disc_kinds) if k == kind)
        assert got == want, kind
    sites = es["sites"].cubes
    assert [(round(c.pose.position.x, 6), round(c.pose.position.y, 6)) for c in sites] == \
        [(round(x, 6), round(y, 6)) for x, y in zip(v.site_xs, v.site_ys)]
    filled = {(c.color.r, c.color.g, c.color.b) for c, f in zip(sites, v.site_filled) if f}
    empty = {(c.color.r, c.color.g, c.color.b) for c, f in zip(sites, v.site_filled) if not f}
    assert not filled & empty
    for i, aid in enumerate(v.agent_ids):
        e = es[f"agents/{aid}"]
        body = e.cylinders[0].pose.position
        assert (body.x, body.y) == pytest.approx((v.agent_x[i], v.agent_y[i]), abs=1e-9)
        assert math.remainder(yaw(e.arrows[0].pose.orientation) - v.agent_heading[i], 2 * math.pi) == \
            pytest.approx(0, abs=1e-6)
        assert (len(e.cylinders) == 2) == v.agent_holding[i]  # the body, and the brick it holds
        assert {m.key: m.value for m in e.metadata}["tick"] == str(v.tick)


def assert_grid_matches(grid, m: AgentMap) -> None:
    """The Grid decodes to the agent's map: row 0 of the AgentMap (north) is the grid's last row."""
    assert grid.column_count == m.size and grid.row_stride == m.size and grid.cell_stride == 1
    assert [(f.name, f.offset) for f in grid.fields] == [("value", 0)]
    rows = [list(grid.data[r * m.size:(r + 1) * m.size]) for r in range(m.size)]
    assert [c for row in reversed(rows) for c in row] == list(m.cells)


# --- a recording ---------------------------------------------------------------------------------

def _view(tick: int, holding: bool = False) -> WorldView:
    return WorldView(W, tick, 12.0, 10.0, (1.5, 2.5, 7.25), (1.5, 8.5, 3.75), ("food", "brick", "water"),
                     (4.5, 5.5), (5.5, 5.5), (True, False), ("a1", "a2"), (True, False), (3.2, 9.1), (4.4, 2.0),
                     (0.7, -2.5), (holding, False), (0.5, 11.5), (0.5, 9.5))


def _cued_view(tick: int) -> WorldView:
    """`_view(tick)` in a world with cues: a site cue on the empty site, a supply cue beside it."""
    from dataclasses import replace

    return replace(_view(tick), cue_xs=(5.5, 9.5), cue_ys=(5.5, 7.5), cue_kinds=("site", "supply"))


def _map(tick: int, layer: str = "brick", size: int = 5) -> AgentMap:
    return AgentMap("a1", tick, layer, size, tuple((7 * i + tick) % 128 for i in range(size * size)))


def _bus_messages() -> list[tuple[str, object]]:
    """A run's bus messages in the order a recorder hears them: an attach, two frames, a view,
    two map layers, an agent's state and a second view."""
    ranges = tuple(float(c) + 0.25 * s if s != 2 else -1.0 for c in range(len(CHANNELS)) for s in range(4))
    return [
        (keys.welcome(W, "a1"), Welcome(W, "a1", 0, 0, 3.2, 4.4, 0.7, False, 0, 4, 6.0, 1.0, (4.5,), (5.5,),
                                        disc_radius=0.5, agent_radius=0.3)),
        (keys.sensors(W, "a1"), SensorFrame("a1", 10, 0.7, 0.0, 0.0, 4, ranges, True)),
        (keys.sensors(W, "a1"), SensorFrame("a1", 11, 0.7, 0.0, 0.0, 4, ranges, True)),  # not a view's tick
        (keys.view(W), _view(10, holding=True)),
        (keys.agent_maps(W, "a1"), _map(10)),
        (keys.agent_maps(W, "a1"), _map(10, "matching")),
        (keys.agent_state(W, "a1"), AgentState("a1", 12, "brick_nav", True, 1, "no open site in reach", (0,) * 14)),
        (keys.view(W), _view(20)),
    ]


def test_a_recording_holds_foxglove_channels_that_an_outside_reader_decodes_as_the_world_says(tmp_path):
    out = tmp_path / "r.mcap"
    messages = _bus_messages()
    with McapRecorder(out, {"seed": "1"}, derive=Translator().feed) as rec:
        for i, (key, msg) in enumerate(messages):
            rec.add(key, encode(msg), 1_000 + i)

    got = read_foxglove(out)
    scenes = got["/world/scene"]
    assert [t for t, _ in scenes] == [10, 20]
    assert_scene_matches(scenes[0][1], _view(10, holding=True))
    assert_scene_matches(scenes[1][1], _view(20))
    walls = got["/world/walls"]
    assert len(walls) == 1 and sorted((c.pose.position.x, c.pose.position.y)
                                      for c in entities(walls[0][1])["walls"].cubes) == [(0.5, 0.5), (11.5, 9.5)]
    tf = {t.child_frame_id: t for t in got["/tf"][0][1].transforms}
    assert tf["a2"].parent_frame_id == "world" and (tf["a2"].translation.x, tf["a2"].translation.y) == (9.1, 2.0)
    assert yaw(tf["a2"].rotation) == pytest.approx(-2.5)
    # the maps: the agent's grid, cell for cell, centred on its body
    grid_tick, grid = got["/agents/a1/maps/brick"][0]
    assert grid_tick == 10
    assert_grid_matches(grid, _map(10))
    assert (grid.pose.position.x, grid.pose.position.y) == pytest.approx((3.2 - 2.5, 4.4 - 2.5))
    assert_grid_matches(got["/agents/a1/maps/matching"][0][1], _map(10, "matching"))
    # the sensors of the view's tick: one scan per colour, a point per sector, inf where nothing is seen
    for c, channel in enumerate(CHANNELS):
        [(tick, scan)] = got[f"/agents/a1/scan/{channel}"]
        assert tick == 10 and (scan.pose.position.x, scan.pose.position.y) == (3.2, 4.4)
        assert list(scan.ranges) == [c, c + 0.25, math.inf, c + 0.75]
        assert scan.end_angle - scan.start_angle == pytest.approx(1.5 * math.pi)
    logs = [m for _, m in got["/log"]]
    assert "attached" in logs[0].message and logs[0].level == 2  # INFO
    assert "no open site in reach" in logs[1].message and logs[1].level == 3  # WARNING
    assert [m for _, m in got["/progress"]] == [
        {"tick": 10, "sites_filled": 1, "sites_total": 2, "agents_alive": 1},
        {"tick": 20, "sites_filled": 1, "sites_total": 2, "agents_alive": 1}]
    # a replay sees the bus's messages only, as before
    assert [e.key for e in read_recording(out).entries] == [k for k, _ in messages]



def _derived_by_topic(path: Path) -> dict[str, list[tuple[int, int, int, bytes]]]:
    """topic -> [(log_time, publish_time, sequence, data)] of every non-msgpack message, by sequence."""
    with open(path, "rb") as f:
        out: dict[str, list[tuple[int, int, int, bytes]]] = {}
        for _, channel, m in make_reader(f).iter_messages(log_time_order=False):
            if channel.message_encoding != "msgpack":
                out.setdefault(channel.topic, []).append((m.log_time, m.publish_time, m.sequence, bytes(m.data)))
    return {topic: sorted(ms, key=lambda m: m[2]) for topic, ms in out.items()}


def _channel_encodings(path: Path) -> set[str]:
    """The message encodings of the channels a file (finished or not) holds."""
    from mcap.stream_reader import StreamReader

    found = set()
    with open(path, "rb") as f:
        try:
            for record in StreamReader(f).records:
                if isinstance(record, Channel):
                    found.add(record.message_encoding)
        except EndOfFile:  # no footer: the file was cut short
            pass
    return found


def _translated_as_they_come(messages: list[tuple[str, bytes, int]]) -> dict[str, list[tuple[int, int, int, bytes]]]:
    """What one Translator fed each message in turn makes, as the recorder writes it."""
    translator, out = Translator(), {}  # type: ignore[var-annotated]
    for key, data, t in messages:
        for d in translator.feed(key, data, t):
            got = out.setdefault(d.topic, [])
            got.append((t, d.tick * DEFAULT_TICK_NS, len(got) + 1, d.data))
    return out


def _encoded(n: int = 40) -> list[tuple[str, bytes, int]]:
    """`_bus_messages` over and over, ticks moving on by 20 each round: (key, bytes, log time)."""
    from dataclasses import replace

    out = []
    for r in range(n // len(_bus_messages()) + 1):
        for key, msg in _bus_messages():
            tick = getattr(msg, "tick", None)
            msg = msg if tick is None else replace(msg, tick=tick + 20 * r)
            out.append((key, encode(msg), 1_000 + len(out)))
    return out[:n]


def test_the_foxglove_channels_made_on_close_are_what_a_translator_makes_as_messages_come(tmp_path):
    # The recorder writes the bus's messages during a run and their Foxglove channels once
    # stopped, read back from its own file (over many chunks here): the same messages, log
    # times, ticks and sequences as translating each message as it came.
    messages = _encoded(40)
    rec = McapRecorder(tmp_path / "r.mcap", derive=Translator().feed, chunk_size=300)
    for key, data, t in messages:
        rec.add(key, data, t)
    path = rec.close()
    want = _translated_as_they_come(messages)
    assert {"/world/scene", "/tf", "/agents/a1/maps/brick", "/log", "/progress"} <= set(want)
    assert _derived_by_topic(path) == want
    assert [(e.key, e.data) for e in read_recording(path).entries] == [(k, d) for k, d, _ in messages]
    assert read_end(path)["derived_messages"] == str(sum(len(v) for v in want.values()))
    assert "derived_until_tick" not in read_end(path)


def test_foxglove_channels_cut_short_say_where_and_translate_makes_them_all(tmp_path, capsys):
    # Past its deadline the recorder stops making the Foxglove channels and says up to which
    # tick they go; `conag record OUT --translate IN` makes a copy with them all, the bus's
    # messages as they were.
    messages = _encoded(40)
    rec = McapRecorder(tmp_path / "r.mcap", derive=Translator().feed, chunk_size=300)
    for key, data, t in messages:
        rec.add(key, data, t)
    cut = rec.close(derive_deadline=time.monotonic() - 1.0)
    assert rec.derived_until == 0 and read_end(cut)["derived_until_tick"] == "0"
    assert _derived_by_topic(cut) == {}

    from conag.cli import main

    assert main(["record", str(tmp_path / "all.mcap"), "--translate", str(cut)]) == 0
    assert "wrote" in capsys.readouterr().out
    full = tmp_path / "all.mcap"
    assert _derived_by_topic(full) == _translated_as_they_come(messages)
    assert read_recording(full).entries == read_recording(cut).entries
    assert read_end(full)["last_tick"] == read_end(cut)["last_tick"] and "derived_until_tick" not in read_end(full)


def test_translate_makes_the_foxglove_channels_of_what_a_killed_recorder_left(tmp_path, capsys):
    messages = _encoded(40)
    rec = McapRecorder(tmp_path / "r.mcap", derive=Translator().feed)
    for key, data, t in messages[:24]:
        rec.add(key, data, t)
    rec.flush()                                        # the recorder process does this every second
    for key, data, t in messages[24:]:
        rec.add(key, data, t)
    part = tmp_path / "killed.mcap.part"
    shutil.copy(rec.part, part)                        # what a SIGKILL now leaves: no Foxglove channels yet
    rec.close()
    assert _channel_encodings(part) == {"msgpack"}

    from conag.cli import main

    assert main(["record", str(tmp_path / "out.mcap"), "--translate", str(part)]) == 0
    assert "cut short" in capsys.readouterr().out
    assert _derived_by_topic(tmp_path / "out.mcap") == _translated_as_they_come(messages[:24])
    assert [e.data for e in read_recording(tmp_path / "out.mcap").entries] == [d for _, d, _ in messages[:24]]


def test_a_translation_that_fails_on_close_loses_no_bus_message(tmp_path):
    # The Foxglove channels are made as the file is closed: should the translation raise,
    # the file is finished all the same, every bus message in it, and says what went wrong.
    messages = _encoded(40)
    seen = []

    def derive(key, data, t):
        seen.append(key)
        if len(seen) == 20:
            raise RuntimeError("a translator bug")
        return Translator.feed(translator, key, data, t)

    translator = Translator()
    rec = McapRecorder(tmp_path / "r.mcap", derive=derive, chunk_size=300)
    for key, data, t in messages:
        rec.add(key, data, t)
    path = rec.close()
    assert path == tmp_path / "r.mcap" and path.exists() and not rec.part.exists()
    assert [e.data for e in read_recording(path).entries] == [d for _, d, _ in messages]
    assert read_end(path)["derived_error"] == "RuntimeError: a translator bug" == rec.derive_error


def test_translate_refuses_what_it_cannot_do(tmp_path, capsys):
    from conag.cli import main

    with McapRecorder(tmp_path / "r.mcap") as rec:
        rec.add(keys.view(W), encode(_view(10)), 1)
    for argv, says in ((["record", str(tmp_path / "r.mcap"), "--translate", str(tmp_path / "r.mcap")], "another file"),
                       (["record", "o.mcap", "--translate", str(tmp_path / "r.mcap"), "--msgpack-only"],
                        "--msgpack-only"),
                       (["record", str(tmp_path / "o.mcap"), "--translate", str(tmp_path / "none.mcap")], "none.mcap")):
        assert main(argv) != 0
        assert says in capsys.readouterr().err
    assert not (tmp_path / "o.mcap").exists()


def test_a_scene_made_from_kept_primitives_is_the_scene_made_afresh():
    # A translator keeps each disc's and site's primitive for the next views: a disc that
    # moves, a site that fills and sizes from a Welcome must show as a fresh translator shows them.
    from dataclasses import replace

    from conag.foxglove.convert import Geometry

    kept = Translator()
    views = [_view(10), replace(_view(20), disc_xs=(1.5, 3.0, 7.25)),            # the brick moved
             replace(_view(30), disc_xs=(1.5, 3.0, 7.25), site_filled=(True, True))]  # a site filled
    for geometry in (Geometry.default(), Geometry(2.0, 0.3, 0.75)):
        kept.geometry = geometry
        for v in views:
            fresh = Translator()
            fresh.geometry, fresh._agents = geometry, set(kept._agents)
            assert kept.scene(v, 5).encode() == fresh.scene(v, 5).encode()
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

    assert_scene_matches(SceneUpdate.FromString(kept.scene(views[-1], 5).encode()), views[-1])

def test_cues_show_as_their_own_entities_and_go_when_the_world_takes_them_off(tmp_path):
    # A foreman's marks (docs/society.md) in a recording, read by Foxglove's own decoder: a cross
    # per site cue and a diamond per supply cue, on the floor above the sites and under the discs,
    # in colours of their own; a kind whose last cue goes is deleted; a world without cues has none.
    from dataclasses import replace

    out = tmp_path / "r.mcap"
    both = replace(_view(10), cue_xs=(4.5, 8.5, 9.5), cue_ys=(5.5, 2.5, 7.5), cue_kinds=("site", "site", "supply"))
    views = [_view(0), both, replace(_view(20), cue_xs=(8.5,), cue_ys=(2.5,), cue_kinds=("site",))]
    with McapRecorder(out, derive=Translator().feed) as rec:
        for i, v in enumerate(views):
            rec.add(keys.view(W), encode(v), 1_000 + i)
    scenes = [m for _, m in read_foxglove(out)["/world/scene"]]
    for update, v in zip(scenes, views):
        assert_scene_matches(update, v)
    assert not [e for e in scenes[0].entities if e.id.startswith("cues/")]
    es = entities(scenes[1])
    site, supply, disc = es["cues/site"].cubes[0], es["cues/supply"].cubes[0], es["discs/brick"].cylinders[0]
    assert (site.color.r, site.color.g, site.color.b) != (supply.color.r, supply.color.g, supply.color.b)
    sites_top = es["sites"].cubes[0].pose.position.z + es["sites"].cubes[0].size.z / 2
    for bar in (site, supply):
        bottom, top = bar.pose.position.z - bar.size.z / 2, bar.pose.position.z + bar.size.z / 2
        assert sites_top <= bottom and top < disc.size.z  # over the site squares, inside a lying disc's height
    assert [d.id for d in scenes[2].deletions] == ["cues/supply"]


def test_a_recording_without_foxglove_channels_has_the_bus_channels_only(tmp_path):
    out = tmp_path / "r.mcap"
    with McapRecorder(out) as rec:
        rec.add(keys.view(W), encode(_view(10)), 1)
    assert read_foxglove(out) == {} and len(read_recording(out).entries) == 1


def test_a_map_is_decoded_fast_as_the_codec_decodes_it():
    for m in (_map(10), _map(0, "matching", 41), AgentMap("a-2.x", 7, "config_nm", 1, (127,))):
        assert decode_map(encode(m)) == MapLayer.of(m)
        assert MapLayer.of(m).cells == bytes(m.cells)


def _raw_map(fields: list) -> bytes:
    import msgpack

    return msgpack.packb({"v": SCHEMA_VERSION, "t": "AgentMap", "f": fields}, use_bin_type=True)


@pytest.mark.parametrize("data", [
    _raw_map(["a1", 1, "food", 3, [1] * 8]),            # fewer cells than size x size
    _raw_map(["a1", 1, "food", 3, [1] * 8 + [128]]),    # above MAP_LEVEL
    _raw_map(["a1", 1, "food", 3, [1] * 8 + [-1]]),
    _raw_map(["a1", 1, "food", 3, [1] * 8 + [1.0]]),    # not an int
    _raw_map(["a1", 1, "food", 3, [1] * 8 + ["x"]]),
    _raw_map(["a 1", 1, "food", 3, [1] * 9]),           # not an id
    _raw_map(["a1", -1, "food", 3, [1] * 9]),
    _raw_map(["a1", True, "food", 3, [1] * 9]),
    _raw_map(["a1", 1, "nope", 3, [1] * 9]),            # no such layer
    _raw_map(["a1", 1, "food", 4, [1] * 16]),           # an even size
    _raw_map(["a1", 1, "food", 3, [1] * 9, 0]),         # a field too many
    encode(_view(10)),                                  # another message
    b"\xc1not msgpack",
])
def test_a_map_the_codec_refuses_is_refused_and_not_translated(data):
    with pytest.raises(ProtocolError):
        decode(data, AgentMap)
    with pytest.raises(ProtocolError):
        decode_map(data)
    assert Translator().feed(keys.agent_maps(W, "a1"), data, 1) == []


# --- live ----------------------------------------------------------------------------------------

class FoxgloveClient:
    """A Foxglove WebSocket protocol client on the `websockets` package (the protocol: JSON ops
    as text, message data as binary: opcode 1, subscription id, receive time, payload)."""

    def __init__(self, url: str, timeout: float = 20.0):
        from websockets.sync.client import connect

        self.ws = connect(url, subprotocols=[SUBPROTOCOL], open_timeout=timeout, legacy=True)
        self.channels: dict[str, dict] = {}
        self.subscriptions = 0

    def subscribe(self, topic: str, timeout: float = 30.0) -> int:
        """Subscribe to `topic` once it is advertised; the subscription's id."""
        deadline = time.monotonic() + timeout
        while topic not in self.channels:
            self._receive(deadline)
        self.subscriptions += 1
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": self.subscriptions, "channelId": self.channels[topic]["id"]}]}))
        return self.subscriptions

    def next_message(self, topic: str, timeout: float = 30.0, subscribed: bool = False) -> bytes:
        """Subscribe to `topic` (`subscribed`: its last subscription); the payload of its next message."""
        deadline = time.monotonic() + timeout
        sub = self.subscriptions if subscribed else self.subscribe(topic, timeout)
        while True:
            m = self._receive(deadline)
            if isinstance(m, bytes) and m[0] == 1 and struct.unpack_from("<I", m, 1)[0] == sub:
                return m[13:]

    def receive(self, timeout: float) -> None:
        """Take what comes within `timeout` seconds (advertisements among it)."""
        try:
            self._receive(time.monotonic() + timeout)
        except TimeoutError:
            pass

    def _receive(self, deadline: float) -> str | bytes:
        if time.monotonic() >= deadline:
            raise TimeoutError("nothing came in time")
        m = self.ws.recv(timeout=max(deadline - time.monotonic(), 0.01))
        if isinstance(m, str):
            op = json.loads(m)
            if op["op"] == "advertise":
                self.channels.update({c["topic"]: c for c in op["channels"]})
        return m

    def close(self) -> None:
        self.ws.close()


def test_a_live_world_is_served_to_a_foxglove_websocket_client(bus):  # with cues, as a society's
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

    from conag.foxglove.live import FoxgloveBridge

    world = bus.server_session()
    bridge = FoxgloveBridge(bus.client_session(), W, port=0, maps_every=10).start()
    stop = threading.Event()

    def serve() -> None:  # the world publishes a view, the bridge takes it (the display period)
        tick = 0
        while not stop.wait(0.05):
            tick += 10
            world.put(keys.view(W), encode(_cued_view(tick)))
            bridge.step()

    thread = threading.Thread(target=serve, daemon=True)
    thread.start()
    client = None
    try:
        client = FoxgloveClient(f"ws://127.0.0.1:{bridge.port}")
        update = SceneUpdate.FromString(client.next_message("/world/scene"))
        tick = int({m.key: m.value for m in entities(update)["sites"].metadata}["tick"])
        assert_scene_matches(update, _cued_view(tick))  # the cues too, as their own entities
        assert client.channels["/world/scene"]["schemaName"] == "foxglove.SceneUpdate"
        assert client.channels["/world/scene"]["encoding"] == "protobuf"
        # the walls were sent before this client came: they are sent again for it
        walls = SceneUpdate.FromString(client.next_message("/world/walls"))
        assert len(entities(walls)["walls"].cubes) == 2
        # the agents are asked for their maps only while their map topics are watched, each for its own
        assert maps_asked(world) == set()
        client.subscribe("/agents/a1/maps/brick")
        wait_until(lambda: maps_asked(world) == {"a1"}, what="a maps request for a1 alone")
    finally:
        if client is not None:
            client.close()
        stop.set()
        thread.join(5)
        bridge.close()


def _frame(tick: int) -> SensorFrame:
    """a1's frame of `tick`: its food ranges say the tick (to tell which frame a scan came from)."""
    ranges = tuple(float(tick) if c == 0 else 1.0 for c in range(len(CHANNELS)) for _ in range(4))
    return SensorFrame("a1", tick, 0.7, 0.0, 0.0, 4, ranges, True)


def test_a_client_of_an_agents_scans_gets_those_of_the_newest_views_tick(bus):
    from foxglove_schemas_protobuf.LaserScan_pb2 import LaserScan

    from conag.foxglove.live import FoxgloveBridge

    world = bus.server_session()
    frames = world.declare_publisher(keys.sensors(W, "a1"))
    bridge = FoxgloveBridge(bus.client_session(), W, port=0).start()
    client = None
    try:
        client = FoxgloveClient(f"ws://127.0.0.1:{bridge.port}")
        client.subscribe("/world/scene")
        wait_until(bridge.listener.watched, what="the scene watched")
        while "/agents/a1/scan/food" not in client.channels:  # advertised once a view names a1
            world.put(keys.view(W), encode(_view(10)))
            bridge.step()
            client.receive(0.1)
        client.subscribe("/agents/a1/scan/food")
        wait_until(lambda: bridge.step() is not None and frames.matching_status.matching,
                   what="the bridge subscribed to a1's frames")
        for tick in range(20, 36):  # the frames of ticks 20 to 35, the view of tick 30 among them
            frames.put(encode(_frame(tick)))
            if tick == 30:
                world.put(keys.view(W), encode(_view(30)))

        # Step the bridge until the scan comes, not just once: a view of tick 10 put above can
        # still be on its way, and a step that takes only it sends the scene (no frame of
        # tick 10 came) with the view of tick 30 yet to come (failed once so in CI).
        def scan_sent() -> bytes | None:
            bridge.step()
            try:
                return client.next_message("/agents/a1/scan/food", timeout=0.2, subscribed=True)
            except TimeoutError:
                return None

        scan = LaserScan.FromString(wait_until(scan_sent, what="a1's scan"))
        assert list(scan.ranges) == [30.0] * 4  # the frame of the view's tick, of the 16 that came
        assert (scan.pose.position.x, scan.pose.position.y) == (3.2, 4.4)  # a1's body in that view
    finally:
        if client is not None:
            client.close()
        bridge.close()


def test_the_more_agents_are_watched_the_less_often_each_is_asked_for_its_maps(bus):
    from conag.foxglove.live import MAPS_TOTAL_HZ, FoxgloveBridge

    now = [0.0]
    bridge = FoxgloveBridge(bus.client_session(), W, port=0, maps_every=10, clock=lambda: now[0])
    try:
        bridge.translator.view = _view(0)
        assert bridge._maps_interval(1) == 10 and bridge._maps_interval(10) == 100  # before the speed is known
        now[0], bridge.translator.view = 2.0, _view(200)  # 100 ticks a second
        assert bridge._maps_interval(1) == 100  # one agent: once a second, as the browser viewer
        for agents in (2, 10, 40):
            snapshots = agents * 100 / bridge._maps_interval(agents)  # a second, all agents together
            assert snapshots <= 2.5 * MAPS_TOTAL_HZ, agents
        assert bridge._maps_interval(10) >= 200
    finally:
        bridge.close()


def maps_asked(session) -> set[str]:
    """The agents some maps request token asks now."""
    replies = session.liveliness().get(f"{keys.world_root(W)}/alive/maps/**", timeout=1.0)
    return {str(r.ok.key_expr).split("/")[-2] for r in replies if r.ok is not None}


def test_a_bridge_nobody_watches_translates_nothing(bus):
    from conag.foxglove.live import FoxgloveBridge

    world = bus.server_session()
    bridge = FoxgloveBridge(bus.client_session(), W, port=0).start()
    try:
        world.put(keys.view(W), encode(_view(10)))
        time.sleep(0.3)
        assert bridge.step() == 0 and bridge.translator.view is None
        assert maps_asked(world) == set()  # nor does it ask the agents for their maps
    finally:
        bridge.close()


# --- the commands (slow) ---------------------------------------------------------------------------

def _bus_truth(path: Path) -> tuple[dict[int, WorldView], dict[tuple[str, int, str], AgentMap]]:
    """What the world and the agents published, from the recording's msgpack channels."""
    views, maps = {}, {}
    for e in read_recording(path).entries:
        if e.key.endswith("/view"):
            views[e.tick] = decode(e.data, WorldView)
        elif e.key.endswith("/maps"):
            m = decode(e.data, AgentMap)
            maps[(m.agent_id, m.tick, m.layer)] = m
    return views, maps


@pytest.fixture(scope="module")
def fig19_recording(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("fig19") / "r.mcap"
    run = conag("run", SCENARIOS / "fig19.toml", "--headless", "--quiet", "--max-ticks", "400", "--stall-ticks", "0",
                "--maps-every", "50", "--record", out, "--listen", f"tcp/127.0.0.1:{free_port()}", timeout=240)
    assert run.returncode in (0, 3), run.stdout + run.stderr
    return out


@pytest.mark.slow
def test_conag_run_record_writes_world_and_maps_an_outside_reader_checks(fig19_recording):
    views, maps = _bus_truth(fig19_recording)
    got = read_foxglove(fig19_recording)
    scenes = got["/world/scene"]
    assert len(scenes) >= 30 and {t for t, _ in scenes} <= set(views)
    for tick, update in scenes:
        assert_scene_matches(update, views[tick])
    grids = [(topic, tick, g) for topic, ms in got.items() if "/maps/" in topic for tick, g in ms]
    assert len(grids) >= len(MAP_LAYERS[:6]) * 4  # the six ESMs of four snapshots at least (every 50 ticks)
    for topic, tick, grid in grids:
        _, _, agent, _, layer = topic.split("/")
        assert_grid_matches(grid, maps[(agent, tick, layer)])
    assert got["/progress"][-1][1]["tick"] == max(views)


@pytest.mark.slow
def test_conag_run_foxglove_serves_a_live_run_to_a_client(tmp_path):
    from foxglove_schemas_protobuf.Grid_pb2 import Grid
    from foxglove_schemas_protobuf.SceneUpdate_pb2 import SceneUpdate

    port = free_port()
    run = Process("run", str(SCENARIOS / "fig19.toml"), "--headless", "--max-ticks", "20000", "--stall-ticks", "0",
                  "--listen", f"tcp/127.0.0.1:{free_port()}", "--foxglove", str(port))
    client = None
    try:
        run.wait_for("foxglove at ws://", 60)
        client = FoxgloveClient(f"ws://127.0.0.1:{port}")
        update = SceneUpdate.FromString(client.next_message("/world/scene", 60))
        es = entities(update)
        assert {"discs/brick", "sites"} <= set(es) and any(k.startswith("agents/") for k in es)
        assert len(es["sites"].cubes) > 0
        grid = Grid.FromString(client.next_message("/agents/a1/maps/brick", 60))  # asked for while watched
        assert grid.column_count > 0 and len(grid.data) == grid.column_count ** 2
    finally:
        if client is not None:
            client.close()
        run.stop(timeout=30)
        run.kill()


# --- Node readers (slow; skipped without node and tests/node's packages) ------------------------------

def _node(script: str, *args: str, timeout: float = 120) -> dict:
    node = shutil.which("node")
    if node is None:
        pytest.skip("no node on this machine")
    if not (NODE_DIR / "node_modules" / "@mcap" / "core").is_dir():
        pytest.skip("tests/node has no packages (cd tests/node && npm ci; .ci/run does it)")
    done = subprocess.run([node, str(NODE_DIR / script), *args], capture_output=True, text=True, timeout=timeout)
    assert done.returncode == 0, done.stdout + done.stderr
    return json.loads(done.stdout)


@pytest.mark.slow
def test_node_mcap_core_with_protobufjs_reads_the_world_and_a_map(fig19_recording):
    views, maps = _bus_truth(fig19_recording)
    got = _node("read_recording.mjs", str(fig19_recording))
    assert got["schemas"]["/world/scene"] == "foxglove.SceneUpdate"
    assert len(got["scenes"]) >= 30
    for scene in got["scenes"]:
        v = views[scene["tick"]]
        bodies = {a: (x, y) for a, x, y in scene["agents"]}
        assert bodies == pytest.approx({a: (x, y) for a, x, y in zip(v.agent_ids, v.agent_x, v.agent_y)})
        assert sorted(map(tuple, scene["bricks"])) == pytest.approx(
            sorted((x, y) for x, y, k in zip(v.disc_xs, v.disc_ys, v.disc_kinds) if k == "brick"))
    grid = got["grid"]
    m = maps[(grid["agent"], grid["tick"], grid["layer"])]
    rows = [grid["cells"][r * m.size:(r + 1) * m.size] for r in range(m.size)]
    assert [c for row in reversed(rows) for c in row] == list(m.cells)


@pytest.mark.slow
def test_node_foxglove_ws_protocol_client_decodes_a_scene_of_a_live_run():
    port = free_port()
    run = Process("run", str(SCENARIOS / "fig19.toml"), "--headless", "--max-ticks", "20000", "--stall-ticks", "0",
                  "--listen", f"tcp/127.0.0.1:{free_port()}", "--foxglove", str(port))
    try:
        run.wait_for("foxglove at ws://", 60)
        got = _node("live_client.mjs", f"ws://127.0.0.1:{port}", "/world/scene", timeout=90)
        assert got["schemaName"] == "foxglove.SceneUpdate"
        assert "sites" in got["entities"] and any(e.startswith("agents/") for e in got["entities"])
    finally:
        run.stop(timeout=30)
        run.kill()


def test_node_scripts_and_their_lockfile_are_there():
    # the Node tests skip without packages, never without their scripts
    for name in ("package.json", "package-lock.json", "read_recording.mjs", "live_client.mjs"):
        assert (NODE_DIR / name).is_file(), name
    assert {"@mcap/core", "@foxglove/ws-protocol", "protobufjs"} <= set(
        json.loads((NODE_DIR / "package.json").read_text())["dependencies"])


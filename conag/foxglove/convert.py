"""Bus messages to Foxglove's well-known schemas: the pure core of the recordings' and the
live server's Foxglove channels (no zenoh, no sockets).

A `Translator` takes the bus's messages one at a time (`feed(key, data, log_time)`, the bytes
as they travelled) and returns what they become, as `Derived` messages: a topic, its
schema (`SchemaDef`), the world tick and the encoded payload (protobuf, encoded by the
`foxglove-sdk` package; JSON for `/progress`). Everything is in the frame `world`: x east,
y north, z up, one unit one world unit; headings counter-clockwise from east.

* `/world/scene` (`foxglove.SceneUpdate`, from each WorldView): entities `discs/<kind>`
  (a flat cylinder per disc, coloured as the viewer colours them), `sites` (a flat square
  per drop site, dark yellow when filled), `agents/<id>` (body, heading arrow, the brick it
  holds, its id), and in a world with cues `cues/site` (a cross per site cue) and
  `cues/supply` (a diamond outline per supply cue), flat marks on the floor above the sites
  and under the discs, in the viewer's colours; a kind's entity is deleted when its last cue
  goes, and a world without cues has none. Each entity's metadata holds the `tick`;
* `/world/walls` (`SceneUpdate`, entity `walls`): the fixed wall cells, once, and again if
  they change;
* `/tf` (`foxglove.FrameTransforms`, from each WorldView): frame `<agent id>` in `world`,
  at the body's position and heading;
* `/agents/<id>/scan/<channel>` (`foxglove.LaserScan`): the sector sensors of one colour
  (food, water, brick, obstacle, agent), one point per sector at its middle bearing,
  compass-aligned, centred on the body; `inf` where nothing of that colour is in range.
  Of the SensorFrames only those of ticks that are a multiple of `scans_every` (the ticks
  the world publishes its views at) are translated, once the view of that tick is known;
* `/agents/<id>/maps/<layer>` (`foxglove.Grid`, from AgentMap): the agent's ESMs, NMs and
  Matching grid, one field `value` (uint8, 0 to MAP_LEVEL), compass-aligned and centred on
  where the world had the body at the newest view; row 0 of the grid is the south row (the
  AgentMap's last);
* `/log` (`foxglove.Log`): behaviours and blockers (AgentState; a blocker is a warning),
  attaches (Welcome), perturbations (Perturbed), lockstep timeouts (a warning);
* `/progress` (JSON, schema `conag.Progress`): tick, sites filled and total, agents alive,
  per WorldView: what a Plot panel draws.
"""

from __future__ import annotations

import functools
import json
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

import foxglove.messages as fm
import msgpack

from conag.recording.mcap_log import peek
from protocol.codec import MAX_MESSAGE_BYTES, ProtocolError, decode
from protocol.keys import check_id
from protocol.messages import (
    CHANNELS,
    CUE_KINDS,
    MAP_LAYERS,
    MAP_LEVEL,
    NO_READING,
    SCHEMA_VERSION,
    AgentMap,
    AgentState,
    LockstepTimeout,
    Perturbed,
    SensorFrame,
    Welcome,
    WorldView,
)
from world_server.config import WorldConfig

FRAME = "world"
SCENE = "/world/scene"
WALLS = "/world/walls"
TF = "/tf"
LOG = "/log"
PROGRESS = "/progress"
SCANS_EVERY = 10  # the world's default view_every: scans at the ticks views are published
PRIMITIVES_KEPT = 4096  # disc and site primitives kept for the next views (emptied when full)
COLOURS = {"food": "#3a9d23", "water": "#2a6fdb", "brick": "#b5462f", "wall": "#555555", "site": "#f2d27a",
           "filled": "#e0a100", "agent": "#6a3d9a", "dead": "#aaaaaa", "heading": "#111111",
           "cue_site": "#00838f", "cue_supply": "#ef6c00"}  # the viewer's
PROGRESS_SCHEMA = {
    "title": "conag.Progress", "type": "object",
    "properties": {"tick": {"type": "integer"}, "sites_filled": {"type": "integer"},
                   "sites_total": {"type": "integer"}, "agents_alive": {"type": "integer"}},
    "required": ["tick", "sites_filled", "sites_total", "agents_alive"],
}


@dataclass(frozen=True)
class SchemaDef:
    """A channel's schema as MCAP and the Foxglove WebSocket protocol declare it."""

    name: str              # e.g. foxglove.SceneUpdate
    encoding: str          # protobuf | jsonschema
    data: bytes            # a FileDescriptorSet, or the JSON schema's text
    message_encoding: str  # protobuf | json


@dataclass(frozen=True)
class Derived:
    """One Foxglove message made from a bus message: where it goes, its schema, its world
    tick and its encoded bytes."""

    topic: str
    schema: SchemaDef
    tick: int
    data: bytes


@functools.cache
def schema_of(kind: str) -> SchemaDef:
    """The schema of a well-known message type (`SceneUpdate`, ...) or of `Progress`."""
    if kind == "Progress":
        return SchemaDef("conag.Progress", "jsonschema", json.dumps(PROGRESS_SCHEMA).encode(), "json")
    s = getattr(fm, kind).get_schema()
    return SchemaDef(s.name, s.encoding, bytes(s.data), "protobuf")


def scan_topic(agent: str, channel: str) -> str:
    """The LaserScan topic of one agent's sensors of one colour."""
    return f"/agents/{agent}/scan/{channel}"


def map_topic(agent: str, layer: str) -> str:
    """The Grid topic of one layer of one agent's maps."""
    return f"/agents/{agent}/maps/{layer}"


def world_topics() -> dict[str, SchemaDef]:
    """The world's topics and their schemas (a live server advertises them before anything comes)."""
    return {SCENE: schema_of("SceneUpdate"), WALLS: schema_of("SceneUpdate"), TF: schema_of("FrameTransforms"),
            LOG: schema_of("Log"), PROGRESS: schema_of("Progress")}


def agent_topics(agent: str) -> dict[str, SchemaDef]:
    """One agent's topics (scans and maps) and their schemas."""
    out = {scan_topic(agent, c): schema_of("LaserScan") for c in CHANNELS}
    out.update({map_topic(agent, layer): schema_of("Grid") for layer in MAP_LAYERS})
    return out


def _stamp(ns: int) -> fm.Timestamp:
    return fm.Timestamp(ns // 1_000_000_000, ns % 1_000_000_000)


def _colour(name: str, alpha: float = 1.0) -> fm.Color:
    h = COLOURS[name]
    return fm.Color(r=int(h[1:3], 16) / 255, g=int(h[3:5], 16) / 255, b=int(h[5:7], 16) / 255, a=alpha)


def _yaw(heading: float) -> fm.Quaternion:
    return fm.Quaternion(x=0.0, y=0.0, z=math.sin(heading / 2), w=math.cos(heading / 2))


def _pose(x: float, y: float, z: float = 0.0, heading: float = 0.0) -> fm.Pose:
    return fm.Pose(position=fm.Vector3(x=x, y=y, z=z), orientation=_yaw(heading))


@dataclass(frozen=True)
class Geometry:
    """The sizes a picture needs, from the agents' Welcomes (WorldConfig's defaults until one comes)."""

    cell: float
    disc_radius: float
    agent_radius: float

    @classmethod
    def default(cls) -> Geometry:
        """WorldConfig's sizes."""
        c = WorldConfig()
        return cls(c.cell_size, c.disc_radius, c.agent_radius)


@dataclass(frozen=True)
class MapLayer:
    """An AgentMap as the translator needs it: its cells as bytes, one a cell, row 0 north."""

    agent_id: str
    tick: int
    layer: str
    size: int
    cells: bytes

    @classmethod
    def of(cls, m: AgentMap) -> MapLayer:
        """The layer of a decoded AgentMap."""
        return cls(m.agent_id, m.tick, m.layer, m.size, bytes(m.cells))


def decode_map(data: bytes) -> MapLayer:
    """An encoded AgentMap as a `MapLayer`, checked as `protocol.codec.decode` checks it (a
    ProtocolError for anything it would refuse), in a tenth of the time: the cells go
    straight from msgpack's list to bytes (C), with no tuple of ints and no check per cell in
    Python. A live server gets nine a snapshot from every agent it watches."""
    if len(data) > MAX_MESSAGE_BYTES:
        raise ProtocolError(f"message of {len(data)} bytes exceeds {MAX_MESSAGE_BYTES}")
    try:
        raw = msgpack.unpackb(data, raw=False, strict_map_key=True, use_list=True)
    except Exception as exc:  # noqa: BLE001 -- msgpack raises many types; all mean "not a message"
        raise ProtocolError(f"not msgpack: {exc}") from None
    if not isinstance(raw, dict) or set(raw) != {"v", "t", "f"} or type(raw["v"]) is not int \
            or raw["v"] != SCHEMA_VERSION or raw["t"] != "AgentMap":
        raise ProtocolError("not an AgentMap")
    f = raw["f"]
    if not isinstance(f, list) or len(f) != 5:
        raise ProtocolError("AgentMap: expected 5 fields")
    agent, tick, layer, size, cells = f
    if not (type(tick) is int and tick >= 0 and layer in MAP_LAYERS and type(size) is int
            and 1 <= size <= 89 and size % 2 == 1 and isinstance(cells, list) and len(cells) == size * size):
        raise ProtocolError("AgentMap: bad fields")
    try:
        check_id(agent, "agent id")
        grid = bytes(bytearray(cells))  # ints 0 to 255, else ValueError or TypeError; in C (bytes(list) is slow)
    except (TypeError, ValueError) as exc:
        raise ProtocolError(str(exc)) from None
    if not (grid.isascii() if MAP_LEVEL == 127 else max(grid) <= MAP_LEVEL):  # isascii: every byte <= 127
        raise ProtocolError(f"AgentMap.cells must be 0 to {MAP_LEVEL}")
    return MapLayer(agent, tick, layer, size, grid)


class Translator:
    """Bus messages in, Foxglove messages out (see the module). One per recording or live
    server; not thread-safe."""

    def __init__(self, scans_every: int = SCANS_EVERY):
        self.scans_every = scans_every
        self.geometry = Geometry.default()
        self.view: WorldView | None = None
        self._walls: tuple | None = None
        self._agents: set[str] = set()
        self._cue_kinds: set[str] = set()  # the cue entities the last scene showed
        self._frames: dict[str, SensorFrame] = {}  # per agent: its frame of a view tick, not yet translated
        # A disc or a site looks the same from one view to the next unless it moved or filled:
        # its primitive is made once and reused (most of a SceneUpdate's making, otherwise).
        self._primitives: dict[tuple, Any] = {}

    def feed(self, key: str, data: bytes, log_time: int) -> list[Derived]:
        """What the message `data` published on `key` at `log_time` (ns) becomes (often nothing)."""
        leaf = key.rsplit("/", 1)[-1]
        handler = _HANDLERS.get(leaf)
        if handler is None or (leaf == "sensors" and not self._wanted_frame(data)):
            return []
        try:
            msg = decode_map(data) if leaf == "maps" else decode(data, handler[0])
        except ProtocolError:
            return []
        return list(handler[1](self, msg, log_time))

    def resend_walls(self) -> None:
        """Send the walls again with the next view (a live client that came later has not seen them)."""
        self._walls = None

    def _wanted_frame(self, data: bytes) -> bool:
        tick = peek(data)[1]
        return tick is not None and self.scans_every > 0 and tick % self.scans_every == 0

    # --- the world ------------------------------------------------------------------------------
    def _on_view(self, v: WorldView, t: int) -> Iterable[Derived]:
        if self.view is not None and v.tick < self.view.tick:
            return
        self.view = v
        walls = (v.wall_xs, v.wall_ys)
        if walls != self._walls:
            self._walls = walls
            yield Derived(WALLS, schema_of("SceneUpdate"), v.tick, self._walls_update(v, t).encode())
        yield Derived(SCENE, schema_of("SceneUpdate"), v.tick, self.scene(v, t).encode())
        yield Derived(TF, schema_of("FrameTransforms"), v.tick, transforms(v, t).encode())
        filled = sum(v.site_filled)
        progress = {"tick": v.tick, "sites_filled": filled, "sites_total": len(v.site_xs),
                    "agents_alive": sum(v.agent_alive)}
        yield Derived(PROGRESS, schema_of("Progress"), v.tick, json.dumps(progress).encode())
        for agent in sorted(self._frames):
            yield from self._scans(agent, t)

    def scene(self, v: WorldView, t: int) -> fm.SceneUpdate:
        """The SceneUpdate of a WorldView (see the module)."""
        meta = [fm.KeyValuePair(key="tick", value=str(v.tick))]
        g = self.geometry
        entities = [self._discs(v, kind, t, meta) for kind in ("food", "water", "brick")]
        entities.append(self._entity("sites", t, meta, cubes=[
            self._kept(("site", g, x, y, f), _site_cube, g, x, y, f)
            for x, y, f in zip(v.site_xs, v.site_ys, v.site_filled)]))
        kinds = set(v.cue_kinds)
        entities += [self._cues(v, kind, t, meta) for kind in CUE_KINDS if kind in kinds]
        entities += [self._agent(v, i, t, meta) for i in range(len(v.agent_ids))]
        gone = [f"agents/{a}" for a in sorted(self._agents - set(v.agent_ids))]
        gone += [f"cues/{k}" for k in CUE_KINDS if k in self._cue_kinds - kinds]
        self._agents, self._cue_kinds = set(v.agent_ids), kinds
        deletions = [fm.SceneEntityDeletion(timestamp=_stamp(t), type=fm.SceneEntityDeletionType.MatchingId, id=eid)
                     for eid in gone]
        return fm.SceneUpdate(deletions=deletions, entities=entities)

    def _entity(self, eid: str, t: int, meta: list, **primitives) -> fm.SceneEntity:
        return fm.SceneEntity(timestamp=_stamp(t), frame_id=FRAME, id=eid, metadata=meta, **primitives)

    def _kept(self, key: tuple, make: Callable[..., Any], *args: Any) -> Any:
        """`make(*args)`, made once per `key` (what the primitive shows; one is never changed once made)."""
        p = self._primitives.get(key)
        if p is None:
            if len(self._primitives) >= PRIMITIVES_KEPT:
                self._primitives.clear()
            p = self._primitives[key] = make(*args)
        return p

    def _discs(self, v: WorldView, kind: str, t: int, meta: list) -> fm.SceneEntity:
        g = self.geometry
        return self._entity(f"discs/{kind}", t, meta, cylinders=[
            self._kept(("disc", g, kind, x, y), _disc_cylinder, g, kind, x, y)
            for x, y, k in zip(v.disc_xs, v.disc_ys, v.disc_kinds) if k == kind])

    def _cues(self, v: WorldView, kind: str, t: int, meta: list) -> fm.SceneEntity:
        g = self.geometry
        bars = [self._kept(("cue", g, kind, x, y), _cue_bars, g, kind, x, y)
                for x, y, k in zip(v.cue_xs, v.cue_ys, v.cue_kinds) if k == kind]
        return self._entity(f"cues/{kind}", t, meta, cubes=[b for mark in bars for b in mark])

    def _agent(self, v: WorldView, i: int, t: int, meta: list) -> fm.SceneEntity:
        aid, x, y, h = v.agent_ids[i], v.agent_x[i], v.agent_y[i], v.agent_heading[i]
        r = self.geometry.agent_radius
        cylinders = [fm.CylinderPrimitive(pose=_pose(x, y, 0.15), size=fm.Vector3(x=2 * r, y=2 * r, z=0.3),
                                          bottom_scale=1.0, top_scale=1.0,
                                          color=_colour("agent" if v.agent_alive[i] else "dead"))]
        if v.agent_holding[i]:
            d = self.geometry.disc_radius
            cylinders.append(fm.CylinderPrimitive(pose=_pose(x, y, 0.4), size=fm.Vector3(x=d, y=d, z=0.2),
                                                  bottom_scale=1.0, top_scale=1.0, color=_colour("brick")))
        arrow = fm.ArrowPrimitive(pose=_pose(x, y, 0.32, h), shaft_length=r, shaft_diameter=r / 4,
                                  head_length=r / 2, head_diameter=r / 2, color=_colour("heading"))
        label = fm.TextPrimitive(pose=_pose(x, y, 0.7), billboard=True, font_size=12.0, scale_invariant=True,
                                 color=_colour("heading"), text=aid)
        holding = [*meta, fm.KeyValuePair(key="holding", value=str(bool(v.agent_holding[i])).lower())]
        return self._entity(f"agents/{aid}", t, holding, cylinders=cylinders, arrows=[arrow], texts=[label])

    def _walls_update(self, v: WorldView, t: int) -> fm.SceneUpdate:
        c = self.geometry.cell
        size = fm.Vector3(x=c, y=c, z=0.5)
        cubes = [fm.CubePrimitive(pose=_pose(x, y, 0.25), size=size, color=_colour("wall"))
                 for x, y in zip(v.wall_xs, v.wall_ys)]
        meta = [fm.KeyValuePair(key="tick", value=str(v.tick))]
        return fm.SceneUpdate(entities=[self._entity("walls", t, meta, cubes=cubes)])

    # --- the agents -----------------------------------------------------------------------------
    def _on_frame(self, f: SensorFrame, t: int) -> Iterable[Derived]:
        self._frames[f.agent_id] = f
        yield from self._scans(f.agent_id, t)

    def _scans(self, agent: str, t: int) -> Iterable[Derived]:
        """The LaserScans of `agent`'s pending frame, once the view of its tick is known."""
        f, v = self._frames.get(agent), self.view
        if f is None or v is None or v.tick != f.tick or agent not in v.agent_ids:
            return
        del self._frames[agent]
        i = v.agent_ids.index(agent)
        step = 2 * math.pi / f.sectors
        pose = _pose(v.agent_x[i], v.agent_y[i], 0.2)
        for c, channel in enumerate(CHANNELS):
            ranges = [math.inf if r == NO_READING else r for r in f.ranges[c * f.sectors:(c + 1) * f.sectors]]
            scan = fm.LaserScan(timestamp=_stamp(t), frame_id=FRAME, pose=pose, start_angle=step / 2,
                                end_angle=(f.sectors - 0.5) * step, ranges=ranges, intensities=[float(c)] * f.sectors)
            yield Derived(scan_topic(agent, channel), schema_of("LaserScan"), f.tick, scan.encode())

    def _on_map(self, m: MapLayer, t: int) -> Iterable[Derived]:
        yield Derived(map_topic(m.agent_id, m.layer), schema_of("Grid"), m.tick, self.grid(m, t).encode())

    def grid(self, m: MapLayer | AgentMap, t: int) -> fm.Grid:
        """The Grid of one AgentMap layer, centred on where the newest view has the agent (the
        world's centre when none has it)."""
        if isinstance(m, AgentMap):
            m = MapLayer.of(m)
        x, y = self._where(m.agent_id)
        c = self.geometry.cell
        half = m.size * c / 2
        n, cells = m.size, m.cells
        rows = [cells[r * n:(r + 1) * n] for r in range(n - 1, -1, -1)]  # south first
        return fm.Grid(timestamp=_stamp(t), frame_id=FRAME, pose=_pose(x - half, y - half), column_count=m.size,
                       cell_size=fm.Vector2(x=c, y=c), row_stride=m.size, cell_stride=1,
                       fields=[fm.PackedElementField(name="value", type=fm.PackedElementFieldNumericType.Uint8)],
                       data=b"".join(rows))

    def _where(self, agent: str) -> tuple[float, float]:
        v = self.view
        if v is None:
            return 0.0, 0.0
        if agent in v.agent_ids:
            i = v.agent_ids.index(agent)
            return v.agent_x[i], v.agent_y[i]
        return v.width / 2, v.height / 2

    # --- the log --------------------------------------------------------------------------------
    def _on_welcome(self, w: Welcome, t: int) -> Iterable[Derived]:
        if w.cell_size > 0 and w.disc_radius > 0 and w.agent_radius > 0:
            self.geometry = Geometry(w.cell_size, w.disc_radius, w.agent_radius)
        yield _log(t, w.tick, fm.LogLevel.Info, w.agent_id,
                   f"{w.agent_id} attached to body {w.body} at ({w.x:.2f}, {w.y:.2f}), tick {w.tick}")

    def _on_state(self, s: AgentState, t: int) -> Iterable[Derived]:
        text = f"tick {s.tick}: {s.behaviour}, {'holding a brick, ' if s.holding else ''}{s.sites_open} sites open"
        if s.blocker:
            yield _log(t, s.tick, fm.LogLevel.Warning, s.agent_id, f"{text}; stalled: {s.blocker}")
        else:
            yield _log(t, s.tick, fm.LogLevel.Info, s.agent_id, text)

    def _on_perturbed(self, p: Perturbed, t: int) -> Iterable[Derived]:
        where = f"({p.x:.2f}, {p.y:.2f})" + (f" to ({p.to_x:.2f}, {p.to_y:.2f})" if p.op == "move" else "")
        yield _log(t, p.tick, fm.LogLevel.Info if p.ok else fm.LogLevel.Warning, "world",
                   f"tick {p.tick}: {p.op} {p.kind} at {where}: {'done' if p.ok else p.message}")

    def _on_timeout(self, lt: LockstepTimeout, t: int) -> Iterable[Derived]:
        yield _log(t, lt.tick, fm.LogLevel.Warning, "world",
                   f"tick {lt.tick}: stepped without the commands of {', '.join(lt.agent_ids)}")


def _site_cube(g: Geometry, x: float, y: float, filled: bool) -> fm.CubePrimitive:
    return fm.CubePrimitive(pose=_pose(x, y, 0.005), size=fm.Vector3(x=g.cell * 0.9, y=g.cell * 0.9, z=0.01),
                            color=_colour("filled" if filled else "site"))


def _cue_bars(g: Geometry, kind: str, x: float, y: float) -> list[fm.CubePrimitive]:
    """A cue's mark as thin flat bars (cubes): a cross for a site cue, a diamond outline for a
    supply cue, as the viewer draws them. Both lie within a disc's radius, so a brick on a
    marked cell hides its mark (the world's sensors do not see it either), and sit on the
    floor just above the site squares (z 0 to 0.01) and under the discs."""
    c, width, z = g.cell, 0.1 * g.cell, 0.02
    colour = _colour(f"cue_{kind}")
    if kind == "site":
        arm = 0.3 * c  # the cross's half-width along x and y
        return [fm.CubePrimitive(pose=_pose(x, y, z, h), size=fm.Vector3(x=2 * arm * math.sqrt(2), y=width, z=0.01),
                                 color=colour) for h in (math.pi / 4, -math.pi / 4)]
    a = 0.38 * c  # the diamond's corners, along x and y from its centre
    return [fm.CubePrimitive(pose=_pose(x + sx * a / 2, y + sy * a / 2, z, math.atan2(sy, -sx)),
                             size=fm.Vector3(x=a * math.sqrt(2), y=width, z=0.01), color=colour)
            for sx, sy in ((1, 1), (-1, 1), (-1, -1), (1, -1))]


def _disc_cylinder(g: Geometry, kind: str, x: float, y: float) -> fm.CylinderPrimitive:
    d = 2 * g.disc_radius
    return fm.CylinderPrimitive(pose=_pose(x, y, 0.05), size=fm.Vector3(x=d, y=d, z=0.1), bottom_scale=1.0,
                                top_scale=1.0, color=_colour(kind))


def _log(t: int, tick: int, level: fm.LogLevel, name: str, text: str) -> Derived:
    msg = fm.Log(timestamp=_stamp(t), level=level, message=text, name=name)
    return Derived(LOG, schema_of("Log"), tick, msg.encode())


def transforms(v: WorldView, t: int) -> fm.FrameTransforms:
    """Each body's frame (its id) in `world`: its position and heading at the view's tick."""
    return fm.FrameTransforms(transforms=[
        fm.FrameTransform(timestamp=_stamp(t), parent_frame_id=FRAME, child_frame_id=aid,
                          translation=fm.Vector3(x=x, y=y, z=0.0), rotation=_yaw(h))
        for aid, x, y, h in zip(v.agent_ids, v.agent_x, v.agent_y, v.agent_heading)])


# the last part of a key -> (the type published there, the translator's handler)
_HANDLERS: dict[str, tuple[type, Callable[[Translator, Any, int], Iterable[Derived]]]] = {
    "view": (WorldView, Translator._on_view),
    "sensors": (SensorFrame, Translator._on_frame),
    "maps": (AgentMap, Translator._on_map),  # decoded by decode_map
    "welcome": (Welcome, Translator._on_welcome),
    "state": (AgentState, Translator._on_state),
    "perturbed": (Perturbed, Translator._on_perturbed),
    "lockstep_timeout": (LockstepTimeout, Translator._on_timeout),
}


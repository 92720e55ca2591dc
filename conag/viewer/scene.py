"""What the viewer draws, folded from bus messages (the pure core of `conag view`).

A `Scene` takes messages one at a time (`apply`, or `apply_bytes` for what came off the
wire) and gives the picture as a dict of plain lists and numbers (`picture`), the JSON the
page draws:

* `tick`, `width`, `height`; `discs` as [x, y, kind]; `sites` as [x, y, filled]; `walls`
  as [x, y]; `cues` as [x, y, kind] (the marks foremen put on the floor: docs/society.md;
  empty in a world without cues): from the newest WorldView;
* `agents`: per body its id, x, y, heading, holding, alive (WorldView), and from its
  newest AgentState its behaviour, sites it believes open and blocker; from its newest
  Decision (learning students publish one per step) its six state nodes;
* `progress`: [tick, sites filled] points, one per tick that changed the count (and the
  first and newest), thinned to at most `max_progress` points on long runs;
* `scenario`, `mode`, `sites_filled`, `sites_total`, `agents_alive`, `completed` from
  WorldStatus (sites and agents alive from the view when it is newer).

A `Timeline` replays a recording's entries through a Scene and keeps one picture per
recorded WorldView, so a page can scrub: `at(tick)` is the picture of the newest view at
or before `tick`; `maps_at(agent, tick)` the agent's newest map snapshot (AgentMap
messages, recorded with `--maps-every`), as `maps_picture` gives it.
"""

from __future__ import annotations

import base64
import bisect
import json
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any, Protocol

from protocol.codec import ProtocolError, decode
from protocol.messages import BEHAVIOURS, AgentMap, AgentState, Decision, WorldStatus, WorldView

STATE_NODES = ("holding_brick", "at_drop_site", "at_brick", "near_brick", "brick_available",
               "drop_site_available")  # Decision.state, in order
# Pictures a second sent to a live page. Each picture costs a browser a frame (style, layout,
# raster, composite) whatever it redraws: a headless Chromium with software rendering took
# 5.3-5.8% of a core at 10 a second and 3.7-4.2% at 5, following a 10-agent lockstep build
# on the run's own two cores (bench/bench_view.py, docs/results/benchmarks.md). `conag view --display-hz`.
DISPLAY_HZ = 5.0
# The page asks for the shown agent's maps once a second (viewer.js), so a live viewer asks
# that agent for about one snapshot a second, whatever the run's speed: at every 10 ticks, a
# 10-agent lockstep run at 70 ticks/s made 7 a second, each about 1.2 ms on the run's serial
# chain (asking less often measured no gain in bench_view, within its noise: docs/results/benchmarks.md).
MAPS_HZ = 1.0
MAPS_STEPS = (10, 20, 50, 100, 200, 500, 1000, 2000, 5000)  # the intervals asked for (a token each)
LEAVES = ("view", "status", "state", "decision", "maps")  # the keys a viewer listens to (their last part)
_TYPES = (WorldView, WorldStatus, AgentState, Decision)


def maps_interval(ticks_per_second: float, floor: int) -> int:
    """Ticks between the shown agent's map snapshots for a run going at `ticks_per_second`:
    the largest of `MAPS_STEPS` that still gives about `MAPS_HZ` a second, never fewer
    ticks than `floor` (`conag view --maps-every`); 0 when `floor` is 0 (maps off).

    The steps are coarse so that a run's speed wobbling does not make the viewer take its
    request back and ask again at each page ask."""
    if floor <= 0:
        return 0
    fit = [s for s in MAPS_STEPS if s <= ticks_per_second / MAPS_HZ]
    return max(floor, fit[-1] if fit else floor)


def static_dir() -> Path:
    """The directory holding the page (index.html, viewer.js)."""
    return Path(__file__).resolve().parent / "static"


def maps_picture(layers: Iterable[AgentMap]) -> dict[str, Any]:
    """An agent's map snapshot as the page draws it: `{"tick", "size", "layers": {name: cells}}`
    (the newest tick among `layers`, and only the layers of that tick), each layer's cells
    the base64 of its size x size bytes (values 0 to MAP_LEVEL), row by row: a tenth of
    the work of JSON numbers, for the viewer and for a page on the run's own cores."""
    layers = list(layers)
    if not layers:
        return {"tick": None, "size": 0, "layers": {}}
    tick = max(m.tick for m in layers)
    now = [m for m in layers if m.tick == tick]
    return {"tick": tick, "size": now[0].size,
            "layers": {m.layer: base64.b64encode(bytes(m.cells)).decode("ascii") for m in now}}


def layer_cells(encoded: str) -> list[int]:
    """A layer of `maps_picture` back as its cell values."""
    return list(base64.b64decode(encoded))


def decode_maps(raw: Iterable[bytes]) -> list[AgentMap]:
    """The AgentMaps among `raw` encoded messages (others and bad ones left out)."""
    out = []
    for data in raw:
        try:
            msg = decode(data, AgentMap)
        except ProtocolError:
            continue
        if isinstance(msg, AgentMap):
            out.append(msg)
    return out


def decode_newest_maps(raw: list[bytes]) -> list[AgentMap]:
    """The AgentMaps of the newest snapshot among `raw` (in arrival order, a snapshot's layers
    together), decoded from the end back to the first message of an older tick: a live viewer
    keeps the last 16 messages, and each decode checks every one of a layer's cells."""
    out: list[AgentMap] = []
    for data in reversed(raw):
        got = decode_maps([data])
        if not got:
            continue
        if out and got[0].tick != out[0].tick:
            break
        out.append(got[0])
    return out[::-1]


def wanted(key: str) -> bool:
    """Whether a viewer needs the messages on `key` (a WorldView, status, agent state or decision)."""
    return key.rsplit("/", 1)[-1] in LEAVES


def _r(v: float) -> float:
    return round(v, 3)  # millimetres of a cell: enough to draw, a third of the JSON


class Scene:
    """The newest state of everything drawn; see the module."""

    def __init__(self, max_progress: int = 2000):
        self.view: WorldView | None = None
        self.status: WorldStatus | None = None
        self.states: dict[str, AgentState] = {}
        self.decisions: dict[str, Decision] = {}
        self.progress: list[list[int]] = []
        self.max_progress = max_progress
        self.version = 0  # +1 per message applied: a server sends a picture only when it changed

    def apply_bytes(self, data: bytes) -> bool:
        """Decode and apply one message; False (and nothing changes) for one the viewer does not use."""
        try:
            msg = decode(data, _TYPES)
        except ProtocolError:
            return False
        return self.apply(msg)

    def apply(self, msg: object) -> bool:
        """Apply one decoded message; True if it is one the viewer draws."""
        if isinstance(msg, WorldView):
            if self.view is not None and msg.tick < self.view.tick:
                return False  # an older view arriving late (a query's answer after a publication)
            self.view = msg
            self._progress(msg.tick, sum(msg.site_filled))
        elif isinstance(msg, WorldStatus):
            if self.status is not None and (msg.tick, msg.seq) < (self.status.tick, self.status.seq):
                return False
            self.status = msg
            self._progress(msg.tick, msg.sites_filled)
        elif isinstance(msg, AgentState):
            self.states[msg.agent_id] = msg
        elif isinstance(msg, Decision):
            if self.decisions.get(msg.agent_id) == msg:
                return False  # asked again with no new tick (a paused world): nothing to redraw
            self.decisions[msg.agent_id] = msg
        else:
            return False
        self.version += 1
        return True

    def _progress(self, tick: int, filled: int) -> None:
        p = self.progress
        if p and tick < p[-1][0]:
            return
        if p and tick == p[-1][0]:
            p[-1][1] = filled
        elif len(p) >= 2 and p[-1][1] == filled == p[-2][1]:
            p[-1][0] = tick  # a flat stretch: move its end along
        else:
            p.append([tick, filled])
        if len(p) > self.max_progress:
            self.progress = p[:1] + p[1:-1:2] + p[-1:]  # halve, keeping the first and the newest

    def picture(self, progress: bool = True) -> dict[str, Any]:
        """The picture as JSON-ready data (see the module); `progress=False` leaves out the
        chart's points (a timeline sends them once)."""
        v, st = self.view, self.status
        out: dict[str, Any] = {"tick": 0, "width": 0.0, "height": 0.0, "discs": [], "sites": [], "walls": [],
                               "cues": [], "agents": []}
        if st is not None:
            out.update(tick=st.tick, scenario=st.scenario, mode=st.mode, sites_filled=st.sites_filled,
                       sites_total=st.sites_total, agents_alive=st.agents_alive, completed=st.completed)
        if v is not None:
            out.update(width=v.width, height=v.height,
                       discs=[[_r(x), _r(y), k] for x, y, k in zip(v.disc_xs, v.disc_ys, v.disc_kinds)],
                       sites=[[_r(x), _r(y), f] for x, y, f in zip(v.site_xs, v.site_ys, v.site_filled)],
                       walls=[[_r(x), _r(y)] for x, y in zip(v.wall_xs, v.wall_ys)],
                       cues=[[_r(x), _r(y), k] for x, y, k in zip(v.cue_xs, v.cue_ys, v.cue_kinds)],
                       agents=[self._agent(v, i) for i in range(len(v.agent_ids))])
            if st is None or v.tick >= st.tick:
                filled = sum(v.site_filled)
                out.update(tick=v.tick, sites_filled=filled, sites_total=len(v.site_xs),
                           agents_alive=sum(v.agent_alive))
                if st is not None:
                    out["completed"] = filled == len(v.site_xs) > 0
        if progress:
            out["progress"] = [list(p) for p in self.progress]
        return out

    def _agent(self, v: WorldView, i: int) -> dict[str, Any]:
        aid = v.agent_ids[i]
        a: dict[str, Any] = {"id": aid, "x": _r(v.agent_x[i]), "y": _r(v.agent_y[i]),
                             "heading": _r(v.agent_heading[i]), "holding": v.agent_holding[i],
                             "alive": v.agent_alive[i]}
        s = self.states.get(aid)
        if s is not None:
            a.update(behaviour=s.behaviour, state_tick=s.tick, sites_open=s.sites_open, blocker=s.blocker,
                     behaviour_ticks={b: t for b, t in zip(BEHAVIOURS, s.behaviour_ticks) if t})
        d = self.decisions.get(aid)
        if d is not None:
            a.update(state_nodes=dict(zip(STATE_NODES, (_r(x) for x in d.state))), arm=d.arm, motor=d.motor,
                     decision_tick=d.tick)
        return a


class _Entry(Protocol):  # read-only, so a frozen dataclass (mcap_log.Entry) is one
    @property
    def key(self) -> str: ...
    @property
    def tick(self) -> int: ...
    @property
    def data(self) -> bytes: ...


class Timeline:
    """One picture per recorded WorldView, for scrubbing a recording (see the module).

    `ticks[i]` is the tick of `pictures[i]` (JSON text, ready to send); `progress` is the
    chart over the whole recording; `info` whatever the recording's metadata said.
    """

    def __init__(self, ticks: list[int], pictures: list[str], progress: list[list[int]], info: dict[str, Any],
                 maps: dict[str, tuple[list[int], list[list[bytes]]]] | None = None):
        self.ticks = ticks
        self.pictures = pictures
        self.progress = progress
        self.info = info
        self.maps = maps or {}  # agent -> (ticks, the encoded AgentMaps of each tick)

    @classmethod
    def from_entries(cls, entries: Iterable[_Entry], info: dict[str, Any] | None = None,
                     dumps: Callable[[Any], str] = json.dumps) -> Timeline:
        """Fold a recording's entries (anything with `key`, `tick` and `data`, in recorded order)."""
        scene = Scene(max_progress=10**9)
        ticks: list[int] = []
        pictures: list[str] = []
        maps: dict[str, tuple[list[int], list[list[bytes]]]] = {}
        for e in entries:
            if e.key.endswith("/maps"):
                agent = e.key.rsplit("/", 2)[-2]
                mt, layers = maps.setdefault(agent, ([], []))
                if not mt or mt[-1] != e.tick:
                    mt.append(e.tick)
                    layers.append([])
                layers[-1].append(e.data)
                continue
            if not wanted(e.key) or not scene.apply_bytes(e.data):
                continue
            if e.key.endswith("/view") and scene.view is not None and scene.view.tick == e.tick:
                picture = dumps(scene.picture(progress=False))
                if ticks and ticks[-1] == e.tick:
                    pictures[-1] = picture  # a second view of one tick (after a perturbation): the newer
                else:
                    ticks.append(e.tick)
                    pictures.append(picture)
        return cls(ticks, pictures, scene.progress, dict(info or {}), maps)

    def __len__(self) -> int:
        return len(self.ticks)

    def index(self, tick: int) -> int:
        """Index of the newest picture at or before `tick` (the first one before them all); -1 if none."""
        if not self.ticks:
            return -1
        return max(bisect.bisect_right(self.ticks, tick) - 1, 0)

    def at(self, tick: int) -> str | None:
        """The picture (JSON text) to show at `tick`, or None for a recording without views."""
        i = self.index(tick)
        return None if i < 0 else self.pictures[i]

    def maps_at(self, agent: str, tick: int) -> dict[str, Any]:
        """`agent`'s newest map snapshot at or before `tick` (see `maps_picture`)."""
        mt, layers = self.maps.get(agent, ([], []))
        i = bisect.bisect_right(mt, tick) - 1
        return maps_picture(decode_maps(layers[i]) if i >= 0 else [])

    def summary(self) -> dict[str, Any]:
        """What the page needs to draw the timeline: first and last tick, every picture's
        tick, the progress chart and the recording's metadata."""
        return {"first": self.ticks[0] if self.ticks else 0, "last": self.ticks[-1] if self.ticks else 0,
                "ticks": self.ticks, "progress": self.progress, "info": self.info,
                "maps_of": sorted(self.maps)}

"""The viewer's shell (`conag view`): an HTTP server for the page, fed by the bus or a recording.

The standard library's `ThreadingHTTPServer` serves the page (`conag/viewer/static/`) and a small
JSON API; the picture itself is built by the pure `conag.viewer.scene`:

* `GET /api/info`: `{"mode": "live" | "recording", ...}`;
* live (`LiveFeed`): zenoh subscriptions to the world's WorldView, status and agent states
  fold into one `Scene` under a lock; the decisions and maps of the agent the page shows
  only (its newest Decision asked for at most `display_hz` times a second, not every
  tick's; its maps about once a second); `GET /api/scene` is the picture now and
  `GET /api/events` a Server-Sent Events stream sending it at `display_hz` (`DISPLAY_HZ`, 5 a second),
  only when something changed: a run of any speed costs the page five pictures a second,
  and the world nothing but a WorldView every `view_every` ticks; the same stream pushes
  the shown agent's maps (event `maps`, as `/api/maps` gives them, with `agent`) once a
  second when they changed;
* recording (`Timeline`): `GET /api/timeline` (ticks, progress, metadata) and
  `GET /api/frame?tick=T`, the picture of the newest view at or before T;
* `GET /api/maps?agent=ID[&tick=T]`: that agent's newest map snapshot (at or before T in a
  recording), `{"tick", "size", "layers": {name: base64 cells}}` (agents publish them while a
  viewer or recorder asks, `--maps-every`);
* `POST /api/perturb` with `{"op", "x", "y", "to_x", "to_y", "kind"}`: the world's perturb
  query (remove or move a disc from the page), answered with the PerturbResult as JSON.

Each route has one handler per source it serves, in the request handler's `GET_ROUTES` and
`POST_ROUTES` tables; a route the source does not serve is a 404.
"""

from __future__ import annotations

import json
import logging
import mimetypes
import os
import threading
import time
from collections.abc import Callable
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any, ClassVar
from urllib.parse import parse_qs, urlparse

import zenoh

from conag.viewer.scene import (
    DISPLAY_HZ,
    LEAVES,
    Scene,
    Timeline,
    decode_newest_maps,
    maps_interval,
    maps_picture,
    static_dir,
)
from protocol import keys
from protocol.bus import Declarations, undeclare
from protocol.codec import decode, encode
from protocol.messages import Perturbation, PerturbResult

DEFAULT_PORT = 8765  # the HTTP port of `conag view` (and of `conag run --view` without one)

log = logging.getLogger("conag.view")


class LiveFeed:
    """One world's messages folded into a Scene (thread-safe), and its perturb query.

    Everything costly to the run is asked for only for the agent the page shows (`select`):
    its newest Decision, by a query as a picture is built (at most once every
    `decision_period` seconds; a subscription took every tick's, 50-100 a second), and, with
    `maps_every` N, its maps (a maps request token for that agent alone) about once a page
    ask: every N ticks at first, then every `maps_interval` ticks for the run's speed as
    measured between the page's asks, never more often than every N. With no agent
    selected the agents send the viewer nothing but their AgentState reports (every 100
    ticks).
    """

    def __init__(self, session: zenoh.Session, world_id: str, maps_every: int = 0, requester: str | None = None,
                 clock: Callable[[], float] = time.monotonic, decision_period: float = 1.0 / DISPLAY_HZ):
        self.session = session
        self.world_id = world_id
        self.maps_every = maps_every
        self.requester = requester or f"viewer-{os.getpid()}"
        self.clock = clock
        self.decision_period = decision_period
        self._decision_asked = -float("inf")  # clock time of the last decision query
        self.selected: str | None = None
        self.asked_every = 0              # the interval of the maps request token up now (0: none)
        self._maps_token: Any = None
        self._last_ask: tuple[float, int] | None = None  # (clock, tick) at the page's last maps ask
        self._select_lock = threading.Lock()
        self.scene = Scene()
        self._lock = threading.Lock()
        self._cache: tuple[int, str] = (-1, "")
        self._maps: dict[str, list[bytes]] = {}  # the newest AgentMaps of each agent, undecoded
        self._maps_cache: tuple[str, list[bytes], dict[str, Any]] = ("", [], {})  # agent, its raw maps, their picture
        self._declared = Declarations()

    def start(self) -> LiveFeed:
        """Subscribe, then ask for the current view and status (a world that is not ticking
        publishes no view until it does)."""
        root = keys.world_root(self.world_id)
        for leaf in LEAVES:
            if leaf == "decision":
                continue  # only the selected agent's, asked for (`picture`)
            key = f"{root}/{leaf}" if leaf in ("view", "status") else keys.all_agents(self.world_id, leaf)
            self._declared.add(self.session.declare_subscriber(key, self._on_sample))
        self.refresh()
        return self

    def select(self, agent: str) -> None:
        """Follow `agent` in detail: its Decisions, and its maps every `maps_every` ticks."""
        keys.check_id(agent, "agent id")
        with self._select_lock:
            if agent == self.selected:
                return
            undeclare(self._maps_token)
            self.selected = agent
            self._maps_token, self.asked_every, self._last_ask = None, 0, None
            self._ask_maps(self.maps_every)
            self._decision_asked = -float("inf")
        self._ask_decision()

    def _ask_maps(self, every: int) -> None:
        """Put the selected agent's maps request at `every` ticks (the old one goes after the
        new one is up, so the agent is never left without one); 0 takes it back."""
        if every == self.asked_every or self.selected is None:
            return
        old = self._maps_token
        self._maps_token = self.session.liveliness().declare_token(
            keys.maps_request_token(self.world_id, self.requester, every, self.selected)) if every else None
        self.asked_every = every
        undeclare(old)

    def _retune_maps(self) -> None:
        """At a page ask: the maps request's interval for the run's speed since the last ask."""
        with self._lock:
            tick = max((m.tick for m in (self.scene.view, self.scene.status) if m is not None), default=0)
        now = self.clock()
        with self._select_lock:
            last, self._last_ask = self._last_ask, (now, tick)
            if last is not None and now > last[0] and tick >= last[1]:
                self._ask_maps(maps_interval((tick - last[1]) / (now - last[0]), self.maps_every))

    def refresh(self, timeout: float = 2.0) -> None:
        """Query the world's view and status now."""
        for key in (keys.view(self.world_id), keys.status(self.world_id)):
            for reply in self.session.get(key, timeout=timeout):
                if reply.ok is not None:
                    self._apply(reply.ok.payload.to_bytes())

    def _on_sample(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        if key.endswith("/maps"):
            with self._lock:
                self._maps.setdefault(keys.agent_of(key) or "", []).append(sample.payload.to_bytes())
                del self._maps[keys.agent_of(key) or ""][:-16]  # a snapshot has at most 9 layers
        else:
            self._apply(sample.payload.to_bytes())

    def _apply(self, data: bytes) -> None:
        with self._lock:
            self.scene.apply_bytes(data)

    def _ask_decision(self) -> None:
        """Ask the selected agent for its newest Decision, unless asked within
        `decision_period`; the answer comes to `_on_decision` (the query does not wait)."""
        agent, now = self.selected, self.clock()
        if agent is None or now - self._decision_asked < self.decision_period:
            return
        self._decision_asked = now
        self.session.get(keys.decision(self.world_id, agent), self._on_decision, timeout=max(self.decision_period, 1.0))

    def _on_decision(self, reply: zenoh.Reply) -> None:
        if reply.ok is not None and keys.agent_of(str(reply.ok.key_expr)) == self.selected:
            self._apply(reply.ok.payload.to_bytes())

    def picture(self) -> tuple[int, str]:
        """(version, JSON text) of the picture now; built once per change. Asks for the
        shown agent's newest Decision for the next one."""
        self._ask_decision()
        with self._lock:
            version = self.scene.version
            if self._cache[0] != version:
                self._cache = (version, json.dumps(self.scene.picture()))
            return self._cache

    def maps(self, agent: str) -> dict[str, Any]:
        """`agent`'s newest map snapshot (see `conag.viewer.scene.maps_picture`); selects it."""
        self.select(agent)
        self._retune_maps()
        with self._lock:
            raw = list(self._maps.get(agent, ()))
        cached = self._maps_cache
        if cached[0] == agent and cached[1] == raw:
            return cached[2]  # nothing new since the page's last ask (it asks about once a second)
        picture = maps_picture(decode_newest_maps(raw))
        self._maps_cache = (agent, raw, picture)
        return picture

    def perturb(self, p: Perturbation, timeout: float = 5.0) -> PerturbResult:
        """Ask the world for `p`; a PerturbResult either way (not ok when no world answers)."""
        for reply in self.session.get(keys.perturb(self.world_id), payload=encode(p), timeout=timeout):
            if reply.ok is not None:
                return decode(reply.ok.payload.to_bytes(), PerturbResult)
            return PerturbResult(False, reply.err.payload.to_string()[:200], 0)
        return PerturbResult(False, f"no world {self.world_id!r} answered within {timeout:g} s", 0)

    def close(self) -> None:
        """Undeclare the subscriptions and the maps request (the session is the caller's)."""
        with self._select_lock:
            undeclare(self._maps_token)
            self._maps_token, self.asked_every, self.selected = None, 0, None
        self._declared.close()


class ViewerServer:
    """The page and its API on `host:port` (0: any free port), for a `LiveFeed` or a `Timeline`."""

    def __init__(self, source: LiveFeed | Timeline, host: str = "127.0.0.1", port: int = 0,
                 display_hz: float = DISPLAY_HZ):
        self.source = source
        self.display_hz = display_hz
        self.stop = threading.Event()
        self.httpd = ThreadingHTTPServer((host, port), _handler(self))
        self.httpd.daemon_threads = True
        self._thread: threading.Thread | None = None

    @property
    def url(self) -> str:
        """Where the page is."""
        host, port = self.httpd.server_address[:2]
        return f"http://{host!s}:{port}/"

    def serve_in_thread(self) -> ViewerServer:
        """Serve from a daemon thread until `close`."""
        self._thread = threading.Thread(target=self.httpd.serve_forever, kwargs={"poll_interval": 0.1},
                                        daemon=True, name="conag-view-http")
        self._thread.start()
        return self

    def close(self) -> None:
        """Stop serving: event streams end, the socket closes."""
        self.stop.set()
        self.httpd.shutdown()
        self.httpd.server_close()
        if self._thread is not None:
            self._thread.join(5)

    def __enter__(self) -> ViewerServer:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    # the API -----------------------------------------------------------------------------
    def info(self) -> dict[str, Any]:
        """GET /api/info."""
        if isinstance(self.source, Timeline):
            return {"mode": "recording", "pictures": len(self.source), **self.source.summary()}
        return {"mode": "live", "world_id": self.source.world_id, "display_hz": self.display_hz}


Source = LiveFeed | Timeline
Query = dict[str, list[str]]
Routes = dict[tuple[str, type | None], Callable[..., None]]


def _route(routes: Routes, path: str, source: Source) -> Callable[..., None] | None:
    """The handler of `path` for this kind of source: the one for it, else the one for either."""
    kind = LiveFeed if isinstance(source, LiveFeed) else Timeline
    return routes.get((path, kind)) or routes.get((path, None))


def _handler(server: ViewerServer) -> type[BaseHTTPRequestHandler]:
    static = static_dir()

    class Handler(BaseHTTPRequestHandler):
        protocol_version = "HTTP/1.1"

        def log_message(self, format: str, *args: Any) -> None:
            log.debug("%s %s", self.address_string(), format % args)

        def _send(self, body: bytes | str, ctype: str = "application/json", status: int = 200) -> None:
            data = body.encode() if isinstance(body, str) else body
            self.send_response(status)
            self.send_header("Content-Type", ctype)
            self.send_header("Content-Length", str(len(data)))
            self.send_header("Cache-Control", "no-store")
            self.end_headers()
            self.wfile.write(data)

        def _json(self, obj: Any, status: int = 200) -> None:
            self._send(json.dumps(obj), status=status)

        # GET: one handler per route and source (`GET_ROUTES`); each takes the source and the query
        def _index(self, _source: Source, _query: Query) -> None:
            self._send((static / "index.html").read_bytes(), "text/html; charset=utf-8")

        def _info(self, _source: Source, _query: Query) -> None:
            self._json(server.info())

        def _scene(self, feed: LiveFeed, _query: Query) -> None:
            self._send(feed.picture()[1])

        def _live_maps(self, feed: LiveFeed, query: Query) -> None:
            try:
                self._json(feed.maps(query.get("agent", [""])[0]))
            except ValueError as exc:
                self._json({"error": str(exc)}, HTTPStatus.BAD_REQUEST)

        def _recorded_maps(self, timeline: Timeline, query: Query) -> None:
            self._json(timeline.maps_at(query.get("agent", [""])[0], int(query.get("tick", ["0"])[0] or 0)))

        def _timeline(self, timeline: Timeline, _query: Query) -> None:
            self._json(timeline.summary())

        def _frame(self, timeline: Timeline, query: Query) -> None:
            try:
                tick = int(query.get("tick", ["0"])[0])
            except ValueError:
                self._json({"error": "tick must be an integer"}, HTTPStatus.BAD_REQUEST)
                return
            picture = timeline.at(tick)
            if picture is None:
                self._json({"error": "the recording holds no WorldView"}, HTTPStatus.NOT_FOUND)
            else:
                self._send(picture)

        def _static(self, path: str) -> bool:
            """GET /static/NAME: a file of the page's folder (no subfolders); False if none."""
            name = path[len("/static/"):]
            f = static / name
            if not path.startswith("/static/") or "/" in name or not f.is_file():
                return False
            self._send(f.read_bytes(), mimetypes.guess_type(f.name)[0] or "application/octet-stream")
            return True

        def do_GET(self) -> None:
            url = urlparse(self.path)
            path, query = url.path, parse_qs(url.query)
            route = _route(self.GET_ROUTES, path, server.source)
            if route is not None:
                route(self, server.source, query)
            elif not self._static(path):
                self._json({"error": f"no {path}"}, HTTPStatus.NOT_FOUND)

        def _events(self, feed: LiveFeed, _query: Query) -> None:
            """Server-Sent Events: the picture at the display rate, when it changed, and the
            shown agent's maps (event `maps`) once a second, when they changed: pushed on the
            open stream, not asked for by the page (a request a second cost the page and the
            viewer more than the maps themselves)."""
            self.send_response(200)
            self.send_header("Content-Type", "text/event-stream")
            self.send_header("Cache-Control", "no-store")
            self.send_header("Connection", "close")
            self.end_headers()
            sent, idle, maps_sent, beat = -1, 0, None, 0
            per_second = max(int(server.display_hz), 1)
            try:
                while not server.stop.wait(1.0 / server.display_hz):
                    beat, wrote = beat + 1, False
                    agent = feed.selected
                    if agent is not None and beat % per_second == 0:
                        maps = feed.maps(agent)
                        if maps is not maps_sent:  # the same object while nothing new came
                            data = json.dumps({"agent": agent, **maps}).encode()
                            self.wfile.write(b"event: maps\ndata: " + data + b"\n\n")
                            maps_sent, wrote = maps, True
                    version, text = feed.picture()
                    if version != sent:
                        self.wfile.write(b"data: " + text.encode() + b"\n\n")
                        sent, idle, wrote = version, 0, True
                    else:
                        idle += 1
                        if idle % int(5 * server.display_hz) == 0:
                            self.wfile.write(b": idle\n\n")  # finds a closed page
                            wrote = True
                    if wrote:
                        self.wfile.flush()
            except (BrokenPipeError, ConnectionResetError):
                pass  # the page went away
            self.close_connection = True

        # POST: the same, in `POST_ROUTES`
        def _perturb(self, feed: LiveFeed, _query: Query) -> None:
            try:
                length = int(self.headers.get("Content-Length", "0"))
                req = json.loads(self.rfile.read(min(length, 65536)) or b"{}")
                p = Perturbation(op=str(req["op"]), x=float(req["x"]), y=float(req["y"]),
                                 kind=str(req.get("kind", "brick")), to_x=float(req.get("to_x", 0.0)),
                                 to_y=float(req.get("to_y", 0.0)))
            except (ValueError, KeyError, TypeError) as exc:
                self._json({"ok": False, "message": f"bad perturbation: {exc}"}, HTTPStatus.BAD_REQUEST)
                return
            result = feed.perturb(p)
            self._json({"ok": result.ok, "message": result.message, "tick": result.tick})

        def _perturb_recording(self, _timeline: Timeline, _query: Query) -> None:
            self._json({"ok": False, "message": "a recording cannot be changed"}, HTTPStatus.CONFLICT)

        def do_POST(self) -> None:
            url = urlparse(self.path)
            route = _route(self.POST_ROUTES, url.path, server.source)
            if route is None:
                self._json({"error": "not found"}, HTTPStatus.NOT_FOUND)
            else:
                route(self, server.source, parse_qs(url.query))

        # (path, the source it serves, or None for either) -> handler
        GET_ROUTES: ClassVar[Routes] = {
            ("/", None): _index, ("/index.html", None): _index,
            ("/api/info", None): _info,
            ("/api/scene", LiveFeed): _scene,
            ("/api/events", LiveFeed): _events,
            ("/api/maps", LiveFeed): _live_maps,
            ("/api/maps", Timeline): _recorded_maps,
            ("/api/timeline", Timeline): _timeline,
            ("/api/frame", Timeline): _frame,
        }
        POST_ROUTES: ClassVar[Routes] = {
            ("/api/perturb", LiveFeed): _perturb,
            ("/api/perturb", Timeline): _perturb_recording,
        }

    return Handler


def serve_live(session: zenoh.Session, world_id: str, stop: threading.Event, *, host: str = "127.0.0.1",
               port: int = 0, on_ready: Callable[[str], None] | None = None, maps_every: int = 0,
               display_hz: float = DISPLAY_HZ) -> None:
    """Serve the live page for world `world_id` until `stop` is set, sending it at most
    `display_hz` pictures a second; with `maps_every` N, ask the agent the page shows for
    its maps about once a second, never more often than every N ticks (`LiveFeed`)."""
    feed = LiveFeed(session, world_id, maps_every, decision_period=1.0 / display_hz).start()
    try:
        with ViewerServer(feed, host, port, display_hz).serve_in_thread() as server:
            if on_ready:
                on_ready(server.url)
            while not stop.wait(0.5):
                pass
    finally:
        feed.close()


def serve_timeline(timeline: Timeline, stop: threading.Event, *, host: str = "127.0.0.1", port: int = 0,
                   on_ready: Callable[[str], None] | None = None) -> None:
    """Serve a recording's page until `stop` is set."""
    with ViewerServer(timeline, host, port).serve_in_thread() as server:
        if on_ready:
            on_ready(server.url)
        while not stop.wait(0.5):
            pass

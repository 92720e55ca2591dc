"""The viewer's HTTP routes (conag/viewer/server.py): one handler per route and source, in
a table; a route the source does not serve is a 404 with the same body as before."""

from __future__ import annotations

import json
import urllib.error
import urllib.request

import pytest

from conag.viewer.scene import Timeline
from conag.viewer.server import LiveFeed, ViewerServer, _handler, _route


def test_each_route_has_a_handler_per_source():
    live, recorded = LiveFeed(None, "w0"), Timeline([], [], [], {})  # type: ignore[arg-type]
    routes = _handler(ViewerServer(recorded)).GET_ROUTES  # type: ignore[attr-defined]
    assert _route(routes, "/api/maps", live) is not _route(routes, "/api/maps", recorded)
    assert _route(routes, "/api/info", live) is _route(routes, "/api/info", recorded) is not None
    assert _route(routes, "/api/scene", recorded) is None and _route(routes, "/api/frame", live) is None
    assert _route(routes, "/api/nothing", live) is None


def _status(url: str, data: bytes | None = None) -> tuple[int, dict]:
    try:
        with urllib.request.urlopen(urllib.request.Request(url, data=data), timeout=10) as r:
            return r.status, json.loads(r.read())
    except urllib.error.HTTPError as err:
        return err.code, json.loads(err.read())


@pytest.mark.parametrize(("path", "post", "status", "body"), [
    ("api/scene", False, 404, {"error": "no /api/scene"}),           # a live route, a recording
    ("static/../server.py", False, 404, {"error": "no /static/../server.py"}),
    ("api/frame?tick=x", False, 400, {"error": "tick must be an integer"}),
    ("api/frame?tick=3", False, 404, {"error": "the recording holds no WorldView"}),
    ("api/nothing", True, 404, {"error": "not found"}),
    ("api/perturb", True, 409, {"ok": False, "message": "a recording cannot be changed"}),
])
def test_a_recording_answers_what_it_does_not_serve_as_before(path, post, status, body):
    with ViewerServer(Timeline([], [], [], {})).serve_in_thread() as server:
        assert _status(server.url + path, b"{}" if post else None) == (status, body)

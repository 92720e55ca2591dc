"""The browser viewer's pure core: what to draw, as plain data (no bus, no HTTP).

* `scene`: `Scene` folds WorldView, WorldStatus, AgentState and Decision messages into the
  JSON-ready picture the page draws (discs, sites, bodies, the progress chart, each
  agent's behaviour); `Timeline` does the same over a recording's entries, one picture per
  recorded WorldView, looked up by tick;
* `static/`: the page itself (`index.html`, `conag.viewer.js`), served as it is.

The shell that serves it over HTTP and follows the bus is `conag/viewer/server.py`.
"""

from conag.viewer.scene import Scene, Timeline, static_dir

__all__ = ["Scene", "Timeline", "static_dir"]

"""Bird's-eye pictures of a scenario world (the style of the paper's Fig. 6).

`render_scenario` draws one scenario to an image file: food discs green, water discs
blue, free bricks red, fixed obstacles as dark grey squares, drop sites as dashed
circles (a brick on a site is a red disc inside its dashed circle) and agents as
circles of radius `world.agent_radius` with a line showing their heading. The light
grid is the layout's cells; axes are in world units (x east, y north, one cell = one
disc diameter). By default everything comes from the layout; `agents` and `discs`
override it with live poses and disc positions, e.g. from a running world.
`draw_world` draws the same picture on an existing axes, for composite figures.

Rendering uses matplotlib's Agg canvas directly (no pyplot, no global backend switch),
so it works headless and from any thread.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.collections import LineCollection
from matplotlib.figure import Figure
from matplotlib.legend_handler import HandlerPatch
from matplotlib.patches import Circle, Rectangle

from world_server.scenario import Scenario

DISC_STYLE = {
    "food": {"facecolor": "#2ca02c", "edgecolor": "#145214"},
    "water": {"facecolor": "#1f77b4", "edgecolor": "#0b3a5e"},
    "brick": {"facecolor": "#d62728", "edgecolor": "#6b1010"},
}
SITE_STYLE = {"fill": False, "edgecolor": "black", "linestyle": "--", "linewidth": 1.2}
AGENT_STYLE = {"facecolor": "#ffbf3f", "edgecolor": "black", "linewidth": 1.0}
OBSTACLE_COLOUR = "#404040"
_LAYOUT_DISCS = {"F": "food", "W": "water", "b": "brick", "B": "brick"}
_DISC_SCALE = 0.9  # discs drawn a little smaller than a cell so touching ones stay apart


def render_scenario(scenario: Scenario, out_path: str | Path, *,
                    agents: Iterable[tuple[float, float, float]] | None = None,
                    discs: Iterable[tuple[float, float, str]] | None = None,
                    title: str | None = None, max_pixels: int | None = None) -> Path:
    """Draw `scenario` to `out_path` (format from the suffix, e.g. .png) and return the path.

    agents: (x, y, heading) poses in world units, heading in radians counter-clockwise
    from east; default: every `A` cell facing east. discs: (x, y, kind) with kind
    "food", "water" or "brick"; default: the layout's F, W, b and B cells. max_pixels:
    the longest side at most about this (a lower resolution for large worlds).
    """
    size = (2.5 + 0.3 * scenario.cols, 1.0 + 0.3 * scenario.rows)
    dpi = 100 if max_pixels is None else min(100, max(20, int(max_pixels / max(size))))
    fig = Figure(figsize=size)
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    draw_world(ax, scenario, agents=agents, discs=discs)
    ax.set_title(title if title is not None else scenario.name)
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=dpi, bbox_inches="tight")
    return out


def draw_world(ax, scenario: Scenario, *,
               agents: Iterable[tuple[float, float, float]] | None = None,
               discs: Iterable[tuple[float, float, str]] | None = None,
               legend: str | None = "right") -> None:
    """Draw the bird's-eye world on an existing matplotlib axes (see `render_scenario`
    for `agents` and `discs`); `legend` puts the key "right" of or "below" the axes, or
    nowhere (None)."""
    agents = _layout_agents(scenario) if agents is None else [(float(x), float(y), float(h)) for x, y, h in agents]
    discs = _layout_discs(scenario) if discs is None else [_checked_disc(d) for d in discs]
    _setup_axes(ax, scenario)
    handles: dict[str, object] = {}
    _draw_grid(ax, scenario)
    _draw_obstacles(ax, scenario, handles)
    _draw_discs(ax, scenario, discs, handles)
    _draw_sites(ax, scenario, handles)
    _draw_agents(ax, scenario, agents, handles)
    if legend and handles:
        places: dict[str, dict[str, Any]] = {
            "right": {"loc": "upper left", "bbox_to_anchor": (1.02, 1.0)},
            "below": {"loc": "upper center", "bbox_to_anchor": (0.5, -0.13), "ncol": len(handles)}}
        where = places[legend]
        ax.legend(list(handles.values()), list(handles), handler_map={Circle: _CircleHandler()},
                  fontsize="small", frameon=False, **where)


def _layout_agents(scenario: Scenario) -> list[tuple[float, float, float]]:
    return [(x, y, 0.0) for x, y in scenario.to_world(scenario.cells_col_row("A")).tolist()]


def _layout_discs(scenario: Scenario) -> list[tuple[float, float, str]]:
    cells = scenario.cells_col_row("".join(_LAYOUT_DISCS))
    kinds = [_LAYOUT_DISCS[scenario.layout[r][c]] for c, r in cells.tolist()]
    return [(x, y, k) for (x, y), k in zip(scenario.to_world(cells).tolist(), kinds)]


def _checked_disc(disc) -> tuple[float, float, str]:
    x, y, kind = disc
    if kind not in DISC_STYLE:
        raise ValueError(f"disc kind must be one of {', '.join(DISC_STYLE)}, got {kind!r}")
    return float(x), float(y), kind


def _setup_axes(ax, scenario: Scenario) -> None:
    width, height = scenario.size
    ax.set_xlim(0, width)
    ax.set_ylim(0, height)
    ax.set_aspect("equal")
    ax.set_xlabel("x (world units, east)")
    ax.set_ylabel("y (world units, north)")


def _draw_grid(ax, scenario: Scenario) -> None:
    size, (width, height) = scenario.world.cell_size, scenario.size
    lines = [[(c * size, 0), (c * size, height)] for c in range(scenario.cols + 1)]
    lines += [[(0, r * size), (width, r * size)] for r in range(scenario.rows + 1)]
    ax.add_collection(LineCollection(lines, colors="#dddddd", linewidths=0.5, zorder=0))


def _draw_obstacles(ax, scenario: Scenario, legend: dict) -> None:
    size = scenario.world.cell_size
    for x, y in scenario.to_world(scenario.cells_col_row("#")).tolist():
        square = Rectangle((x - size / 2, y - size / 2), size, size, color=OBSTACLE_COLOUR, zorder=1)
        legend["obstacle"] = ax.add_patch(square)


def _draw_discs(ax, scenario: Scenario, discs, legend: dict) -> None:
    radius = _DISC_SCALE * scenario.world.disc_radius
    for x, y, kind in discs:
        legend.setdefault(kind, ax.add_patch(Circle((x, y), radius, zorder=2, **DISC_STYLE[kind])))


def _draw_sites(ax, scenario: Scenario, legend: dict) -> None:
    for x, y in scenario.to_world(scenario.cells_col_row("+B")).tolist():
        site = ax.add_patch(Circle((x, y), scenario.world.disc_radius, zorder=3, **SITE_STYLE))
        legend.setdefault("drop site", site)


def _draw_agents(ax, scenario: Scenario, agents, legend: dict) -> None:
    radius = scenario.world.agent_radius
    for x, y, heading in agents:
        legend.setdefault("agent", ax.add_patch(Circle((x, y), radius, zorder=4, **AGENT_STYLE)))
        tip = (x + 1.6 * radius * math.cos(heading), y + 1.6 * radius * math.sin(heading))
        ax.plot([x, tip[0]], [y, tip[1]], color="black", linewidth=1.5, zorder=5)


class _CircleHandler(HandlerPatch):
    """Legend entries for circles are small circles in the artist's own style."""

    def create_artists(self, legend, orig_handle, xdescent, ydescent, width, height, fontsize, trans):  # noqa: ARG002
        centre = (width / 2 - xdescent, height / 2 - ydescent)
        circle = Circle(centre, min(width, height) / 2)
        self.update_prop(circle, orig_handle, legend)
        circle.set_transform(trans)
        return [circle]

"""What one agent believes: its ESMs and NMs beside the world (paper Fig. 4 and Fig. 5).

`render_agent_maps` runs a scenario in-process (`conag.sim.loop`, lockstep) for some ticks,
asks one agent's Brain to plan, and draws one figure: on the left the bird's-eye world
as it is now (the chosen agent ringed, its map's extent dashed), on the right the
agent's egocentric spatial maps (food, water, brick, configuration), its
configuration and brick navigation maps as Eq. 1-2 activations (goals 1, falling with
path distance, unreachable 0, obstacles -1 drawn black) and, with goal sequencing, its
Matching grid (paper §6, Fig. 17-19: the matched paths, the sites that are goals and
those that wait).

Map panels are egocentric but not rotated: axes are cell offsets from the agent (x
east, y north), north up, so they line up with the world panel; the agent's centre
cell is marked with a cross. The NMs' obstacles are those the plan used.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib import colormaps
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Circle, Rectangle

from agent_runtime.brain import Brain, Plans
from agent_runtime.esm import BRICK, CONFIG, FOOD, WATER
from agent_runtime.spreading import activation
from conag.sim.loop import SimRun, start
from protocol.messages import DISC_KINDS
from world_server.render import draw_world
from world_server.scenario import Scenario

ESM_PANELS = ((FOOD, "food ESM", "Greens"), (WATER, "water ESM", "Blues"),
              (BRICK, "brick ESM", "Reds"), (CONFIG, "configuration ESM", "Purples"))


def render_agent_maps(scenario: Scenario, out_path: str | Path, *, agent: str = "a1",
                      ticks: int = 0, seed: int | None = None) -> Path:
    """Run `scenario` for `ticks` lockstep ticks, then draw `agent`'s world, ESMs and NMs
    to `out_path` (format from the suffix) and return the path. ValueError for an
    unknown agent id or negative ticks."""
    if ticks < 0:
        raise ValueError(f"ticks must be >= 0, got {ticks}")
    run = start(scenario, seed=seed)
    if agent not in run.brains:
        raise ValueError(f"unknown agent {agent!r}: scenario {scenario.name} has agents "
                         f"{', '.join(run.brains)}")
    run.run(ticks, until_complete=False)
    brain = run.brains[agent]
    fig = _figure(scenario, run, agent, brain, brain.plan())
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=90, bbox_inches="tight")
    return out


def _figure(scenario: Scenario, run: SimRun, agent: str, brain: Brain, plans: Plans) -> Figure:
    fig = Figure(figsize=(20, 9))
    FigureCanvasAgg(fig)
    grid = fig.add_gridspec(2, 5, width_ratios=(1.7, 1, 1, 1, 1), wspace=0.45, hspace=0.3)
    _world_panel(fig.add_subplot(grid[:, 0]), scenario, run, agent, brain.maps.size)
    cells = [grid[r, c] for r in range(2) for c in range(1, 4)] + [grid[0, 4], grid[1, 4]]
    for spec, (layer, name, cmap) in zip(cells, ESM_PANELS):
        _esm_panel(fig, fig.add_subplot(spec), brain.maps.maps[layer], name, cmap)
    config_obs, brick_obs = nm_obstacles(brain)
    _nm_panel(fig, fig.add_subplot(cells[4]), plans.config, config_obs, plans.config_goals, "configuration NM")
    _nm_panel(fig, fig.add_subplot(cells[5]), plans.brick, brick_obs, plans.brick_goals, "brick NM")
    if plans.matching is not None:
        _matching_panel(fig.add_subplot(cells[6]), fig.add_subplot(cells[7]), brain, plans)
    status = run.world.status()
    behaviour = run.behaviours.get(agent, "-")
    fig.suptitle(f"{scenario.name}: agent {agent} after {status.tick} ticks "
                 f"(behaviour: {behaviour}; sites filled {status.sites_filled}/{status.sites_total})")
    return fig


def nm_obstacles(brain: Brain) -> tuple[np.ndarray, np.ndarray]:
    """The configuration and brick NMs' obstacle grids of the agent's last plan."""
    plans = brain.plans if brain.plans is not None else brain.plan()
    return plans.config_obstacles, plans.brick_obstacles


def _world_panel(ax, scenario: Scenario, run: SimRun, agent: str, map_size: int) -> None:
    world = run.world
    _, xy, kinds = world.discs.present_arrays()
    discs = [(x, y, DISC_KINDS[k]) for (x, y), k in zip(xy.tolist(), kinds.tolist())]
    poses = world.agent_poses()
    draw_world(ax, scenario, agents=poses.tolist(), discs=discs, legend="below")
    x, y, _ = poses[list(run.brains).index(agent)]
    ring = 1.8 * scenario.world.agent_radius
    ax.add_patch(Circle((x, y), ring, fill=False, edgecolor="magenta", linewidth=2.0, zorder=6))
    ax.annotate(agent, (x, y + ring), color="magenta", ha="center", va="bottom", fontweight="bold")
    half = map_size / 2 * scenario.world.cell_size
    ax.add_patch(Rectangle((x - half, y - half), 2 * half, 2 * half, fill=False, edgecolor="magenta",
                           linestyle=":", linewidth=1.0, zorder=6, clip_on=True))
    ax.set_title("world now (ringed: the agent; dotted: its map edge)")


def _extent(grid: np.ndarray) -> tuple[float, float, float, float]:
    c = grid.shape[0] // 2
    return (-c - 0.5, c + 0.5, -c - 0.5, c + 0.5)


def _map_axes(ax, title: str) -> None:
    ax.plot(0, 0, marker="+", color="magenta", markersize=12, markeredgewidth=2)
    ax.set_title(title)
    ax.set_xlabel("cells east of agent")
    ax.set_ylabel("cells north of agent")


def _esm_panel(fig, ax, layer: np.ndarray, title: str, cmap: str) -> None:
    image = ax.imshow(layer, cmap=cmap, vmin=0.0, vmax=1.0, origin="upper",
                      extent=_extent(layer), interpolation="nearest")
    fig.colorbar(image, ax=ax, fraction=0.046, pad=0.03)
    _map_axes(ax, title)


# Matching grid panel: what each cell is, in drawing order (later wins).
_MATCH_KINDS = (("path (match = 1)", "#c8c8c8"), ("site, open goal", "#2a9d3a"),
                ("site, waits (match = 1)", "#e07b00"), ("free brick", "#f2b8b8"),
                ("matched brick", "#c0182c"), ("structure / food / water", "black"))


def _matching_panel(ax, key, brain: Brain, plans: Plans) -> None:
    """The Matching grid (§6, Fig. 17-19): paths, which sites are goals and which wait."""
    from matplotlib.colors import ListedColormap
    from matplotlib.patches import Patch

    m = brain.maps.maps > 0.5
    sites = m[CONFIG] & ~m[BRICK]
    free = m[BRICK] & ~m[CONFIG]
    match = plans.matching.match
    kind = np.zeros(match.shape, int)
    for k, mask in enumerate((match, sites & ~match, sites & match, free & ~match, free & match,
                              m[FOOD] | m[WATER] | (m[BRICK] & m[CONFIG])), start=1):
        kind[mask] = k
    colours = ["white"] + [c for _, c in _MATCH_KINDS]
    ax.imshow(kind, cmap=ListedColormap(colours), vmin=-0.5, vmax=len(colours) - 0.5, origin="upper",
              extent=_extent(kind), interpolation="nearest")
    key.axis("off")
    key.legend(handles=[Patch(color=c, label=n) for n, c in _MATCH_KINDS], loc="upper left",
               fontsize=8, title="Matching grid", frameon=False)
    _map_axes(ax, "Matching grid (goal sequencing)")


def _nm_panel(fig, ax, dist: np.ndarray, obstacles: np.ndarray, goals: np.ndarray, title: str) -> None:
    act = activation(dist, obstacles=obstacles)
    cmap = colormaps["viridis"].with_extremes(under="black")  # obstacles (-1) black
    image = ax.imshow(act, cmap=cmap, vmin=0.0, vmax=1.0, origin="upper",
                      extent=_extent(act), interpolation="nearest")
    fig.colorbar(image, ax=ax, fraction=0.046, pad=0.03, extend="min")
    rows, cols = np.nonzero(goals)
    c = dist.shape[0] // 2
    ax.scatter(cols - c, c - rows, s=14, facecolors="none", edgecolors="white", linewidths=0.8)
    _map_axes(ax, f"{title} (black: obstacle, o: goal)")


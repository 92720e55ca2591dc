"""Issue 37 items 2 and 3: what noise and occlusion do to a build, and anchored maps (docs/noise.md).

    python3 -m experiments.noise --quick        # 4 small layouts x 5 settings: noise_quick.md (minutes)
    python3 -m experiments.noise --jobs 2       # the sample x every setting: noise.md, noise.png (hours)
    python3 -m experiments.noise --goal         # the sample at item 3's goal, without and with anchored maps
    python3 -m experiments.noise --settings "baseline,odometry 10%"   # some settings, merged into noise.json
    python3 -m experiments.noise --report-only  # the tables and the plot again from noise.json
    python3 -m experiments.noise --pictures     # docs/noise.md's picture (as experiments.pictures noise_maps)
    python3 -m experiments.noise --cluster tcp://HOST:8786   # on a Dask cluster (experiments/runner.py)

The sample: the first SAMPLE layouts, in the suite's order, of the generated suite of
`experiments.generalisation` (made from its committed manifest) whose longer side is at
most MAX_SIDE cells and that have at most MAX_AGENTS agents (larger teams and worlds cost
more than the two shared cores allow for ten settings). Each is built in process
(`conag.sim`, lockstep, the default agent) once per setting of SETTINGS: the noise-free
baseline, then one factor at a time
(odometry noise 2, 5, 10, 20%; sensor noise 2x, 4x; occlusion on) and two combinations
(10% + 2x + occlusion, the condition of issue 37 item 3's goal; 20% + 4x + occlusion,
the worst), and the goal's condition without its odometry noise (2x + occlusion: what the
agent achieves with maps that stay true, the ceiling for any correction of them); then
five of them again with anchored maps (`AgentConfig.anchor_maps`). Not the full factorial:
30 settings x 40 layouts would take most of a day on the two shared cores. Odometry noise
p means a distance slip of p and a heading slip of p radians per step
(`WorldConfig.odometry_distance_slip`, `odometry_heading_slip`). Every run's randomness,
the noise included, comes from the layout's seed: a run is reproduced exactly by running
it again. A run stops when complete, after `--stall` ticks with no
site filled (as the generalisation suite), or at the layout's `max_ticks`.

Reported per setting: completion; the median ticks of completed runs and, over layouts
completed both with the setting and without noise, the median ratio of their ticks;
misplaced bricks (`misplaced_bricks`); map error (`MapError`).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from agent_runtime.config import AgentConfig
from conag import sim
from experiments import runner
from experiments.generalisation import DEFAULT_STALL, LAYOUTS, family_of, how_it_ended, materialise, stall_limit
from experiments.report import RESULTS_DOC, write_section
from world_server.discs import BRICK_DISC
from world_server.noise import NoiseSettings
from world_server.scenario import Scenario, load_scenario, parse_scenario

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "experiments"
SAMPLE = 40
MAX_SIDE = 30
MAX_AGENTS = 3
QUICK_LAYOUTS = 4
EVERY = 10   # ticks between map error samples


def odometry(p: float) -> dict:
    """Odometry noise p: a distance slip of p and a heading slip of p radians per step."""
    return {"odometry_distance_slip": p, "odometry_heading_slip": p}


@dataclass(frozen=True)
class Setting:
    """One column of the sweep: a name, its three factors and the NoiseSettings they make."""

    name: str
    odometry: float       # distance and heading slip per step
    sensor: float         # times the scenario's sensor noise
    occlusion: bool
    anchored: bool = False  # the agents correct their maps (AgentConfig.anchor_maps)

    @property
    def noise(self) -> NoiseSettings:
        """The overrides this setting puts on a layout's world."""
        if not (self.odometry or self.occlusion or self.sensor != 1.0):
            return NoiseSettings()
        return NoiseSettings(sensor_noise_scale=self.sensor, occlusion=self.occlusion or None,
                             **(odometry(self.odometry) if self.odometry else {}))


SETTINGS = (
    Setting("baseline", 0.0, 1.0, False),
    Setting("odometry 2%", 0.02, 1.0, False),
    Setting("odometry 5%", 0.05, 1.0, False),
    Setting("odometry 10%", 0.10, 1.0, False),
    Setting("odometry 20%", 0.20, 1.0, False),
    Setting("sensor 2x", 0.0, 2.0, False),
    Setting("sensor 4x", 0.0, 4.0, False),
    Setting("occlusion", 0.0, 1.0, True),
    Setting("2x + occlusion", 0.0, 2.0, True),        # the goal's condition without its odometry noise
    Setting("10% + 2x + occlusion", 0.10, 2.0, True),
    Setting("20% + 4x + occlusion", 0.20, 4.0, True),
    # The same agents with their maps anchored to landmarks (issue 37 item 3).
    Setting("anchored: baseline", 0.0, 1.0, False, True),
    Setting("anchored: odometry 10%", 0.10, 1.0, False, True),
    Setting("anchored: odometry 20%", 0.20, 1.0, False, True),
    Setting("anchored: 10% + 2x + occlusion", 0.10, 2.0, True, True),
    Setting("anchored: 20% + 4x + occlusion", 0.20, 4.0, True, True),
)
QUICK_SETTINGS = ("baseline", "odometry 10%", "10% + 2x + occlusion", "anchored: odometry 10%",
                  "anchored: 10% + 2x + occlusion")
# The goal of issue 37 item 3, without and with the correction: what `--goal` runs.
GOAL_SETTINGS = ("10% + 2x + occlusion", "anchored: 10% + 2x + occlusion")
BY_NAME = {s.name: s for s in SETTINGS}


# ------------------------------------------------------------------ the measures

class MapError:
    """A loop observer: how far each agent's configuration ESM has slid from the truth.

    An agent holds every blueprint site at a fixed cell of its odometry frame (set from
    the Welcome at attach, when it is exact: `agent_runtime/far_memory.py`), and its
    configuration ESM draws each site at that cell relative to where it believes it is:
    the odometry summed since attach (`FarMemory.pos` whole cells plus `EgocentricMaps.frac`).
    So every site is off by one vector, the agent's dead-reckoning error: its true
    displacement since attach minus the one its odometry says. The map error of an agent
    at a tick is that vector's length in cells; `samples` holds it for every agent every
    `every` ticks. Read-only use of the brains' maps.
    """

    def __init__(self, run: sim.SimRun, every: int = EVERY):
        self.every = every
        self.samples: list[float] = []
        self.last: dict[str, float] = {}
        # A brain's maps stand as of the last frame it read, one tick behind the world
        # between ticks: its belief is compared with where its body was then.
        self._then = self._true(run)
        self._offset = {a: self._then[a] - self._believed(run, a) for a in run.brains}

    @staticmethod
    def _true(run: sim.SimRun) -> dict[str, np.ndarray]:
        poses = run.world.agent_poses()
        return {a: poses[run.world.agents[a].index, :2] / run.world.cfg.cell_size for a in run.brains}

    @staticmethod
    def _believed(run: sim.SimRun, agent: str) -> np.ndarray:
        return run.brains[agent].believed_cells()

    def error(self, run: sim.SimRun, agent: str) -> float:
        """The agent's map error as of the last frame it read, in cells (call after a tick)."""
        d = self._believed(run, agent) + self._offset[agent] - self._then[agent]
        return float(math.hypot(d[0], d[1]))

    def __call__(self, run: sim.SimRun) -> None:
        """A loop observer: called after every tick, samples every `every` ticks."""
        if run.world.tick % self.every == 0:
            for agent in run.brains:
                self.last[agent] = e = self.error(run, agent)
                self.samples.append(e)
        self._then = self._true(run)


def misplaced_bricks(run: sim.SimRun, start_cells: np.ndarray) -> int:
    """Bricks lying in a cell next to a drop site (one of its 8 neighbours) but on no site,
    that are not in the cell they started in: bricks an agent dropped one cell off."""
    world = run.world
    sc = world.scenario
    present = world.discs.present()
    bricks = present[world.discs.kind[present] == BRICK_DISC]
    if not len(bricks):
        return 0
    cells = sc.to_cell(world.discs.xy[bricks])
    site = np.zeros((sc.rows + 2, sc.cols + 2), bool)           # padded by one cell all round
    sites = sc.to_cell(world.sites_xy)
    site[sites[:, 1] + 1, sites[:, 0] + 1] = True
    near = np.zeros_like(site)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            near |= np.roll(np.roll(site, dr, axis=0), dc, axis=1)
    r, c = np.clip(cells[:, 1] + 1, 0, sc.rows + 1), np.clip(cells[:, 0] + 1, 0, sc.cols + 1)
    moved = np.any(cells != start_cells[bricks], axis=1)
    return int(np.count_nonzero(near[r, c] & ~site[r, c] & moved))


# ------------------------------------------------------------------ runs

@dataclass(frozen=True)
class Outcome:
    layout: str
    family: str
    cols: int
    rows: int
    agents: int
    setting: str
    completed: bool
    stalled: bool
    ticks: int
    sites_filled: int
    sites_total: int
    misplaced: int            # misplaced_bricks at the end
    map_error: float          # mean over agents and samples, cells
    map_error_end: float      # mean over agents at the last sample, cells
    wrong_cell: float         # share of samples with a map error of half a cell or more
    seconds: float            # wall time of the run (left out of the tables: not reproducible)


@dataclass(frozen=True)
class Job:
    layout: str        # file name under LAYOUTS
    setting: str       # a name of SETTINGS
    stall: int
    text: str = field(default="", repr=False)   # the layout file's text: a task needs no file of the suite


def run_one(job: Job) -> Outcome:
    """Build one layout under one setting; stop when complete, stalled or out of ticks."""
    layout, setting = job.layout, job.setting
    sc = parse_scenario(job.text, layout) if job.text else load_scenario(LAYOUTS / layout)
    began = time.perf_counter()
    run = sim.start(sc, cfg=AgentConfig(anchor_maps=BY_NAME[setting].anchored), noise=BY_NAME[setting].noise)
    start_cells = sc.to_cell(run.world.discs.xy)
    errors = MapError(run)
    result = run.run(sc.max_ticks, stall_ticks=stall_limit(sc, job.stall), observers=[errors])
    status = run.world.status()
    samples = errors.samples
    return Outcome(layout=layout, family=family_of(sc), cols=sc.cols, rows=sc.rows, agents=len(run.brains),
                   setting=setting, completed=result.completed, stalled=result.stalled, ticks=result.ticks,
                   sites_filled=status.sites_filled, sites_total=status.sites_total,
                   misplaced=misplaced_bricks(run, start_cells),
                   map_error=round(float(np.mean(samples)), 4) if samples else 0.0,
                   map_error_end=round(float(np.mean(list(errors.last.values()))), 4) if errors.last else 0.0,
                   wrong_cell=round(float(np.mean(np.asarray(samples) >= 0.5)), 4) if samples else 0.0,
                   seconds=round(time.perf_counter() - began, 1))


def sample(n: int = SAMPLE) -> list[str]:
    """The first `n` layouts of the suite (its order) whose longer side is at most MAX_SIDE
    cells and that have at most MAX_AGENTS agents."""
    out = []
    for path in materialise():
        sc = load_scenario(path)
        if max(sc.cols, sc.rows) <= MAX_SIDE and sc.agents <= MAX_AGENTS:
            out.append(path.name)
        if len(out) == n:
            break
    return out


def quick_sample(names: list[str], n: int = QUICK_LAYOUTS) -> list[str]:
    """The `n` layouts of `names` that are cheapest to build (cells x agents, sites)."""
    def work(name: str) -> tuple[int, str]:
        sc: Scenario = load_scenario(LAYOUTS / name)
        return sc.cols * sc.rows * max(sc.agents, 1) + 50 * len(sc.cells_col_row("+")), name
    cheapest = {name for _, name in sorted(map(work, names))[:n]}
    return [name for name in names if name in cheapest]


def run_all(jobs: list[tuple[str, str]], where: runner.Where, stall: int, seen=None) -> list[Outcome]:
    """Every (layout, setting) where `where` says (experiments/runner.py), with progress on stderr."""
    out: list[Outcome] = []
    began = time.monotonic()
    tasks = [Job(layout, setting, stall, (LAYOUTS / layout).read_text(encoding="utf-8")) for layout, setting in jobs]
    for done in runner.run(run_one, tasks, where, seen=seen):
        o = done.result
        out.append(o)
        print(f"[{len(out)}/{len(jobs)} {time.monotonic() - began:6.0f} s] {o.layout} {o.setting}: {how_it_ended(o)}, "
              f"map error {o.map_error:.2f}, misplaced {o.misplaced} ({o.seconds:.0f} s, {done.worker})",
              file=sys.stderr, flush=True)
    order = {s.name: i for i, s in enumerate(SETTINGS)}
    return sorted(out, key=lambda o: (order[o.setting], o.layout))


# ------------------------------------------------------------------ the table

def _median(values: list[float], fmt: str) -> str:
    return format(statistics.median(values), fmt) if values else "—"


def table(outcomes: list[Outcome]) -> str:
    """One row per setting: completion, ticks, misplaced bricks, map error."""
    base = {o.layout: o for o in outcomes if o.setting == "baseline"}
    lines = [("| setting | odometry | sensor noise | occlusion | maps anchored | completed | ticks (median, completed) "
              "| ticks / baseline (median) | misplaced bricks (runs with any) | map error, cells (mean) "
              "| map error at the end (mean) | time sites drawn a cell off |"),
             "|---|---:|---:|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    for s in SETTINGS:
        runs = [o for o in outcomes if o.setting == s.name]
        if not runs:
            continue
        done = [o for o in runs if o.completed]
        ratios = [o.ticks / base[o.layout].ticks for o in done
                  if o.layout in base and base[o.layout].completed and s.name != "baseline"]
        misplaced = sum(o.misplaced for o in runs)
        lines.append(
            f"| {s.name} | {100 * s.odometry:g}% | {s.sensor:g}x | {'on' if s.occlusion else 'off'} "
            f"| {'yes' if s.anchored else 'no'} "
            f"| {len(done)}/{len(runs)} ({100 * len(done) / len(runs):.0f}%) "
            f"| {_median([o.ticks for o in done], '.0f')} | {_median(ratios, '.2f') if ratios else '—'} "
            f"| {misplaced} ({sum(o.misplaced > 0 for o in runs)}) "
            f"| {statistics.fmean(o.map_error for o in runs):.2f} "
            f"| {statistics.fmean(o.map_error_end for o in runs):.2f} "
            f"| {100 * statistics.fmean(o.wrong_cell for o in runs):.0f}% |")
    return "\n".join(lines)


def markdown(outcomes: list[Outcome], args: argparse.Namespace, seconds: float | None,
             docs: str = "../docs/", plot_path: str = "") -> str:
    """The results section: how it was run, the table, what the columns mean (`docs`: the
    docs folder relative to the page; `plot_path`: the plot, relative to the page, if any)."""
    layouts = sorted({o.layout for o in outcomes})
    settings = sorted({o.setting for o in outcomes}, key=[s.name for s in SETTINGS].index)
    agents = sorted({o.agents for o in outcomes})
    where = getattr(args, "where", None) or f"{args.jobs} worker processes"
    wall = (f" Wall time: {seconds / 60:.0f} min on {where} (niced, on a shared 2-core "
            "machine)." if seconds is not None else "")
    every = [s.name for s in SETTINGS]
    part = {n: sorted({o.layout.split("-")[0] for o in outcomes if o.setting == n}) for n in settings}
    part = {n: some for n, some in part.items() if len(some) < len(layouts)}
    whole = [n for n in settings if n not in part]      # measured on every layout
    if args.quick:
        command = "python3 -m experiments.noise --quick"
    elif whole == every:
        command = f"python3 -m experiments.noise --jobs {args.jobs}"
    elif whole == list(GOAL_SETTINGS):
        command = f"python3 -m experiments.noise --goal --jobs {args.jobs}"
    else:
        command = f"python3 -m experiments.noise --jobs {args.jobs} --settings \"{','.join(whole)}\""
    missing = [n for n in (QUICK_SETTINGS if args.quick else every) if n not in settings]
    not_run = f"\n\nNot measured yet: {', '.join(missing)}." if missing else ""
    if part:
        runs = [f"{n}, {len(some)} layouts (`--settings \"{n}\" --layouts {','.join(some)}`)"
                for n, some in part.items()]
        not_run += " Measured on part of the sample only: " + "; ".join(runs) + "."
    which = f"the {QUICK_LAYOUTS} cheapest to build of" if args.quick else "all of"
    return f"""## Noise and occlusion (issue 37)

`{command}` builds {len(layouts)} generated layouts ({which} the first {SAMPLE} of the suite of
`experiments.generalisation` whose longer side is at most {MAX_SIDE} cells and that have at most
{MAX_AGENTS} agents; {agents[0]} to {agents[-1]} agents, so larger teams and worlds are not covered)
under {len(whole)} settings, in process (`conag.sim`, lockstep, the default agent), each run's
noise drawn from the layout's seed (re-running gives the same table). A run stops when complete,
after {args.stall} ticks with no site filled, or at the layout's `max_ticks`.{wall}{not_run}

The design is one factor at a time from the noise-free baseline, and three combinations (the goal's
condition of issue 37 item 3, 10% + 2x + occlusion; the same without odometry noise, which no
correction of the maps can improve on; and the worst), each with
the default agent, and five of them again with its maps anchored (`anchor_maps`, issue 37 item 3;
[Maps that stay true]({docs}noise.md#maps-that-stay-true)); not the full
factorial of 5 odometry x 3 sensor x 2 occlusion settings (30 x {SAMPLE} runs would take most
of a day on the two shared cores). Odometry noise p is a distance slip of p and a heading slip of p
radians per step (`odometry_distance_slip`, `odometry_heading_slip`: the reported length of each
step is off by a relative error of std p, its direction by an angle of std p); sensor noise is a
multiple of the default 0.02 per unit of distance; occlusion: a sector reports only its nearest
object of any colour. See [Noise and occlusion]({docs}noise.md).

{table(outcomes)}

- *ticks / baseline*: over the layouts completed both with the setting and without noise, the
  median of the ratio of their ticks.
- *misplaced bricks*: at the end of the run, bricks lying in one of the 8 cells around a drop site
  but on no site, that an agent moved there (not in their starting cell); summed over the runs.
- *map error*: how far an agent's configuration ESM has slid from the truth. An agent keeps every
  site at a fixed cell of its odometry frame (exact at attach) and draws it relative to where its
  odometry says it is, so every site is off by the same vector: the agent's dead-reckoning error.
  Its length in cells, sampled every {EVERY} ticks for every agent; the mean over agents and
  samples, averaged over runs; *at the end*: the agents' mean at the run's last sample.
- *time sites drawn a cell off*: the share of samples in which that error is half a cell or more,
  so that the configuration ESM may put a site in the wrong cell.
""" + (f"\n![noise and occlusion]({plot_path})\n" if plot_path else "")


def plot(outcomes: list[Outcome], path: Path) -> Path:
    """Completion and map error per setting, as two bar charts side by side."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [s.name for s in SETTINGS if any(o.setting == s.name for o in outcomes)]
    done = [100 * statistics.fmean(o.completed for o in outcomes if o.setting == n) for n in names]
    err = [statistics.fmean(o.map_error for o in outcomes if o.setting == n) for n in names]
    end = [statistics.fmean(o.map_error_end for o in outcomes if o.setting == n) for n in names]
    fig, (a, b) = plt.subplots(1, 2, figsize=(12, 4.8), sharey=True)
    y = np.arange(len(names))
    a.barh(y, done, color="#4c72b0")
    a.set_xlim(0, 100)
    a.set_xlabel("layouts completed (%)")
    for yi, v in zip(y, done):
        a.text(v + 1, yi, f"{v:.0f}%", va="center", fontsize=8)
    b.barh(y - 0.2, err, height=0.4, color="#dd8452", label="mean over the run")
    b.barh(y + 0.2, end, height=0.4, color="#c44e52", label="at the end")
    b.set_xlabel("map error (cells): configuration ESM against the truth")
    b.legend(loc="lower right", fontsize=8)
    layouts = len({o.layout for o in outcomes})
    count = {n: len({o.layout for o in outcomes if o.setting == n}) for n in names}
    a.set_yticks(y, [n if count[n] == layouts else f"{n}\n({count[n]} layouts only)" for n in names])
    a.invert_yaxis()
    fig.suptitle(f"Noise and occlusion: {layouts} generated layouts per setting (experiments/noise.py)")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


# ------------------------------------------------------------------ pictures of the maps

# The pictures' world: two brick piles, one behind a food wall, water, a ring of sites.
PICTURE_SCENARIO = '''
name = "noise-pictures"
seed = 37
agents = 1
layout = """
..........................
..bbbb..........WWWW......
..bbbb....................
..........................
......FFFFFFFF............
..........................
...........+++++++........
...........+.....+........
...........+.....+....FF..
...........+++++++....FF..
..........................
....A.....................
..........................
..WWWW......bbbbbb........
............bbbbbb........
..........................
..........FFF.............
..........................
"""
'''
PICTURE_TICKS = 1200
PICTURES = (
    ("no noise", NoiseSettings()),
    ("odometry slip 0.3", NoiseSettings(**odometry(0.3))),
    ("sensor noise x8", NoiseSettings(sensor_noise_scale=8.0)),
    ("occlusion", NoiseSettings(occlusion=True)),
    ("aliasing 0.5", NoiseSettings(aliasing=0.5)),
)


def draw_maps(path: Path, scenario: str = PICTURE_SCENARIO, ticks: int = PICTURE_TICKS) -> Path:
    """One row per option of PICTURES: agent a1's food, water, brick and configuration ESMs
    after `ticks` ticks of the same scenario and seed, the truth outlined on each."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from agent_runtime.esm import BRICK, CONFIG, FOOD, WATER
    from world_server.discs import FOOD_DISC, WATER_DISC

    sc = parse_scenario(scenario, "experiments/noise.py")
    layers = ((BRICK, BRICK_DISC, "brick ESM", "Reds"), (FOOD, FOOD_DISC, "food ESM", "Greens"),
              (WATER, WATER_DISC, "water ESM", "Blues"), (CONFIG, None, "configuration ESM", "Purples"))
    fig, axes = plt.subplots(len(PICTURES), len(layers), figsize=(3.1 * len(layers), 3.0 * len(PICTURES)))
    for row, (label, noise) in enumerate(PICTURES):
        run = sim.start(sc, noise=noise)
        errors = MapError(run)
        run.run(ticks - 1, until_complete=False, observers=[errors])
        world = run.world
        cell = world.cfg.cell_size
        # The brain's maps stand as of the frame it read last, of the tick before the world's.
        me = world.agent_poses()[world.agents["a1"].index, :2] / cell
        run.step()
        brain = run.brains["a1"]
        present = world.discs.present()
        for col, (layer, kind, title, cmap) in enumerate(layers):
            ax = axes[row, col]
            grid = brain.maps.maps[layer]
            c = grid.shape[0] // 2
            fx, fy = brain.maps.frac
            # Map cell (r, k) is centred (k - c - fx, c - r - fy) cells from the agent.
            ax.imshow(grid, cmap=cmap, vmin=0, vmax=1, origin="upper", interpolation="nearest",
                      extent=(-c - 0.5 - fx, c + 0.5 - fx, -c - 0.5 - fy, c + 0.5 - fy))
            truth = (world.sites_xy if kind is None else
                     world.discs.xy[present[world.discs.kind[present] == kind]]) / cell - me
            ax.scatter(truth[:, 0], truth[:, 1], s=22, facecolors="none", edgecolors="black", linewidths=0.7)
            ax.plot(0, 0, marker="+", color="magenta", markersize=10, markeredgewidth=2)
            ax.set_xlim(-13.5, 13.5)
            ax.set_ylim(-13.5, 13.5)
            ax.set_xticks([])
            ax.set_yticks([])
            if row == 0:
                ax.set_title(title)
            if col == 0:
                ax.set_ylabel(f"{label}\n(map error {errors.error(run, 'a1'):.1f} cells)")
    fig.suptitle(f"{sc.name}: agent a1's maps after {ticks} ticks (circles: where things really are)")
    fig.tight_layout()
    fig.savefig(path, dpi=80)
    plt.close(fig)
    return path


# ------------------------------------------------------------------ main

def _kept(path: Path, rerun: list[str], only: list[str]) -> list[Outcome]:
    """The runs of `path` (if any) but those of `rerun` settings on `only` layouts: a
    partial run adds to them."""
    if not path.exists():
        return []
    rows = json.loads(path.read_text(encoding="utf-8"))
    return [Outcome(**r) for r in rows
            if r["setting"] in BY_NAME and (r["setting"] not in rerun or r["layout"] not in only)]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true",
                    help=f"{QUICK_LAYOUTS} small layouts x {len(QUICK_SETTINGS)} settings: noise_quick.json/md")
    ap.add_argument("--jobs", type=int, default=2, help="worker processes (default 2)")
    runner.add_cluster_argument(ap)
    ap.add_argument("--stall", type=int, default=DEFAULT_STALL, help="ticks with no site filled that stop a run")
    ap.add_argument("--out", type=Path, default=OUT, help="folder for the json, md and png (default experiments/)")
    ap.add_argument("--report-only", action="store_true", help="the tables and plot again from noise.json")
    ap.add_argument("--pictures", action="store_true",
                    help="draw the pictures of docs/noise.md (noise_maps.png): one agent's maps per option")
    ap.add_argument("--settings", metavar="NAMES",
                    help="run only these settings (names of SETTINGS, comma separated), merged into noise.json")
    ap.add_argument("--layouts", metavar="NAMES",
                    help="only the layouts of the sample whose file name contains one of these, comma separated")
    ap.add_argument("--goal", action="store_true",
                    help="run only the goal of issue 37 item 3 without and with anchored maps, merged into noise.json")
    args = ap.parse_args(argv)
    if args.jobs < 1 or args.stall < 1:
        ap.error("--jobs and --stall must be >= 1")
    chosen = list(GOAL_SETTINGS) if args.goal else [n.strip() for n in (args.settings or "").split(",") if n.strip()]
    unknown = [n for n in chosen if n not in BY_NAME]
    if unknown:
        ap.error(f"unknown setting(s) {', '.join(unknown)}; known: {', '.join(BY_NAME)}")
    args.out.mkdir(parents=True, exist_ok=True)
    if args.pictures:
        print(f"wrote {draw_maps(args.out / 'noise_maps.png')}")
        return 0
    stem = "noise_quick" if args.quick else "noise"
    seconds = None
    if args.report_only:
        outcomes = [Outcome(**r) for r in json.loads((args.out / f"{stem}.json").read_text(encoding="utf-8"))]
        meta = args.out / f"{stem}.meta.json"
        if meta.exists():
            m = json.loads(meta.read_text(encoding="utf-8"))
            args.jobs, args.stall, seconds = m["jobs"], m["stall"], m["seconds"]
            args.where = m.get("where")
    else:
        names = sample()
        if args.quick:
            names = quick_sample(names)
        if args.layouts:
            names = [n for n in names if any(part.strip() in n for part in args.layouts.split(",") if part.strip())]
        settings = chosen or (QUICK_SETTINGS if args.quick else [s.name for s in SETTINGS])
        kept = _kept(args.out / f"{stem}.json", settings, names) if chosen or args.layouts else []
        where = runner.where_of(args, args.jobs)
        args.where = where.describe()
        try:
            outcomes = run_all([(n, s) for s in settings for n in names], where, args.stall,
                               seen=lambda n: setattr(args, "where", where.describe(n)))
        except runner.ClusterError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 2
        order = {s.name: i for i, s in enumerate(SETTINGS)}
        outcomes = sorted(kept + outcomes, key=lambda o: (order[o.setting], o.layout))
        rows = [asdict(o) | ({"seconds": 0.0} if args.quick else {}) for o in outcomes]
        (args.out / f"{stem}.json").write_text(json.dumps(rows, indent=1) + "\n", encoding="utf-8")
        if not args.quick:
            # Wall time of every run, summed (runs of several invocations are merged).
            seconds = sum(o.seconds for o in outcomes) / args.jobs
            info = {"jobs": args.jobs, "stall": args.stall, "seconds": seconds, "where": args.where}
            (args.out / f"{stem}.meta.json").write_text(json.dumps(info) + "\n", encoding="utf-8")
    text = markdown(outcomes, args, seconds, plot_path="" if args.quick else "noise.png")
    (args.out / f"{stem}.md").write_text(text, encoding="utf-8")
    if not args.quick:
        plot(outcomes, args.out / "noise.png")
        if args.out.resolve() == OUT.resolve():
            write_section(RESULTS_DOC, "noise", markdown(outcomes, args, seconds, docs="../",
                                                         plot_path="../../experiments/noise.png"))
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(runner.by_name(main)())

"""Issue 10: does the agent build layouts nobody tuned it for? The generated suite.

A suite of generated layouts (`world_server/generator.py`; made on first use into
experiments/generalisation/layouts/ from the committed manifest layouts.json, which holds
each file's sha256, so a change to the generator cannot silently change the benchmark:
world_server/suite.py) is built in-process (conag/sim/loop.py: the real World and Brain code, lockstep,
headless), each layout once with goal sequencing (ConAg-TS, the default agent) and once
nearest-first (the plain agent of §4), in the same run. Every layout passed the
buildability check when it was generated. A run stops when the structure is complete, when
no site has been filled for `--stall` ticks (stalled; on a large world the longer of that and
its cells per agent), or at the scenario's `max_ticks`.

Reported: completion rate per family and per size band for both agents; ticks to complete;
the distance walked against a lower bound (experiments/replay.lower_bound, on the initial
map); every failure by its layout file, with its stall report and a picture of the state it
stopped in (experiments/generalisation/failures/, drawn by the run or by --pictures; not committed).

    python3 -m experiments.generalisation              # the whole suite (about an hour on 2 cores)
    python3 -m experiments.generalisation --quick      # a smoke run of a few small layouts
    python3 -m experiments.generalisation --layouts    # make the layout files, print where they are
    python3 -m experiments.generalisation --generate   # a new manifest, after a deliberate generator change
    python3 -m experiments.generalisation --pictures   # draw the failures of generalisation.json again
    python3 -m experiments.generalisation --report-only   # the tables again from generalisation.json
    python3 -m experiments.generalisation --resume     # go on with an interrupted run (same options)
    python3 -m experiments.generalisation --families   # make the candidate suite with the solid
                                                       # families (layouts_families.json), print its folder
    python3 -m experiments.generalisation --cluster tcp://HOST:8786   # on a Dask cluster (experiments/runner.py)

Writes experiments/generalisation.json (every run), experiments/generalisation.md and the
generalisation section of docs/results/experiments.md (not with --quick, which writes to --out).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import sys
import tempfile
import time
from dataclasses import asdict, dataclass, field, replace
from functools import partial
from pathlib import Path

import numpy as np

from agent_runtime.config import AgentConfig
from conag import sim
from experiments import runner
from experiments.journal import Journal, code_version
from experiments.report import RESULTS_DOC, write_section
from world_server import suite
from world_server.scenario import Scenario, load_scenario, parse_scenario

ROOT = Path(__file__).resolve().parent.parent
SUITE = ROOT / "experiments" / "generalisation"
LAYOUTS = SUITE / "layouts"              # made from MANIFEST (gitignored)
MANIFEST = SUITE / "layouts.json"
SUITE_SEED = 2026
SUITE_SIZE = 200
# Layouts of other suites kept for the record (EXPERIMENTS.md: unseen sets that found a bug):
# (suite size, suite seed, indices), made from UNSEEN_MANIFEST into UNSEEN (gitignored).
UNSEEN_LAYOUTS = ((30, 1125, (24,)), (30, 1126, (25,)))
UNSEEN = SUITE / "unseen"
UNSEEN_MANIFEST = SUITE / "unseen.json"
# Issue 36's candidate suite: the same size, with the solid shapes and corridors at about a
# quarter (generator.SUITE_MIXES["solid"]); made into FAMILIES_LAYOUTS (gitignored). Not the
# benchmark yet: run it with --only FAMILIES_LAYOUTS/*.toml --out DIR.
FAMILIES_SEED, FAMILIES_MIX = 2036, "solid"
FAMILIES_LAYOUTS = SUITE / "families"
FAMILIES_MANIFEST = SUITE / "layouts_families.json"
MODES = (("goal sequencing", True), ("nearest-first", False))
BANDS = ((15, 30), (31, 60), (61, 120))
DEFAULT_STALL = 3000
JOURNAL = "generalisation.partial.jsonl"   # the runs finished so far (see --resume)


@dataclass(frozen=True)
class Job:
    layout: str        # file name under LAYOUTS (or a path for --only)
    mode: str
    stall: int
    code: str = ""     # the code version the run is for (see journal.code_version)
    text: str = field(default="", repr=False)   # the layout file's text: a task needs no file of the suite


@dataclass(frozen=True)
class Outcome:
    layout: str
    family: str
    cols: int
    rows: int
    agents: int
    mode: str
    completed: bool
    stalled: bool
    ticks: int
    max_ticks: int
    sites_filled: int
    sites_total: int
    bricks_total_start: int
    bricks_total_end: int
    distance: float
    bound: float
    seconds: float
    report: tuple[str, ...] = ()
    picture: str = ""


def family_of(sc: Scenario) -> str:
    """The generator writes `gen-<family>-<seed>` names."""
    m = re.match(r"gen-(.+)-\d+$", sc.name)
    return m.group(1) if m else "other"


def band_of(cols: int, rows: int) -> str:
    side = max(cols, rows)
    lo, hi = next(b for b in BANDS if side <= b[1])
    return f"{lo}-{hi}"


def stall_limit(sc: Scenario, floor: int) -> int:
    """Ticks with no site filled that stop a run: `floor`, or on a large world the cells
    per agent if more (about the time a team needs to sweep the world for a supply out of
    sensor range before the first fill: 82 x 106 cells took two agents 3,500 ticks)."""
    return max(floor, sc.cols * sc.rows // max(sc.agents, 1))


def layout_path(name: str) -> Path:
    p = Path(name)
    return p if p.suffix == ".toml" and p.exists() else LAYOUTS / name


def job_of(name: str, mode: str, stall: int, code: str = "") -> Job:
    """The job of one run of layout `name`, its text read here (a cluster's workers have no suite files)."""
    return Job(name, mode, stall, code, layout_path(name).read_text(encoding="utf-8"))


def run_job(job: Job, draw: bool = False) -> tuple[Outcome, bytes]:
    """Build one layout with one agent; stop when complete, stalled or out of ticks.

    With `draw`, a run that did not complete comes back with the PNG of the state it stopped
    in (`picture_name`), else b"": the run writes nothing where it runs."""
    sc = parse_scenario(job.text, job.layout) if job.text else load_scenario(layout_path(job.layout))
    run = sim.start(sc, cfg=AgentConfig(goal_sequencing=dict(MODES)[job.mode]))
    starts = [tuple(int(v) for v in cell[::-1]) for cell in sc.to_cell(run.world.agent_poses()[:, :2])]
    bricks_start = run.world.discs.bricks_total()
    began = time.perf_counter()
    result = run.run(sc.max_ticks, stall_ticks=stall_limit(sc, job.stall))
    status = run.world.status()
    report, png = (), b""
    if not result.completed:
        report = tuple(run.stall_report())
        if draw:
            png = _picture(run, sc, job)
    outcome = Outcome(layout=Path(job.layout).name, family=family_of(sc), cols=sc.cols, rows=sc.rows,
                   agents=len(starts), mode=job.mode, completed=result.completed, stalled=result.stalled,
                   ticks=result.ticks, max_ticks=sc.max_ticks, sites_filled=status.sites_filled,
                   sites_total=status.sites_total, bricks_total_start=bricks_start,
                   bricks_total_end=status.bricks_total, distance=float(sum(status.agent_distance)),
                   bound=distance_bound(sc, starts), seconds=time.perf_counter() - began, report=report)
    return outcome, png


def distance_bound(sc: Scenario, starts: list[tuple[int, int]]) -> float:
    """Lower bound on the total distance (world units), on the initial map."""
    from experiments.replay import lower_bound

    reach = sc.world.grab_reach / sc.world.cell_size
    return lower_bound(sc.grid("b"), sc.grid("+"), sc.grid("FWB#"), starts, reach,
                       AgentConfig().drop_centering) * sc.world.cell_size


def picture_name(job: Job) -> str:
    """The file name of a run's picture: the layout's stem and the agent."""
    return f"{Path(job.layout).stem}-{'nearest' if job.mode == 'nearest-first' else 'ts'}.png"


def _picture(run: sim.SimRun, sc: Scenario, job: Job) -> bytes:
    """The world as the run left it, as PNG: discs where they are now, agents where they stand."""
    from protocol.messages import DISC_KINDS
    from world_server.render import render_scenario

    _, xy, kind = run.world.discs.present_arrays()
    discs = [(x, y, DISC_KINDS[k]) for (x, y), k in zip(xy.tolist(), kind.tolist())]
    st = run.world.status()
    with tempfile.TemporaryDirectory() as folder:
        path = render_scenario(sc, Path(folder) / picture_name(job), agents=run.world.agent_poses().tolist(),
                               discs=discs, title=f"{sc.name} ({job.mode}): {st.sites_filled}/{st.sites_total} "
                                                  f"at tick {st.tick}", max_pixels=1200)
        return path.read_bytes()


def run_all(jobs: list[Job], where: runner.Where, pictures: Path | None, journal: Journal | None = None,
            earlier: list[Outcome] | None = None, seen=None) -> list[Outcome]:
    """Every job where `where` says (experiments/runner.py), with progress; the pictures of
    the runs that did not complete into `pictures` (none if None), each outcome to `journal`
    as it comes. `earlier` outcomes (a resumed run's) count in the progress and the result."""
    out: list[Outcome] = list(earlier or ())
    total = len(out) + len(jobs)
    began = time.monotonic()
    for done in runner.run(partial(run_job, draw=pictures is not None), jobs, where, seen=seen):
        o, png = done.result
        if png and pictures is not None:
            pictures.mkdir(parents=True, exist_ok=True)
            path = pictures / picture_name(done.job)
            path.write_bytes(png)
            o = replace(o, picture=str(path.resolve()))
        if journal is not None:
            journal.append(_job_key(done.job), asdict(o))
        out.append(o)
        print(f"[{len(out)}/{total} {time.monotonic() - began:6.0f} s] {o.layout} ({o.family}, "
              f"{o.cols}x{o.rows}, {o.agents} agents) {o.mode}: {how_it_ended(o)} ({o.seconds:.0f} s, "
              f"{done.worker})",
              file=sys.stderr, flush=True)
    return sorted(out, key=lambda o: (o.layout, o.mode))


def how_it_ended(o) -> str:
    """A run's end in a few words, for progress lines: complete, stalled or out of ticks."""
    return (f"complete in {o.ticks} ticks" if o.completed else
            f"{'STALLED' if o.stalled else 'OUT OF TICKS'} at {o.sites_filled}/{o.sites_total}")


def _job_key(job: Job) -> list:
    return [job.layout, job.mode, job.stall, job.code]


def resumed(journal: Journal, jobs: list[Job]) -> tuple[list[Outcome], list[Job]]:
    """(outcomes the journal already holds for `jobs`, the jobs still to run). An entry
    counts only for the same layout, agent, stall limit and code (`Job.code`)."""
    found = journal.results()
    keys = [tuple(_job_key(j)) for j in jobs]
    earlier = [Outcome(**(found[k] | {"report": tuple(found[k]["report"])})) for k in keys if k in found]
    return earlier, [j for j, k in zip(jobs, keys) if k not in found]


def in_folder(o: Outcome, pictures: Path) -> Outcome:
    """A journalled outcome with its picture in `pictures` if a file of that name is there.

    The journal holds each picture's absolute path: a journal carried on in another --out
    folder (with its pictures copied along) linked 54 failures of the committed table to
    the folder they were first drawn in, which no clone has."""
    if not o.picture or Path(o.picture).parent.resolve() == pictures.resolve():
        return o
    here = pictures / Path(o.picture).name
    return replace(o, picture=str(here.resolve())) if here.exists() else o


# ------------------------------------------------------------------ tables

def _rate(runs: list[Outcome]) -> str:
    done = sum(o.completed for o in runs)
    return f"{done}/{len(runs)} ({100.0 * done / len(runs):.0f}%)" if runs else "—"


def _median(values: list[float], fmt: str = ".0f") -> str:
    return format(float(np.median(values)), fmt) if values else "—"


def group_table(outcomes: list[Outcome], key, title: str) -> str:
    """Completion, ticks and distance / bound per group, both agents side by side."""
    groups = sorted({key(o) for o in outcomes})
    head = (f"| {title} | layouts | goal sequencing: completed | ticks (median) | distance / bound (median) "
            f"| nearest-first: completed | ticks (median) |")
    lines = [head, "|---|---|---|---|---|---|---|"]
    for g in [*groups, "all"]:
        mine = [o for o in outcomes if g == "all" or key(o) == g]
        ts = [o for o in mine if o.mode == "goal sequencing"]
        nf = [o for o in mine if o.mode == "nearest-first"]
        ratios = [o.distance / o.bound for o in ts if o.completed and o.bound > 0]
        lines.append(f"| {g} | {len(ts)} | {_rate(ts)} | {_median([o.ticks for o in ts if o.completed])} | "
                     f"{_median(ratios, '.2f')} | {_rate(nf)} | {_median([o.ticks for o in nf if o.completed])} |")
    return "\n".join(lines)


def goals(outcomes: list[Outcome]) -> str:
    ts = [o for o in outcomes if o.mode == "goal sequencing"]
    small = [o for o in ts if o.agents <= 3 and max(o.cols, o.rows) <= 60]
    rate = lambda runs: 100.0 * sum(o.completed for o in runs) / len(runs) if runs else float("nan")  # noqa: E731

    def row(goal: str, target: str, runs: list[Outcome], met: bool) -> str:
        # An --only or --quick run may hold no layout a goal speaks of: nothing measured.
        if not runs:
            return f"| {goal} | {target} | no such layout in this run | — |"
        return f"| {goal} | {target} | {rate(runs):.1f}% of {len(runs)} | {'yes' if met else 'no'} |"

    lost = [o for o in outcomes if o.bricks_total_end != o.bricks_total_start]
    return "\n".join([
        "| goal | target | measured | met |", "|---|---|---|---|",
        row("goal sequencing completes buildable layouts", ">= 98%", ts, rate(ts) >= 98),
        row("... with <= 3 agents in worlds up to 60 x 60", "100%", small, rate(small) == 100),
        (f"| bricks_total never changes | every run | {len(outcomes) - len(lost)}/{len(outcomes)} runs | "
         f"{'yes' if not lost else 'no'} |")])


FAILURE_CLASSES = (
    ("sealed", ("an agent holds a brick and no open site is reachable for it: the structure (or an agent's "
                "body inside it) closed the way to the sites left")),
    ("no supply", ("no agent knows a reachable free brick: the supply was not found, or what is left is "
                   "out of reach")),
    ("busy, no fill", ("agents navigate with a brick or to a brick, yet no site is filled (stale beliefs, "
                       "agents in each other's way)")),
    ("out of ticks", "still filling sites when the layout's max_ticks ran out"),
)


def failure_class(o: Outcome) -> str:
    """One of FAILURE_CLASSES, read off the run's stall report."""
    if not o.stalled:
        return "out of ticks"
    lines = " ".join(o.report[1:])
    if "no open site is reachable" in lines:
        return "sealed"
    if all(("no free brick" in line or "no known free brick" in line) for line in o.report[1:]):
        return "no supply"
    return "busy, no fill"


def class_table(outcomes: list[Outcome]) -> str:
    lines = ["| class | what the stall reports say | goal sequencing | nearest-first |", "|---|---|---:|---:|"]
    for name, what in FAILURE_CLASSES:
        count = {m: sum(1 for o in outcomes if o.mode == m and not o.completed and failure_class(o) == name)
                 for m, _ in MODES}
        lines.append(f"| {name} | {what} | {count['goal sequencing']} | {count['nearest-first']} |")
    return "\n".join(lines)


def failures(outcomes: list[Outcome], base: Path) -> str:
    """Every run that did not complete; pictures linked relative to `base` (the document's folder)."""
    bad = [o for o in outcomes if not o.completed]
    if not bad:
        return "None: every run completed."
    lines = []
    for o in bad:
        why = "stalled" if o.stalled else "out of ticks"
        pic = f" ![]({os.path.relpath(o.picture, base)})" if o.picture else ""
        lines.append(f"- `{o.layout}` ({o.family}, {o.cols} x {o.rows}, {o.agents} agents), **{o.mode}**: {why} at "
                     f"tick {o.ticks}, {o.sites_filled}/{o.sites_total} sites ({failure_class(o)}).{pic}")
        lines += [f"  - `{line.strip()}`" for line in o.report[1:]]
    return "\n".join(lines)


def markdown(outcomes: list[Outcome], args: argparse.Namespace, seconds: float, base: Path) -> str:
    layouts = len({o.layout for o in outcomes})
    return f"""## Generalisation: generated layouts (issue 10)

`python3 -m experiments.generalisation` builds {layouts} generated layouts (`world_server/generator.py`
suite seed {SUITE_SEED}, every layout passing the buildability check; made into
`experiments/generalisation/layouts/` on first use and checked against the sha256 of each in the committed
`experiments/generalisation/layouts.json`), each
with goal sequencing and nearest-first in the same run, in-process (conag/sim/loop.py, lockstep, the default
`AgentConfig` but for goal sequencing, hunger and thirst on). A run stops when complete, after
{args.stall} ticks with no site filled (stalled; on large worlds the world's cells per agent if
that is more, the time to sweep it for a supply), or at the layout's `max_ticks`. Distance / bound:
the distance all agents walked over `experiments/replay.lower_bound` on the initial map (completed runs).
Wall time of this run: {seconds / 60:.0f} min on {args.where}.

### Goals

{goals(outcomes)}

### Per family

{group_table(outcomes, lambda o: o.family, "family")}

### Per size band (the world's longer side, cells)

{group_table(outcomes, lambda o: band_of(o.cols, o.rows), "size")}

### Per agent count

{group_table(outcomes, lambda o: f"{o.agents:>2} agents", "agents")}

### Why runs did not complete

{class_table(outcomes)}

### Every run that did not complete

The pictures are not committed: `python3 -m experiments.generalisation --pictures` draws them again.

{failures(outcomes, base)}
"""


# ------------------------------------------------------------------ the suite's files

def generate_layouts(count: int, seed: int) -> None:
    """New manifests from what the generator makes now (after a deliberate change to it,
    with GENERATOR_VERSION bumped), and the layout files they name."""
    for manifest, folder, suites in ((MANIFEST, LAYOUTS, [(count, seed, None)]),
                                     (UNSEEN_MANIFEST, UNSEEN, UNSEEN_LAYOUTS)):
        m, _ = suite.manifest_of(suites)
        manifest.write_text(m.to_json(), encoding="utf-8")
        for path in suite.materialise(m, folder):
            sc = load_scenario(path)
            print(f"{path.name}: {sc.cols}x{sc.rows}, {len(sc.cells_col_row('+'))} open sites, {sc.agents} agents",
                  file=sys.stderr)


def families_layouts(write: bool = False) -> list[Path]:
    """The candidate suite's layout files (made from FAMILIES_MANIFEST; with `write`, the
    manifest made anew first from what the generator makes now)."""
    if write:
        m, _ = suite.manifest_of([(SUITE_SIZE, FAMILIES_SEED, None, FAMILIES_MIX)])
        FAMILIES_MANIFEST.write_text(m.to_json(), encoding="utf-8")
    return suite.materialise(FAMILIES_MANIFEST, FAMILIES_LAYOUTS)


def materialise() -> list[Path]:
    """The suite's layout files (made from MANIFEST where missing), in the suite's order;
    the unseen layouts kept for the record too."""
    suite.materialise(UNSEEN_MANIFEST, UNSEEN)
    return suite.materialise(MANIFEST, LAYOUTS)


def suite_files() -> list[str]:
    """The suite's layout file names (under LAYOUTS, made if missing)."""
    return sorted(p.name for p in materialise())


def quick_files(n: int) -> list[str]:
    """The `n` smallest layouts of the suite (by cells x agents): a smoke run in seconds."""
    def work(name: str) -> tuple[int, str]:
        sc = load_scenario(LAYOUTS / name)
        return sc.cols * sc.rows * max(sc.agents, 1) + 50 * len(sc.cells_col_row("+")), name
    return [name for _, name in sorted(map(work, suite_files()))[:n]]


def rewrite_report(args: argparse.Namespace) -> int:
    """The markdown and the docs/results/experiments.md section again, from experiments/generalisation.json."""
    out = ROOT / "experiments"
    rows = json.loads((out / "generalisation.json").read_text(encoding="utf-8"))
    outcomes = [Outcome(**(r | {"report": tuple(r["report"]),
                                "picture": str((out / r["picture"]).resolve()) if r["picture"] else ""}))
                for r in rows]
    meta = json.loads((out / "generalisation.meta.json").read_text(encoding="utf-8"))
    args.jobs, args.stall = meta["jobs"], meta["stall"]
    args.where = meta.get("where", f"{args.jobs} worker processes")
    (out / "generalisation.md").write_text(markdown(outcomes, args, meta["seconds"], out.resolve()), encoding="utf-8")
    write_section(RESULTS_DOC, "generalisation", markdown(outcomes, args, meta["seconds"], RESULTS_DOC.parent))
    print((out / "generalisation.md").read_text(encoding="utf-8"))
    return 0


def draw_failures(args: argparse.Namespace) -> int:
    """The pictures of the committed table's failures: each run that did not complete in
    experiments/generalisation.json again (same layout, agent and stall limit), drawn where
    the table links it (or under --out); the results are not touched. Exit 1 if a run stops otherwise than
    recorded (the code changed since the table)."""
    out = ROOT / "experiments"
    rows = [r for r in json.loads((out / "generalisation.json").read_text(encoding="utf-8")) if r["picture"]]
    stall = json.loads((out / "generalisation.meta.json").read_text(encoding="utf-8"))["stall"]
    names = set(args.only or ())
    rows = [r for r in rows if (not names or r["layout"] in names) and args.mode in (None, r["mode"])]
    pictures = args.out / "generalisation" / "failures" if args.out else SUITE / "failures"
    print(f"drawing {len(rows)} pictures into {pictures}", file=sys.stderr, flush=True)
    outcomes = run_all([job_of(r["layout"], r["mode"], stall) for r in rows], runner.where_of(args, args.jobs),
                       pictures)
    recorded = {(r["layout"], r["mode"]): r for r in rows}
    same = ("completed", "stalled", "ticks", "sites_filled")
    differ = [o for o in outcomes if any(getattr(o, k) != recorded[o.layout, o.mode][k] for k in same)]
    for o in differ:
        r = recorded[o.layout, o.mode]
        print(f"{o.layout} {o.mode}: stopped at tick {o.ticks} with {o.sites_filled} sites "
              f"(recorded: tick {r['ticks']}, {r['sites_filled']} sites)", file=sys.stderr)
    print(f"{len(outcomes) - len(differ)} of {len(outcomes)} runs stopped as recorded", file=sys.stderr)
    return 1 if differ else 0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="a few small layouts; results go to --out only")
    ap.add_argument("--layouts", action="store_true",
                    help=f"make the suite's layout files from {MANIFEST.name} and print their folder")
    ap.add_argument("--generate", action="store_true",
                    help=f"a new {MANIFEST.name} (and unseen.json) from the generator as it is now, and the "
                         f"{SUITE_SIZE} layout files: only after a deliberate change to the generator")
    ap.add_argument("--families", action="store_true",
                    help=f"make the candidate suite with the solid families from {FAMILIES_MANIFEST.name} "
                         "(--generate: write that manifest anew) and print its folder")
    ap.add_argument("--pictures", action="store_true",
                    help="run again the runs of generalisation.json that did not complete, drawing the "
                         "state each stopped in (failures/), and check they stop as recorded")
    ap.add_argument("--only", nargs="+", metavar="LAYOUT", help="these layout files (names under the suite, or paths)")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="worker processes")
    runner.add_cluster_argument(ap)
    ap.add_argument("--stall", type=int, default=DEFAULT_STALL, help="ticks with no site filled that stop a run")
    ap.add_argument("--out", type=Path, default=None, help="folder for the json and md (default experiments/)")
    ap.add_argument("--mode", choices=[m for m, _ in MODES], default=None,
                    help="run this mode only (default: both, side by side); an agent change that only "
                         "goal sequencing reads leaves nearest-first's runs as they were")
    ap.add_argument("--report-only", action="store_true",
                    help="rewrite the tables from the committed generalisation.json, running nothing")
    ap.add_argument("--resume", action="store_true",
                    help=f"keep the runs an interrupted invocation with the same --out finished ({JOURNAL} there)")
    args = ap.parse_args(argv)
    if args.jobs < 1 or args.stall < 1:
        ap.error("--jobs and --stall must be >= 1")
    if args.families:
        families_layouts(write=args.generate)
        print(FAMILIES_LAYOUTS)
        return 0
    if args.generate:
        generate_layouts(SUITE_SIZE, SUITE_SEED)
        return 0
    if args.report_only:
        return rewrite_report(args)
    try:
        files = suite_files()
    except suite.SuiteError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    if args.layouts:
        print(LAYOUTS)
        return 0
    try:
        if args.pictures:
            return draw_failures(args)
        return sweep(ap, args, files)
    except runner.ClusterError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2


def sweep(ap: argparse.ArgumentParser, args: argparse.Namespace, files: list[str]) -> int:
    """The runs the options name, their journal, tables and files."""
    names = args.only or (quick_files(4) if args.quick else files)
    out = args.out or (None if args.quick else ROOT / "experiments")
    if out is None:
        ap.error("--quick needs --out (it must not overwrite the committed results)")
    out.mkdir(parents=True, exist_ok=True)
    pictures = out / "generalisation" / "failures" if args.out else SUITE / "failures"
    fresh = not (args.only or args.quick or args.resume)
    for old in pictures.glob("*.png") if pictures.exists() and fresh else ():
        old.unlink()
    journal = Journal(out / JOURNAL, resume=args.resume)
    code = code_version()
    earlier, jobs = resumed(journal, [job_of(name, mode, args.stall, code) for name in names for mode, _ in MODES
                                      if args.mode in (None, mode)])
    earlier = [in_folder(o, pictures) for o in earlier]
    if args.resume:
        print(f"resuming: {len(earlier)} of {len(earlier) + len(jobs)} runs already done "
              f"({out / JOURNAL})", file=sys.stderr, flush=True)
    began = time.monotonic()
    where = runner.where_of(args, args.jobs)
    args.where = where.describe()
    outcomes = run_all(jobs, where, pictures, journal, earlier,
                       seen=lambda n: setattr(args, "where", where.describe(n)))
    seconds = journal.earlier_seconds() + time.monotonic() - began
    text = markdown(outcomes, args, seconds, out.resolve())
    rows = [asdict(o) | {"picture": os.path.relpath(o.picture, out.resolve()) if o.picture else ""} for o in outcomes]
    (out / "generalisation.json").write_text(json.dumps(rows, indent=1), encoding="utf-8")
    meta = {"jobs": args.jobs, "stall": args.stall, "seconds": seconds, "where": args.where}
    (out / "generalisation.meta.json").write_text(json.dumps(meta), encoding="utf-8")
    (out / "generalisation.md").write_text(text, encoding="utf-8")
    if not (args.quick or args.only or args.out):
        write_section(RESULTS_DOC, "generalisation", markdown(outcomes, args, seconds, RESULTS_DOC.parent))
    journal.remove()
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(runner.by_name(main)())

"""Draw the results pages' pictures: `python3 -m experiments.pictures [--out DIR] [NAME...]`.

The pictures are made, not committed. Each is drawn from what its experiment committed
(`fig9_learning.json`, `goal_sequencing_runs.json`, `lattice_learning.json`), or, where the
experiment keeps no data for it, by running the cheap part of that experiment again with the
seeds it used:

    fig9_learning        Fig. 9: errors per trial, from experiments/fig9_learning.json
    goal_sequencing      Fig. 13: distance over the lower bound, from goal_sequencing_runs.json
    lattice_square       Fig. 10: the reactive system's square (rng seed 0, as reactive_vs_conag)
    lattice_moved_brick  Fig. 12: the same with a brick moved out
    lattice_nested       Fig. 14: nested squares
    lattice_learning     Fig. 11: learning the rule set, from lattice_learning.json
    noise_maps           docs/noise.md: one agent's maps under each noise option (seeded runs, a minute)
    noise                completion and map error per noise setting, from experiments/noise.json
    team_size            issue 36: speed-up and behaviour shares against the team size, from team_size.json

Each experiment's full run draws its own pictures as well; this command draws them without
running the experiments. By default it writes into experiments/, where the results pages
link them (and where .gitignore keeps them out of git); the docs build (docs/hooks.py)
runs it for the pictures that are missing.
"""

from __future__ import annotations

import argparse
import json
import sys
from collections.abc import Callable
from pathlib import Path

HERE = Path(__file__).resolve().parent


def fig9_learning(out: Path) -> list[Path]:
    from experiments import fig9_learning as fig9

    raw = json.loads((HERE / f"{fig9.STEM}.json").read_text(encoding="utf-8"))
    plan = fig9.Plan(**{k: tuple(v) if isinstance(v, list) else v for k, v in raw["plan"].items()})
    runs = [fig9.LearningRun(kind=r["kind"], eta=r["eta"], run=r["run"], errors=tuple(r["errors"]),
                             completed_at=tuple(r["completed_at"])) for r in raw["runs"]]
    path = out / f"{fig9.STEM}.png"
    fig9.plot(fig9.curves_of(runs, plan), plan, path)
    return [path]


def goal_sequencing(out: Path) -> list[Path]:
    from experiments import goal_sequencing as gs

    results = gs.load_runs(HERE / "goal_sequencing_runs.json")
    path = out / "goal_sequencing.png"
    gs.chart(gs.summarise(results), path)
    return [path]


def lattice(out: Path) -> list[Path]:
    from experiments import reactive_vs_conag as rc

    seeds = [0]  # the pictures show the first rng seed of the full run
    square = {s: rc.reactive_square(s, seeds) for s in ("corners", "sides")}
    moved = {s: rc.reactive_moved(s, seeds) for s in ("corners", "sides")}
    return rc.pictures(square, moved, rc.reactive_nested(seeds), out)


def lattice_learning(out: Path) -> list[Path]:
    from experiments import lattice_learning as ll

    raw = json.loads((HERE / "lattice_learning.json").read_text(encoding="utf-8"))
    path = out / "lattice_learning.png"
    ll.plot(ll.from_curve_data(raw), path, raw["n"], len(raw["seeds"]))
    return [path]


def noise_maps(out: Path) -> list[Path]:
    from experiments import noise

    return [noise.draw_maps(out / "noise_maps.png")]


def noise_sweep(out: Path) -> list[Path]:
    from experiments import noise

    rows = json.loads((HERE / "noise.json").read_text(encoding="utf-8"))
    return [noise.plot([noise.Outcome(**r) for r in rows], out / "noise.png")]


def team_size(out: Path) -> list[Path]:
    from experiments import team_size as ts

    rows = json.loads((HERE / "team_size.json").read_text(encoding="utf-8"))["rows"]
    path = out / "team_size.png"
    ts.plot(rows, path)
    return [path]


# name -> what draws it (lattice() draws all three lattice_* pictures at once)
PICTURES: dict[str, Callable[[Path], list[Path]]] = {
    "fig9_learning": fig9_learning,
    "goal_sequencing": goal_sequencing,
    "lattice_square": lattice,
    "lattice_moved_brick": lattice,
    "lattice_nested": lattice,
    "lattice_learning": lattice_learning,
    "noise_maps": noise_maps,
    "noise": noise_sweep,
    "team_size": team_size,
}


def draw(names: list[str], out: Path = HERE) -> list[Path]:
    """Draw the pictures `names` into `out`; the files written."""
    out.mkdir(parents=True, exist_ok=True)
    done: list[Path] = []
    for draw_one in dict.fromkeys(PICTURES[n] for n in names):  # each drawer once, in order
        paths = draw_one(out)
        for p in paths:
            print(f"wrote {p}", file=sys.stderr, flush=True)
        done += paths
    return done


def missing(out: Path = HERE) -> list[str]:
    """The pictures not in `out` yet."""
    return [n for n in PICTURES if not (out / f"{n}.png").exists()]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("names", nargs="*", metavar="NAME", choices=[[], *PICTURES],
                    help=f"pictures to draw (default: all): {', '.join(PICTURES)}")
    ap.add_argument("--out", type=Path, default=HERE, help="directory to write them to (default experiments/)")
    ap.add_argument("--missing", action="store_true", help="only the pictures not in --out yet")
    args = ap.parse_args(argv)
    names = args.names or list(PICTURES)
    if args.missing:
        names = [n for n in names if n in missing(args.out)]
    draw(names, args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""R3 / Fig. 11: errors per epoch while a network learns the square rule set by imitation.

For corner-seeded and side-seeded squares, over several seeds: collect the
teacher's decisions, train the one-hidden-layer network (conag/baselines/learned.py),
record errors per epoch, and check whether the trained network, driving the
lattice simulation, builds the square.  Writes experiments/lattice_learning.png,
experiments/lattice_learning.md and experiments/lattice_learning.json (the curves, from
which `python3 -m experiments.pictures` draws the picture again).

    python3 -m experiments.lattice_learning           # full run (~1-2 min)
    python3 -m experiments.lattice_learning --quick   # seconds-long smoke run
"""
from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path

import numpy as np

from conag.baselines.learned import learn, simulate_policy
from conag.baselines.rules import square_rules

SEEDINGS = ("corners", "sides")
FULL_N, FULL_SEEDS, FULL_EPOCHS, FULL_EPISODES = 6, range(5), 50, 5  # the full run (the committed table, the curve)


def run(n, seeds, epochs, episodes, eval_runs, eval_steps):
    out = {}
    for seeding in SEEDINGS:
        rule_set, bricks, shape = square_rules(n, seeding)
        curves, sizes, built, to_zero = [], [], [], []
        for seed in seeds:
            errors, _, policy, n_dec = learn(rule_set, bricks, shape,
                                             np.random.default_rng(seed), epochs=epochs,
                                             episodes=episodes, return_net=True)
            curves.append(errors)
            sizes.append(n_dec)
            zero = np.flatnonzero(errors == 0)
            to_zero.append(int(zero[0]) + 1 if len(zero) else None)
            for k in range(eval_runs):
                result = simulate_policy(policy, bricks, shape, 8, eval_steps,
                                         np.random.default_rng(10_000 + 100 * seed + k),
                                         rule_set.target)
                built.append(result.built)
        out[seeding] = dict(curves=np.array(curves), sizes=np.array(sizes), built=built,
                            to_zero=to_zero, rules=len(rule_set.rules),
                            states=len(rule_set.states))
    return out


def plot(out, path, n, n_seeds):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    for seeding, style in zip(SEEDINGS, ("o-", "s--")):
        curves = out[seeding]["curves"]
        epochs = np.arange(1, curves.shape[1] + 1)
        ax.errorbar(epochs, curves.mean(0), yerr=curves.std(0), fmt=style, ms=3,
                    capsize=2, label=f"seed bricks at {seeding} "
                    f"({out[seeding]['rules']} rules, {out[seeding]['states']} states)")
    ax.set_xlabel("training epoch")
    ax.set_ylabel("errors per epoch (decisions ≠ teacher)")
    ax.set_title(f"Learning the rule set, square n={n} "
                 f"(mean ± std, {n_seeds} seeds)")
    ax.legend()
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def curve_data(out, n, seeds) -> dict:
    """What the curve is drawn from, as lattice_learning.json keeps it (`plot(**...)` of `from_curve_data`)."""
    return dict(n=n, seeds=list(seeds), curves={s: {"errors": out[s]["curves"].tolist(), "rules": out[s]["rules"],
                                                    "states": out[s]["states"]} for s in SEEDINGS})


def from_curve_data(raw: dict) -> dict:
    """`run`'s output as far as `plot` reads it, from `curve_data`."""
    return {s: dict(curves=np.array(c["errors"]), rules=c["rules"], states=c["states"])
            for s, c in raw["curves"].items()}


def table(out, n, seeds, epochs, episodes, eval_runs, eval_steps) -> str:
    lines = [f"# R3 — learning the transition rule set (Fig. 11), square n={n}", "",
             (f"Seeds {list(seeds)}; {episodes} teacher episodes per seed (8 agents); "
              f"{epochs} epochs of minibatch GD (batch 32, lr 0.5, 32 tanh hidden units). "
              "Errors = decisions in the epoch whose network argmax differs from the "
              "teacher's class, counted before each minibatch update. Mean ± std over seeds."),
             "", "| epoch | corners | sides |", "|---:|---:|---:|"]
    marks = sorted({1, 2, 3, 5, 10, 15, 20, 30, 40, 50, epochs} & set(range(1, epochs + 1)))
    for e in marks:
        cells = [f"{out[s]['curves'][:, e - 1].mean():.1f} ± {out[s]['curves'][:, e - 1].std():.1f}"
                 for s in SEEDINGS]
        lines.append(f"| {e} | {cells[0]} | {cells[1]} |")
    lines += ["", "| | corners | sides |", "|---|---:|---:|"]

    def row(name, f):
        lines.append(f"| {name} | {f(out['corners'])} | {f(out['sides'])} |")

    row("rules / states", lambda o: f"{o['rules']} / {o['states']}")
    row("decisions per training set (mean)", lambda o: f"{o['sizes'].mean():.0f}")
    row("last-epoch error rate (mean)",
        lambda o: f"{(o['curves'][:, -1] / o['sizes']).mean():.2%}")
    row("first zero-error epoch (per seed)",
        lambda o: ", ".join("—" if z is None else str(z) for z in o["to_zero"]))
    row(f"trained net builds the square ({eval_runs} runs/seed, ≤{eval_steps} steps)",
        lambda o: f"{sum(o['built'])}/{len(o['built'])}")
    return "\n".join(lines) + "\n"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="seconds-long smoke run")
    parser.add_argument("--n", type=int, default=FULL_N, help="side of the square")
    parser.add_argument("--out", type=Path, default=None,
                        help="output directory (default: experiments/, or the temp "
                        "directory for --quick so the smoke run never overwrites results)")
    args = parser.parse_args(argv)
    if args.out is None:
        args.out = Path(tempfile.gettempdir()) if args.quick else Path(__file__).resolve().parent
    args.out.mkdir(parents=True, exist_ok=True)
    if args.quick:
        seeds, epochs, episodes, eval_runs, eval_steps = range(2), 5, 1, 1, 2000
    else:
        seeds, epochs, episodes, eval_runs, eval_steps = FULL_SEEDS, FULL_EPOCHS, FULL_EPISODES, 3, 5000
    out = run(args.n, seeds, epochs, episodes, eval_runs, eval_steps)
    stem = "lattice_learning"
    plot(out, args.out / f"{stem}.png", args.n, len(seeds))
    (args.out / f"{stem}.json").write_text(json.dumps(curve_data(out, args.n, seeds)) + "\n", encoding="utf-8")
    text = table(out, args.n, seeds, epochs, episodes, eval_runs, eval_steps)
    (args.out / f"{stem}.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()

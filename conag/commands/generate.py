"""`conag generate`: write seeded, buildable scenario files.

    conag generate --seed N [--family F] [--size N|WxH] [--agents K] --out FILE
    conag generate --suite COUNT --seed N --out-dir DIR      a balanced benchmark mix
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from world_server.generator import GenerationError, generate, generate_suite
from world_server.layout_options import FAMILIES, MAX_AGENTS, MAX_SIZE, MAX_TEAM, MIN_SIZE, SOURCES


def configure(g: argparse.ArgumentParser) -> None:
    g.add_argument("--seed", type=int, required=True, help="the same seed and options give the same file")
    g.add_argument("--family", choices=FAMILIES, help="blueprint family (default: drawn from the seed)")
    g.add_argument("--size", type=_size, metavar="N|WxH",
                   help=f"world size in cells, {MIN_SIZE} to {MAX_SIZE} a side (default: drawn)")
    g.add_argument("--agents", type=_agents, metavar="K",
                   help=f"1 to {MAX_AGENTS} agents (default: drawn); up to {MAX_TEAM} start side by side, "
                        "more spread over the floor")
    g.add_argument("--source", choices=SOURCES, help="brick source (default: drawn)")
    g.add_argument("--max-sites", type=int, metavar="M", help="at most this many open sites")
    g.add_argument("--out", metavar="FILE", help="the scenario file to write (- prints it)")
    g.add_argument("--suite", type=_count, metavar="COUNT",
                   help="write COUNT layouts, balanced over families, size bands and agent counts")
    g.add_argument("--out-dir", metavar="DIR", help="where --suite writes its files")


def _size(text: str) -> tuple[int, int]:
    try:
        dims = tuple(int(x) for x in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected N or WxH, got {text!r}") from None
    if len(dims) == 1:
        dims = dims * 2
    if len(dims) != 2 or not all(MIN_SIZE <= d <= MAX_SIZE for d in dims):
        raise argparse.ArgumentTypeError(f"size must be N or WxH with {MIN_SIZE} <= N, W, H <= {MAX_SIZE}, "
                                         f"got {text!r}")
    return dims[0], dims[1]


def _agents(text: str) -> int:
    try:
        k = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if not 1 <= k <= MAX_AGENTS:
        raise argparse.ArgumentTypeError(f"agents must be from 1 to {MAX_AGENTS}, got {k}")
    return k


def _count(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"expected a count >= 1, got {text!r}")
    return n


def _line(gen, path) -> str:
    built = f" (+{gen.prefilled} built)" if gen.prefilled else ""
    return (f"{gen.name}: {gen.family} {gen.cols}x{gen.rows}, {gen.sites} sites{built}, {gen.bricks} bricks, "
            f"{gen.agents} agent{'s' if gen.agents > 1 else ''}, {gen.source} -> {path}")


def run(args: argparse.Namespace) -> int:
    if args.suite is None and not args.out:
        raise ValueError("generate needs --out FILE (or --suite COUNT --out-dir DIR)")
    if args.suite is not None and (not args.out_dir or args.out or args.size):
        raise ValueError("--suite needs --out-dir DIR and takes neither --out nor --size")
    try:
        if args.suite is None:
            gen = generate(args.seed, args.family, args.size, args.agents, source=args.source,
                           max_sites=args.max_sites)
            if args.out == "-":
                sys.stdout.write(gen.text)
            else:
                Path(args.out).write_text(gen.text, encoding="utf-8")
                print(_line(gen, args.out))
            return 0
        _write_suite(args)
        return 0
    except GenerationError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1


def _write_suite(args: argparse.Namespace) -> None:
    out = Path(args.out_dir)
    out.mkdir(parents=True, exist_ok=True)
    options: dict = {"families": (args.family,)} if args.family else {}
    if args.agents:
        options["agents"] = (args.agents,)
    if args.max_sites:
        options["max_sites"] = (args.max_sites,) * 3
    for gen in generate_suite(args.suite, args.seed, **options):
        path = out / f"{gen.name}.toml"
        path.write_text(gen.text, encoding="utf-8")
        print(_line(gen, path), flush=True)

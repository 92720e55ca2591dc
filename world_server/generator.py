"""Seeded scenario generator: ordinary scenario files, every one buildable.

`generate(seed, family=..., size=..., agents=...)` draws a layout from an injected
`numpy.random.Generator` (no global randomness: the same arguments give byte-identical
TOML) and returns it with the parameters it chose. What varies:

* the blueprint family: `wall` (straight or L), `ring`, `nested_rings`, `pocket` (dead-end
  corridors that must be filled from the inside out, paper Fig. 18), `letter` (block
  letters of a built-in 5 x 7 font, scaled), `polyomino` (a random connected blob) and
  `multi` (several of those at once); and, asked for by name (an unset family and a suite
  draw from the first seven, as generator version 1 did): `block` (a solid rectangle or a
  compact filled blob, up to 10 x 10), `spiral` (a square spiral of sites one cell wide,
  one free cell between its arms), `corridor` (a winding one-cell path of sites, sometimes
  walled in: filled from its dead end) and `solid_hollow` (a solid block joined to a hollow
  frame); in any family some sites may already hold a brick;
* the brick source: one compact `pile`, `scattered` single bricks, or several `sources`
  far apart; always every open site's brick plus a few spare, all obtainable;
* obstacles: `#` walls with gaps, food and water walls and fields, world edges close to
  the structure;
* 1 to 12 agents starting side by side near the structure or far from it; asked for more
  (up to 1,024), they start spread over the whole floor instead. Worlds are 15 to 120 cells
  a side, so in a large one the blueprint lies far beyond an agent's 41 x 41 cell maps
  and 6-cell sensors: the agents must find it.

Each layout is checked with `world_server.buildability`; a refused one is drawn again
from a derived seed (a bounded number of times). `generate_suite` yields a balanced mix
of families, size bands and agent counts for benchmarks.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field

import numpy as np

from world_server.buildability import check_layout
from world_server.layout_options import (
    FAMILIES,
    MAX_AGENTS,
    MAX_SIZE,
    MAX_TEAM,
    MIN_SIZE,
    SIZE_BANDS,
    SOURCES,
    SUITE_FAMILIES,
)
from world_server.placement import spread_cells
from world_server.scenario import Scenario, parse_scenario

# The generator's version: bump it with any change that makes a different file for the same
# arguments. A suite manifest (world_server/suite.py) records the version that made it.
GENERATOR_VERSION = 1
SUITE_SHARES = (0.50, 0.38, 0.12)     # of a suite's layouts per size band: most finish quickly
SUITE_MAX_SITES = (32, 40, 40)        # open sites per layout in a suite, per size band (32: nested rings)
# Agent counts a suite cycles through: every count from 1 to 12 is there, small teams
# (the common case, and the cheap one to simulate on one core) more often.
SUITE_AGENTS = (1, 1, 2, 2, 3, 3, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12)
# Family mixes a suite may draw from, by name ("": generator version 1's). In "solid" the
# later families are about a quarter of the layouts (5 of 19 draws; blocks twice: solid
# blocks and compact blobs).
SUITE_MIXES = {"": SUITE_FAMILIES,
               "solid": SUITE_FAMILIES * 2 + ("block", "block", "spiral", "corridor", "solid_hollow")}
DEFAULT_MAX_SITES = (40, 80, 120)     # the same for a single `generate` call
MIN_TICKS = 20000
NESTED_MIN_SITES = 32                 # a 7 x 7 ring around a 3 x 3 one
SPIRAL_MIN_SITES = 13                 # the least spiral: 5 x 5 cells, two turns in
MAX_BLOCK_SIDE = 10                   # solid blocks and blobs: at most 10 x 10 sites
ATTEMPTS = 40                         # layouts drawn per call before giving up


class GenerationError(RuntimeError):
    """No buildable layout came out of the allowed attempts."""


@dataclass(frozen=True)
class GeneratedScenario:
    """A generated layout: what was drawn (family, size, agents, supply) and the scenario file text."""

    name: str
    seed: int
    family: str
    cols: int
    rows: int
    agents: int
    source: str                       # pile, scattered or sources
    sites: int                        # open sites (`+`)
    prefilled: int                    # sites already holding a brick (`B`)
    bricks: int                       # free bricks (`b`)
    max_ticks: int
    attempt: int                      # 1 + how many layouts were refused before this one
    text: str = field(repr=False)     # the scenario file

    def scenario(self) -> Scenario:
        """The scenario file parsed."""
        return parse_scenario(self.text, f"<{self.name}>")

    @property
    def size(self) -> tuple[int, int]:
        """(cols, rows)."""
        return self.cols, self.rows


# ---------------------------------------------------------------- public API


def generate(seed: int, family: str | None = None, size: int | tuple[int, int] | None = None,
             agents: int | None = None, *, source: str | None = None, max_sites: int | None = None,
             attempts: int = ATTEMPTS) -> GeneratedScenario:
    """One buildable scenario. Unset choices are drawn from `seed`; `size` is N or (cols, rows)."""
    _validate(seed, family, size, agents, source, max_sites)
    pick = np.random.default_rng([seed, 0])
    family = family or str(pick.choice(SUITE_FAMILIES))
    cols, rows = _pick_size(pick, size)
    agents = agents or _pick_agents(pick)
    source = source or str(pick.choice(SOURCES))
    cap = max_sites or DEFAULT_MAX_SITES[_band(max(cols, rows))]
    if family == "spiral" and cap < SPIRAL_MIN_SITES:
        raise ValueError(f"spiral needs max_sites >= {SPIRAL_MIN_SITES} (a 5 x 5 spiral)")
    if family == "nested_rings" and cap < NESTED_MIN_SITES:
        raise ValueError(f"nested_rings needs max_sites >= {NESTED_MIN_SITES} (two rings around a 3 x 3 one)")
    last = ""
    for attempt in range(1, attempts + 1):
        rng = np.random.default_rng([seed, attempt])  # a derived seed per try
        result = _draw(rng, seed, family, cols, rows, agents, source, cap, attempt)
        if isinstance(result, GeneratedScenario):
            return result
        last = result
    raise GenerationError(f"no buildable {family} layout of {cols}x{rows} cells with {agents} agents for "
                          f"seed {seed} in {attempts} attempts (last refusal: {last})")


def generate_suite(count: int, seed: int, **options) -> Iterator[GeneratedScenario]:
    """`count` buildable layouts in the mix `suite_plan(count, seed, **options)` lays out."""
    for item in suite_plan(count, seed, **options):
        yield generate(**item)


def suite_plan(count: int, seed: int, sizes: tuple[tuple[int, int], ...] = SIZE_BANDS,
               shares: tuple[float, ...] = SUITE_SHARES, families: tuple[str, ...] = SUITE_FAMILIES,
               agents: tuple[int, ...] = SUITE_AGENTS, sources: tuple[str, ...] = SOURCES,
               max_sites: tuple[int, ...] = SUITE_MAX_SITES) -> list[dict]:
    """The `generate` arguments of a balanced suite: families, agent counts and brick
    sources in turn, size bands (lo, hi) by `shares`, at most `max_sites` open sites per
    band. Layout i gets seed `seed * 10000 + i`."""
    if count < 1 or len(sizes) != len(shares) or len(max_sites) != len(sizes):
        raise ValueError("count must be >= 1, with one share and one max_sites per size band")
    rng = np.random.default_rng([seed, 1 << 20])
    bands = _quota(count, shares, rng)
    fams, crowd, kinds = (_cycle(items, count, rng) for items in (families, agents, sources))
    plan = []
    for i in range(count):
        lo, hi = sizes[bands[i]]
        cols = int(rng.integers(lo, hi + 1))
        rows = int(np.clip(round(cols * rng.uniform(0.75, 1.33)), lo, hi))
        plan.append({"seed": seed * 10000 + i, "family": fams[i], "size": (cols, rows), "agents": int(crowd[i]),
                     "source": kinds[i], "max_sites": max_sites[bands[i]]})
    return plan


# ---------------------------------------------------------------- choices


def _validate(seed, family, size, agents, source, max_sites) -> None:
    if family is not None and family not in FAMILIES:
        raise ValueError(f"unknown family {family!r}; choose from {', '.join(FAMILIES)}")
    if source is not None and source not in SOURCES:
        raise ValueError(f"unknown brick source {source!r}; choose from {', '.join(SOURCES)}")
    dims = (size, size) if isinstance(size, int) else size
    if dims is not None and (len(dims) != 2 or not all(MIN_SIZE <= int(d) <= MAX_SIZE for d in dims)):
        raise ValueError(f"size must be from {MIN_SIZE} to {MAX_SIZE} cells a side, got {size!r}")
    if agents is not None and not 1 <= agents <= MAX_AGENTS:
        raise ValueError(f"agents must be from 1 to {MAX_AGENTS}, got {agents}")
    if seed < 0:
        raise ValueError(f"seed must be >= 0, got {seed}")
    if max_sites is not None and max_sites < 8:
        raise ValueError(f"max_sites must be at least 8, got {max_sites}")


def _band(side: int) -> int:
    return next(i for i, (lo, hi) in enumerate(SIZE_BANDS) if side <= hi)


def _pick_size(rng: np.random.Generator, size) -> tuple[int, int]:
    if isinstance(size, int):
        return size, size
    if size is not None:
        return int(size[0]), int(size[1])
    lo, hi = SIZE_BANDS[int(rng.choice(len(SIZE_BANDS), p=SUITE_SHARES))]
    cols = int(rng.integers(lo, hi + 1))
    return cols, int(np.clip(round(cols * rng.uniform(0.75, 1.33)), lo, hi))


def _pick_agents(rng: np.random.Generator) -> int:
    weights = np.array([4, 3, 3, 2, 2, 1.5, 1, 1, 1, 1, 1, 1])  # small teams are the common case
    return int(rng.choice(np.arange(1, MAX_TEAM + 1), p=weights / weights.sum()))


def _quota(count: int, shares: tuple[float, ...], rng: np.random.Generator) -> np.ndarray:
    """Band of every suite layout: counts as close to `shares` as whole numbers allow, shuffled."""
    raw = np.asarray(shares, float) / sum(shares) * count
    n = np.floor(raw).astype(int)
    for i in np.argsort(n - raw)[: count - n.sum()]:  # largest remainders get the rest
        n[i] += 1
    return rng.permutation(np.repeat(np.arange(len(shares)), n))


def _cycle(items: tuple, count: int, rng: np.random.Generator) -> list:
    """`items` over and over, each round in a fresh random order: balanced, not patterned."""
    out: list = []
    while len(out) < count:
        out.extend(items[i] for i in rng.permutation(len(items)))
    return out[:count]


# ---------------------------------------------------------------- one layout


def _draw(rng, seed, family, cols, rows, agents, source, cap, attempt) -> GeneratedScenario | str:
    """One try: a GeneratedScenario, or the reason this layout was refused."""
    world, near = _World(rows, cols), bool(rng.random() < (0.6 if max(cols, rows) <= 30 else 0.4))
    refusal = world.compose(rng, family, source, agents, near, cap)
    if refusal:
        return refusal
    verdict = check_layout(world.layout(), agents)
    if not verdict.ok:
        return verdict.reason
    if verdict.spare < 2:  # a few spare bricks the agents can reach, not just lying somewhere
        return f"only {verdict.spare} spare bricks can be reached"
    prefilled = 0
    if rng.random() < 0.25:  # some sites already built: the first fills of a working order
        prefilled = int(rng.integers(1, max(2, len(verdict.order) // 4) + 1))
        world.prefill(verdict.order[:prefilled], verdict.bricks[:prefilled])
    layout = world.layout()
    sites, bricks = _count(layout, "+"), _count(layout, "b")
    ticks = _max_ticks(sites, cols, rows, agents)
    description = (f"Generated: {family} blueprint, {cols}x{rows} world, {sites} open sites"
                   f"{f' ({prefilled} more already built)' if prefilled else ''}, {bricks} free bricks "
                   f"({source}), {agents} agent{'s' if agents > 1 else ''} starting "
                   f"{_where(agents, near)}; {world.obstacle_note()}.")
    how = (f"conag generate --seed {seed} --family {family} --size {cols}x{rows} --agents {agents} "
           f"--source {source} --max-sites {cap}")  # every choice explicit: the same file again
    name = f"gen-{family}-{seed}"
    text = _toml(name, seed, agents, ticks, description, layout, how)
    return GeneratedScenario(name, seed, family, cols, rows, agents, source, sites, prefilled, bricks, ticks,
                             attempt, text)


def _where(agents: int, near: bool) -> str:
    if agents > MAX_TEAM:
        return "spread over the floor"
    return f"{'near' if near else 'far from'} the structure"


def _count(layout: list[str], ch: str) -> int:
    return sum(row.count(ch) for row in layout)


def _max_ticks(sites: int, cols: int, rows: int, agents: int) -> int:
    """A generous limit: every site a trip across a good part of the world, plus a search
    of the whole world for the blueprint; shared (not perfectly) among the agents."""
    work = sites * (150 + 4 * (cols + rows)) + 2 * cols * rows
    return int(math.ceil((MIN_TICKS + work / math.sqrt(agents)) / 1000) * 1000)


def _toml(name: str, seed: int, agents: int, ticks: int, description: str, layout: list[str], how: str) -> str:
    body = "\n".join(layout)
    return (f"# Generated by world_server.generator ({how}); buildable by construction.\n"
            f'name = "{name}"\n'
            f'description = "{description}"\n'
            f"seed = {seed}\n"
            f"agents = {agents}\n"
            f'tick_mode = "lockstep"\n'
            f"max_ticks = {ticks}\n"
            f'layout = """\n{body}\n"""\n')


# ---------------------------------------------------------------- the world being drawn


_OBSTACLE_PLURAL = {"# wall with gaps": "# walls with gaps", "food and water wall with gaps":
                    "food and water walls with gaps", "food and water field": "food and water fields"}


class _World:
    """A layout under construction: chars [row, col] and the cells kept clear around the
    structure (no obstacle, brick or agent may go there)."""

    def __init__(self, rows: int, cols: int):
        self.grid = np.full((rows, cols), ".", "<U1")
        self.reserved = np.zeros((rows, cols), bool)
        self.notes: list[str] = []

    @property
    def shape(self) -> tuple[int, int]:
        return self.grid.shape

    def layout(self) -> list[str]:
        return ["".join(row) for row in self.grid]

    def obstacle_note(self) -> str:
        if not self.notes:
            return "no obstacles"
        counts = {note: self.notes.count(note) for note in self.notes}  # first-seen order
        return ", ".join(f"a {note}" if n == 1 else f"{n} {_OBSTACLE_PLURAL[note]}" for note, n in counts.items())

    def free(self) -> np.ndarray:
        return (self.grid == ".") & ~self.reserved

    def compose(self, rng, family: str, source: str, agents: int, near: bool, cap: int) -> str:
        """Structure, obstacles, bricks and agents, in that order; '' or why it failed."""
        low = {"nested_rings": NESTED_MIN_SITES, "spiral": SPIRAL_MIN_SITES, "block": 9}.get(family, 6)
        if not self.place_structure(rng, family, int(rng.integers(max(low, cap // 3), cap + 1))):
            return "the structure did not fit"
        self.add_obstacles(rng)
        n_open = int((self.grid == "+").sum())
        if n_open > cap:
            return f"{n_open} sites, more than the {cap} allowed"
        if not self.add_bricks(rng, source, n_open + int(rng.integers(2, 3 + max(2, n_open // 10)))):
            return "the bricks did not fit"
        if not self.add_agents(rng, agents, near):
            return "the agents did not fit"
        return ""

    # -- the structure

    def place_structure(self, rng, family: str, budget: int) -> bool:
        parts = _multi_parts(rng, budget) if family == "multi" else [(family, budget)]
        placed = 0
        for fam, share in parts:
            stamp = _stamp(rng, fam, share, self.shape)
            placed += self._put(rng, stamp)
        return placed == len(parts)

    def _put(self, rng, stamp: np.ndarray, tries: int = 200) -> bool:
        """Stamp a structure at a random free spot, its box plus a one-cell margin reserved;
        sometimes hard against the world edge."""
        rows, cols = self.shape
        h, w = stamp.shape
        if h > rows or w > cols:
            return False
        for _ in range(tries):
            if rng.random() < 0.25:  # the world edge close to the structure
                r = int(rng.choice([0, rows - h]))
                c = int(rng.integers(0, cols - w + 1))
                if rng.random() < 0.5:
                    r, c = int(rng.integers(0, rows - h + 1)), int(rng.choice([0, cols - w]))
            else:
                r, c = int(rng.integers(0, rows - h + 1)), int(rng.integers(0, cols - w + 1))
            box = (slice(max(r - 1, 0), r + h + 1), slice(max(c - 1, 0), c + w + 1))
            if self.reserved[box].any():
                continue
            self.reserved[box] = True
            window = self.grid[r:r + h, c:c + w]
            window[stamp != " "] = stamp[stamp != " "]
            return True
        return False

    def prefill(self, sites, bricks) -> None:
        """Play the first fills of a working order: each site gets its brick."""
        for (c, r), (bc, br) in zip(sites, bricks):
            self.grid[r, c], self.grid[br, bc] = "B", "."

    # -- obstacles

    def add_obstacles(self, rng) -> None:
        rows, cols = self.shape
        n = int(rng.integers(0, 2 + rows * cols // 1200))
        for _ in range(n):
            kind = rng.choice(["wall", "food_wall", "field"], p=[0.4, 0.35, 0.25])
            if kind == "field":
                self._field(rng)
            else:
                self._wall(rng, "#" if kind == "wall" else None)

    def _wall(self, rng, material: str | None) -> None:
        """A straight wall across much of the world, with 1 to 3 gaps (and broken wherever
        it would cross the structure's clear zone)."""
        rows, cols = self.shape
        vertical = bool(rng.random() < 0.5)
        span = rows if vertical else cols
        length = int(rng.integers(span // 2, span + 1))
        start = int(rng.integers(0, span - length + 1))
        at = int(rng.integers(1, (cols if vertical else rows) - 1))
        cells = np.ones(length, bool)
        for _ in range(int(rng.integers(1, 4))):
            g = int(rng.integers(0, length))
            cells[g:g + int(rng.integers(1, 4))] = False
        chars = self._material(rng, material, length)
        for i in np.flatnonzero(cells):
            r, c = (start + i, at) if vertical else (at, start + i)
            if self.grid[r, c] == "." and not self.reserved[r, c]:
                self.grid[r, c] = chars[i]
        self.notes.append("# wall with gaps" if material == "#" else "food and water wall with gaps")

    def _field(self, rng) -> None:
        rows, cols = self.shape
        h, w = int(rng.integers(3, max(4, rows // 3))), int(rng.integers(3, max(4, cols // 3)))
        r, c = int(rng.integers(0, rows - h + 1)), int(rng.integers(0, cols - w + 1))
        density = rng.uniform(0.05, 0.2)
        mask = (rng.random((h, w)) < density) & self.free()[r:r + h, c:c + w]
        chars = self._material(rng, None, h * w).reshape(h, w)
        self.grid[r:r + h, c:c + w][mask] = chars[mask]
        self.notes.append("food and water field")

    @staticmethod
    def _material(rng, material: str | None, n: int) -> np.ndarray:
        if material:
            return np.full(n, material)
        mix = rng.choice(["F", "W", "FW"])
        return rng.choice(list(mix), size=n)

    # -- bricks

    def add_bricks(self, rng, source: str, n: int) -> bool:
        if source == "scattered":
            return self._scatter(rng, n)
        k = 1 if source == "pile" else int(rng.integers(2, 5))
        sizes = [n // k + (i < n % k) for i in range(k)]
        centres = self._far_apart(rng, k)
        return all(self._pile(rng, m, ctr) or self._scatter(rng, m) for m, ctr in zip(sizes, centres))

    def _scatter(self, rng, n: int) -> bool:
        """Single bricks at random free cells, apart where there is room (no other brick
        beside them), side by side where there is not."""
        cells = np.argwhere(self.free())
        cells = cells[rng.permutation(len(cells))]
        placed = 0
        for spaced in (True, False):
            for r, c in cells:
                if placed == n:
                    return True
                crowded = spaced and (self.grid[max(r - 1, 0):r + 2, max(c - 1, 0):c + 2] == "b").any()
                if self.grid[r, c] == "." and not crowded:
                    self.grid[r, c] = "b"
                    placed += 1
        return placed == n

    def _pile(self, rng, n: int, centre: tuple[int, int]) -> bool:
        """A compact block of n bricks near `centre`, on free cells only."""
        rows, cols = self.shape
        w = max(1, round(math.sqrt(n) * rng.uniform(0.7, 1.4)))
        h = -(-n // w)
        free = self.free()
        for _ in range(60):
            r = int(np.clip(centre[0] - h // 2 + rng.integers(-3, 4), 0, rows - h))
            c = int(np.clip(centre[1] - w // 2 + rng.integers(-3, 4), 0, cols - w))
            if r < 0 or c < 0 or not free[r:r + h, c:c + w].all():
                continue
            block = np.zeros((h, w), bool).ravel()
            block[:n] = True
            self.grid[r:r + h, c:c + w][block.reshape(h, w)] = "b"
            return True
        return False

    def _far_apart(self, rng, k: int) -> list[tuple[int, int]]:
        """k free cells spread over the world (each the farthest of a few random candidates)."""
        cells = np.argwhere(self.free())
        chosen = [cells[rng.integers(len(cells))]]
        while len(chosen) < k:
            cand = cells[rng.integers(len(cells), size=16)]
            dist = np.min([np.abs(cand - p).sum(axis=1) for p in chosen], axis=0)
            chosen.append(cand[int(np.argmax(dist))])
        return [(int(p[0]), int(p[1])) for p in chosen]

    # -- agents

    def add_agents(self, rng, k: int, near: bool) -> bool:
        """k starts side by side (a breadth-first blob over free cells) from one cell near
        the structure or as far from it as the world allows; more than MAX_TEAM spread
        over the whole floor from that cell (`placement.spread_cells`): hundreds side by
        side would be a clump in which every body blocks the others."""
        free = self.free()
        cells = np.argwhere(free)
        if len(cells) < k:
            return False
        struct = np.argwhere(self.reserved)
        dist = np.min(np.abs(cells[:, None, :] - struct[None, ::max(1, len(struct) // 64), :]).sum(axis=2), axis=1)
        pool = cells[dist <= np.quantile(dist, 0.1)] if near else cells[dist >= np.quantile(dist, 0.9)]
        first = tuple(pool[rng.integers(len(pool))])
        if k > MAX_TEAM:
            blob = [(int(r), int(c)) for c, r in spread_cells(free, k, (int(first[1]), int(first[0])))]
        else:
            blob = _bfs_cells(free, first, k)
        if len(blob) < k:
            return False
        for r, c in blob:
            self.grid[r, c] = "A"
        return True


def _bfs_cells(free: np.ndarray, first: tuple[int, int], k: int) -> list[tuple[int, int]]:
    rows, cols = free.shape
    seen, queue = {first}, [first]
    for r, c in queue:
        if len(queue) >= k:
            break
        for n in ((r, c + 1), (r + 1, c), (r, c - 1), (r - 1, c)):
            if n not in seen and 0 <= n[0] < rows and 0 <= n[1] < cols and free[n]:
                seen.add(n)
                queue.append(n)
    return queue[:k]


# ---------------------------------------------------------------- blueprint families
#
# A stamp is a small char array: '+' sites, '#', 'F', 'W' obstacles that belong to the
# structure (a pocket's walls), '.' cells kept empty, ' ' nothing (not drawn).


def _stamp(rng, family: str, budget: int, shape: tuple[int, int]) -> np.ndarray:
    span = min(shape) - 2  # leave room for the margin
    return {"wall": _wall_stamp, "ring": _ring_stamp, "nested_rings": _nested_stamp,
            "pocket": _pocket_stamp, "letter": _letter_stamp, "polyomino": _polyomino_stamp,
            "block": _block_stamp, "spiral": _spiral_stamp, "corridor": _corridor_stamp,
            "solid_hollow": _solid_hollow_stamp}[family](
        rng, max(budget, 4), span)


def _multi_parts(rng, budget: int) -> list[tuple[str, int]]:
    k = int(rng.integers(2, 5))
    fams = rng.choice(["wall", "ring", "pocket", "letter", "polyomino"], size=k)
    return [(str(f), max(4, budget // k)) for f in fams]


def _wall_stamp(rng, budget: int, span: int) -> np.ndarray:
    """A straight wall, or an L, one or two cells thick."""
    thick = 2 if rng.random() < 0.2 and budget >= 12 else 1
    length = int(np.clip(budget // thick, 3, span))
    if rng.random() < 0.5:
        s = np.full((thick, length), "+")
    else:  # arms of a and b cells along the outside corner
        a = int(rng.integers(thick + 1, max(thick + 2, length - 1)))
        b = int(np.clip(length - a + thick, thick + 1, span))
        s = np.full((b, a), " ")
        s[:thick, :] = "+"
        s[:, :thick] = "+"
        s = np.rot90(s, int(rng.integers(4)))
    return s if rng.random() < 0.5 else s.T


def _ring_stamp(rng, budget: int, span: int) -> np.ndarray:
    w, h = _ring_dims(rng, budget, span)
    s = np.full((h, w), ".")
    s[[0, -1], :] = "+"
    s[:, [0, -1]] = "+"
    return s


def _ring_dims(rng, budget: int, span: int) -> tuple[int, int]:
    """A rectangle whose perimeter (2w + 2h - 4 sites) fits the budget and the world."""
    half = max(4, (budget + 4) // 2)  # w + h
    w = int(np.clip(rng.integers(3, max(4, half - 2)), 3, span))
    h = int(np.clip(half - w, 3, span))
    return w, h


def _nested_stamp(rng, budget: int, span: int) -> np.ndarray:
    """Two or three concentric rings, one or two free cells between them; the inner ones
    must be finished before an outer ring closes (paper Fig. 14)."""
    options = [(k, gap, w, h) for k in (2, 3) for gap in (1, 2) for w in range(3, 10) for h in range(3, 10)
               if _nested_sites(k, gap, w, h) <= budget and max(w, h) + 2 * (k - 1) * (gap + 1) <= span]
    k, gap, w, h = options[int(rng.integers(len(options)))] if options else (2, 1, 3, 3)
    step = gap + 1
    w, h = w + 2 * (k - 1) * step, h + 2 * (k - 1) * step  # the outer ring
    s = np.full((h, w), ".")
    for i in range(k):
        o = i * step
        s[o, o:w - o] = s[h - 1 - o, o:w - o] = "+"
        s[o:h - o, o] = s[o:h - o, w - 1 - o] = "+"
    return s


def _nested_sites(k: int, gap: int, w: int, h: int) -> int:
    """Sites of k rings around an inner w x h ring, `gap` free cells apart."""
    return sum(2 * (w + h) - 4 + 8 * i * (gap + 1) for i in range(k))


def _pocket_stamp(rng, budget: int, span: int) -> np.ndarray:
    """One to four dead-end corridors side by side (a comb), walled with `#` or food and
    water; every corridor cell is a site, so each is filled from its end outwards."""
    width = 1 if rng.random() < 0.75 else 2
    k = int(np.clip(rng.integers(1, 5), 1, max(1, budget // (2 * width))))
    depth = int(np.clip(budget // (k * width), 2, max(2, span - 2)))
    wall = str(rng.choice(["#", "F", "W", "FW"]))
    cols = k * (width + 1) + 1
    s = np.full((depth + 1, cols), " ")
    for i in range(k):
        c = 1 + i * (width + 1)
        s[:depth, c:c + width] = "+"
    walls = np.zeros(s.shape, bool)
    walls[:, 0::width + 1] = True
    walls[depth, :] = True
    s[walls] = rng.choice(list(wall), size=int(walls.sum()))
    s = np.vstack([np.full((1, cols), "."), s])  # the mouths open onto a clear row
    return np.rot90(s, int(rng.integers(4)))


_FONT = {  # 5 x 7 block letters, '#' = a site
    "A": ".###.|#...#|#...#|#####|#...#|#...#|#...#", "B": "####.|#...#|#...#|####.|#...#|#...#|####.",
    "C": ".###.|#...#|#....|#....|#....|#...#|.###.", "D": "####.|#...#|#...#|#...#|#...#|#...#|####.",
    "E": "#####|#....|#....|####.|#....|#....|#####", "F": "#####|#....|#....|####.|#....|#....|#....",
    "G": ".###.|#...#|#....|#.###|#...#|#...#|.###.", "H": "#...#|#...#|#...#|#####|#...#|#...#|#...#",
    "I": "#####|..#..|..#..|..#..|..#..|..#..|#####", "J": "..###|...#.|...#.|...#.|#..#.|#..#.|.##..",
    "K": "#...#|#..#.|#.#..|##...|#.#..|#..#.|#...#", "L": "#....|#....|#....|#....|#....|#....|#####",
    "M": "#...#|##.##|#.#.#|#.#.#|#...#|#...#|#...#", "N": "#...#|##..#|#.#.#|#..##|#...#|#...#|#...#",
    "O": ".###.|#...#|#...#|#...#|#...#|#...#|.###.", "P": "####.|#...#|#...#|####.|#....|#....|#....",
    "Q": ".###.|#...#|#...#|#...#|#.#.#|#..#.|.##.#", "R": "####.|#...#|#...#|####.|#.#..|#..#.|#...#",
    "S": ".####|#....|#....|.###.|....#|....#|####.", "T": "#####|..#..|..#..|..#..|..#..|..#..|..#..",
    "U": "#...#|#...#|#...#|#...#|#...#|#...#|.###.", "V": "#...#|#...#|#...#|#...#|#...#|.#.#.|..#..",
    "W": "#...#|#...#|#...#|#.#.#|#.#.#|##.##|#...#", "X": "#...#|#...#|.#.#.|..#..|.#.#.|#...#|#...#",
    "Y": "#...#|#...#|.#.#.|..#..|..#..|..#..|..#..", "Z": "#####|....#|...#.|..#..|.#...|#....|#####",
}


def _letter_stamp(rng, budget: int, span: int) -> np.ndarray:
    """One to three block letters, each font pixel a scale x scale square of sites."""
    cells = {ch: sum(row.count("#") for row in rows.split("|")) for ch, rows in _FONT.items()}
    scale = int(rng.integers(1, 4))
    while scale > 1 and (7 * scale > span or min(cells.values()) * scale * scale > budget):
        scale -= 1
    fits = sorted(ch for ch in cells if cells[ch] * scale * scale <= budget) or [min(cells, key=cells.__getitem__)]
    word = [str(rng.choice(fits))]
    while len(word) < 3 and rng.random() < 0.6:
        nxt = str(rng.choice(sorted(cells)))
        width = (len(word) + 1) * 6 * scale
        if sum(cells[ch] for ch in [*word, nxt]) * scale * scale > budget or width > span:
            break
        word.append(nxt)
    glyphs = [np.array([list(r) for r in _FONT[ch].split("|")]) for ch in word]
    gap = np.full((7, 1), ".")
    pixels = np.hstack([x for g in glyphs for x in (g, gap)][:-1])
    big = np.kron(pixels == "#", np.ones((scale, scale), bool))
    return np.where(big, "+", ".")


def _polyomino_stamp(rng, budget: int, span: int) -> np.ndarray:
    """A random connected polyomino of about `budget` cells, grown cell by cell from one;
    some come out compact (a solid blob filled from its core), some stringy."""
    n = int(np.clip(budget, 4, span * span // 2))
    compact = rng.uniform(0.0, 1.0)
    cells = {(0, 0)}
    frontier = [(0, 1), (1, 0), (0, -1), (-1, 0)]
    while len(cells) < n and frontier:
        # compact growth prefers frontier cells with many neighbours already in the shape
        score = np.array([sum((r + dr, c + dc) in cells for dr, dc in ((0, 1), (1, 0), (0, -1), (-1, 0)))
                          for r, c in frontier], float)
        weights = np.exp(compact * 2.0 * score)
        r, c = frontier.pop(int(rng.choice(len(frontier), p=weights / weights.sum())))
        if (r, c) in cells:
            continue
        rs, cs = zip(*cells, (r, c))
        if max(rs) - min(rs) >= span or max(cs) - min(cs) >= span:
            continue
        cells.add((r, c))
        frontier.extend(n for n in ((r, c + 1), (r + 1, c), (r, c - 1), (r - 1, c))
                        if n not in cells and n not in frontier)
    rs, cs = zip(*cells)
    s = np.full((max(rs) - min(rs) + 1, max(cs) - min(cs) + 1), ".")
    for r, c in cells:
        s[r - min(rs), c - min(cs)] = "+"
    return s


def _block_stamp(rng, budget: int, span: int) -> np.ndarray:
    """A solid rectangle of sites (half the time), else a compact blob: a filled ellipse
    or a rectangle with its corners bitten off; at most MAX_BLOCK_SIDE a side."""
    side = min(MAX_BLOCK_SIDE, span)
    dims = [(w, h) for w in range(3, side + 1) for h in range(3, side + 1)
            if w * h <= budget and max(w, h) <= 2 * min(w, h)]
    w, h = dims[int(rng.integers(len(dims)))] if dims else (3, 3)
    if rng.random() < 0.5:
        return np.full((h, w), "+")
    r, c = np.mgrid[0:h, 0:w]
    if rng.random() < 0.5:  # an ellipse through the middles of the box's sides
        inside = ((r - (h - 1) / 2) / (h / 2)) ** 2 + ((c - (w - 1) / 2) / (w / 2)) ** 2 <= 1.0
    else:  # corners cut by 1 or 2 cells
        k = int(rng.integers(1, 3)) if min(w, h) >= 5 else 1
        inside = np.minimum(r, h - 1 - r) + np.minimum(c, w - 1 - c) >= k
    s = np.where(inside, "+", ".")
    keep = np.flatnonzero(inside.any(axis=1))
    cols = np.flatnonzero(inside.any(axis=0))
    return s[keep[0]:keep[-1] + 1, cols[0]:cols[-1] + 1]


def spiral_cells(n: int) -> list[tuple[int, int]]:
    """(row, col) cells of a square spiral one cell wide in an n x n box (n odd >= 5),
    one free cell between its arms: along the west side from the south-west corner up,
    then clockwise inwards. Its corridor opens at the south-west corner."""
    cells = [(n - 1, 0)]
    r, c = n - 1, 0
    turns = ((-1, 0), (0, 1), (1, 0), (0, -1))  # north, east, south, west
    # the first three arms span the box; then each pair of arms is 2 shorter
    lengths = [n - 1, n - 1, n - 1] + [x for k in range(n - 3, 0, -2) for x in (k, k)]
    for i, length in enumerate(lengths):
        dr, dc = turns[i % 4]
        for _ in range(length):
            r, c = r + dr, c + dc
            cells.append((r, c))
    return cells


def _spiral_stamp(rng, budget: int, span: int) -> np.ndarray:
    """A square spiral of sites one cell wide, 5 x 5 to as large as the budget and the world
    allow, turned and mirrored at random."""
    sizes = [n for n in range(5, span + 1, 2) if len(spiral_cells(n)) <= budget]
    n = sizes[int(rng.integers(len(sizes)))] if sizes else 5
    s = np.full((n, n), ".")
    for r, c in spiral_cells(n):
        s[r, c] = "+"
    s = np.rot90(s, int(rng.integers(4)))
    return s if rng.random() < 0.5 else s.T


def _corridor_stamp(rng, budget: int, span: int) -> np.ndarray:
    """A winding path of sites one cell wide: runs of 3 or more cells, two cells apart,
    joined alternately at either end (a serpentine). Half the time walled in with `#` or
    food and water, one mouth open at its start: then it is filled from its dead end."""
    runs = int(rng.integers(2, 6))
    length = int(np.clip(budget // runs, 3, max(3, span - 2)))
    while runs > 2 and runs * length + runs - 1 > budget:
        runs -= 1
    length = int(np.clip((budget - (runs - 1)) // runs, 3, max(3, span - 2)))
    h, w = 2 * runs - 1, length
    s = np.full((h, w), ".")
    for k in range(runs):
        s[2 * k, :] = "+"
        if k < runs - 1:
            s[2 * k + 1, w - 1 if k % 2 == 0 else 0] = "+"
    if rng.random() < 0.5:
        wall = np.full((h + 2, w + 2), " ")
        chars = rng.choice(list(str(rng.choice(["#", "F", "W", "FW"]))), size=wall.shape)
        wall[:, :] = chars
        wall[1:-1, 1:-1] = np.where(s == "+", "+", chars[1:-1, 1:-1])
        wall[1, 0] = "."  # the mouth, at the start of the first run
        s = wall
    s = np.rot90(s, int(rng.integers(4)))
    return s if rng.random() < 0.5 else s.T


def _solid_hollow_stamp(rng, budget: int, span: int) -> np.ndarray:
    """A solid block of sites and a hollow frame of sites side by side, sharing an edge:
    the block is filled from its core, the frame's inside stays empty."""
    side = min(MAX_BLOCK_SIDE, span)
    options = [(h, a, b) for h in range(3, side + 1) for a in range(2, side) for b in range(3, side + 1)
               if a + b <= side and h * a + 2 * b + 2 * (h - 2) - (2 if b else 0) <= budget and b >= 3]
    h, a, b = options[int(rng.integers(len(options)))] if options else (3, 2, 3)
    s = np.full((h, a + b), ".")
    s[:, :a] = "+"
    s[[0, -1], a:] = "+"
    s[:, -1] = "+"
    s = np.rot90(s, int(rng.integers(4)))
    return s if rng.random() < 0.5 else s.T


def word_sites(word: str) -> np.ndarray:
    """bool [row, col]: `word` in the generator's 5 x 7 block letters, one free column
    between letters (a hand-made layout's structure, e.g. experiments/team_size.py's)."""
    glyphs = [np.array([list(r) for r in _FONT[ch].split("|")]) == "#" for ch in word.upper()]
    gap = np.zeros((7, 1), bool)
    return np.hstack([x for g in glyphs for x in (g, gap)][:-1])

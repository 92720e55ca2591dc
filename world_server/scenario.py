"""Scenario files (a contract, docs/design.md): TOML with a bird's-eye ASCII layout.

    name = "quick_wall"          # required
    seed = 7                     # required, integer
    agents = 1                   # required, how many agents the scenario runs
    tick_mode = "lockstep"       # or "realtime"; default lockstep
    max_ticks = 20000            # optional tick limit for a run
    description = "..."          # optional
    layout = \"\"\"
    ..+++..
    .b.A.b.
    \"\"\"
    [world]                      # optional WorldConfig overrides, e.g. sensor_range = 5.0

Layout: one character a cell, north row first: `.` empty, `F` food, `W` water, `b` free
brick, `+` drop site (empty), `B` brick already on a drop site, `#` fixed obstacle,
`A` an agent's start. Common indentation is removed; rows must have equal length.
Every error names the file, line and column and what was expected.

Two conventions for a cell: bool grids (`Scenario.grid`, like the agents' maps) are
indexed [row, col]; cell coordinates (`Scenario.cells_col_row`, `to_world`, `to_cell`,
and the scenario files' comments) are (col, row), column first like (x, y).
"""

from __future__ import annotations

import re
import textwrap
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from world_server.config import WorldConfig

LAYOUT_CHARS = {
    ".": "empty", "F": "food", "W": "water", "b": "free brick", "+": "drop site",
    "B": "brick on a drop site", "#": "fixed obstacle", "A": "agent start",
}
TICK_MODES = ("lockstep", "realtime")
_KEYS = {"name", "seed", "agents", "tick_mode", "max_ticks", "description", "layout", "world"}


class ScenarioError(ValueError):
    """A scenario file is invalid; carries where (line 0: the file as a whole) and what was expected."""

    def __init__(self, path: str, line: int, column: int, expected: str, found: str = ""):
        self.path, self.line, self.column, self.expected = path, line, column, expected
        detail = f" (found {found})" if found else ""
        where = f"{path}:{line}:{column}" if line else path
        super().__init__(f"{where}: expected {expected}{detail}")


@dataclass(frozen=True)
class Scenario:
    """A parsed scenario file: name, seed, agents, tick mode and limit, the layout rows, the world."""

    name: str
    seed: int
    agents: int
    tick_mode: str
    max_ticks: int
    layout: tuple[str, ...]
    world: WorldConfig = field(default_factory=WorldConfig)
    description: str = ""
    path: str = "<string>"

    @property
    def rows(self) -> int:
        """Rows of the layout (north first)."""
        return len(self.layout)

    @property
    def cols(self) -> int:
        """Columns of the layout (west first)."""
        return len(self.layout[0])

    def cells_col_row(self, chars: str) -> np.ndarray:
        """(k, 2) int array of (col, row) of every cell holding one of `chars`, reading order.

        Column first, as `to_world` and `to_cell` take and give cells (x before y); the
        grids (`grid`, the agents' maps) are indexed [row, col] instead."""
        found = [(c, r) for r, line in enumerate(self.layout) for c, ch in enumerate(line) if ch in chars]
        return np.array(found, dtype=np.int64).reshape(-1, 2)

    def grid(self, chars: str) -> np.ndarray:
        """bool [row, col]: where the layout holds one of `chars` (row 0 is the north)."""
        return np.isin(np.array([list(line) for line in self.layout]), list(chars))

    def to_world(self, cells: ArrayLike) -> np.ndarray:
        """Cell (col, row) -> world (x, y) of the cell centre; y grows northwards."""
        cells = np.asarray(cells, dtype=np.float64).reshape(-1, 2)
        size = self.world.cell_size
        return np.column_stack([(cells[:, 0] + 0.5) * size, (self.rows - 1 - cells[:, 1] + 0.5) * size])

    def to_cell(self, xy: ArrayLike) -> np.ndarray:
        """World (x, y) -> the (col, row) of the cell holding it."""
        xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
        size = self.world.cell_size
        return np.column_stack([np.floor(xy[:, 0] / size), self.rows - 1 - np.floor(xy[:, 1] / size)]).astype(np.int64)

    @property
    def size(self) -> tuple[float, float]:
        """World width and height in world units."""
        return self.cols * self.world.cell_size, self.rows * self.world.cell_size


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario file; raise ScenarioError or FileNotFoundError.

    A directory, an unreadable file or one that is not UTF-8 text is a ScenarioError that
    names the file (and the place of the first byte that is not UTF-8)."""
    path = Path(path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise
    except IsADirectoryError:
        raise ScenarioError(str(path), 0, 0, "a scenario file", "a directory") from None
    except OSError as exc:
        raise ScenarioError(str(path), 0, 0, "a readable scenario file", exc.strerror or str(exc)) from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        before = data[:exc.start].decode("utf-8").split("\n")
        raise ScenarioError(str(path), len(before), len(before[-1]) + 1, "UTF-8 text",
                            f"byte 0x{data[exc.start]:02x}") from None
    return parse_scenario(text, str(path))


def parse_scenario(text: str, path: str = "<string>") -> Scenario:
    """Parse and validate scenario TOML `text` (`path` names it in errors); raise ScenarioError."""
    try:
        doc = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        m = re.search(r"\(at line (\d+), column (\d+)\)", str(exc))
        line, col = (int(m.group(1)), int(m.group(2))) if m else (1, 1)
        if not m and "at end of document" in str(exc):
            end = text.splitlines() or [""]
            line, col = len(end), len(end[-1]) + 1
        raise ScenarioError(path, line, col, "valid TOML", str(exc).split(" (at")[0]) from None
    lines = text.splitlines()
    for key in doc:
        if key not in _KEYS:
            raise ScenarioError(path, *_key_pos(lines, key), f"one of the keys {', '.join(sorted(_KEYS))}",
                                f"unknown key {key!r}")
    name = _get(doc, lines, path, "name", str, "a non-empty string for name")
    seed = _get(doc, lines, path, "seed", int, "an integer seed")
    agents = _get(doc, lines, path, "agents", int, "an integer agent count >= 0")
    if not name.strip():
        raise ScenarioError(path, *_key_pos(lines, "name"), "a non-empty string for name")
    if agents < 0:
        raise ScenarioError(path, *_key_pos(lines, "agents"), "an agent count >= 0", str(agents))
    tick_mode = _get(doc, lines, path, "tick_mode", str, "tick_mode \"lockstep\" or \"realtime\"", "lockstep")
    if tick_mode not in TICK_MODES:
        raise ScenarioError(path, *_key_pos(lines, "tick_mode"), "tick_mode \"lockstep\" or \"realtime\"",
                            repr(tick_mode))
    max_ticks = _get(doc, lines, path, "max_ticks", int, "a positive integer max_ticks", 20000)
    if max_ticks <= 0:
        raise ScenarioError(path, *_key_pos(lines, "max_ticks"), "a positive integer max_ticks", str(max_ticks))
    description = _get(doc, lines, path, "description", str, "a string description", "")
    layout_text = _get(doc, lines, path, "layout", str, "a layout string (use a \"\"\" multi-line string)")
    layout = _parse_layout(layout_text, lines, path)
    world_table = doc.get("world", {})
    if not isinstance(world_table, dict):
        raise ScenarioError(path, *_key_pos(lines, "world"), "a [world] table")
    try:
        world = WorldConfig.from_mapping(world_table)
    except ValueError as exc:
        head = str(exc).split("; known:")[0]
        bad = next((k for k in world_table if re.search(rf"\b{re.escape(k)}\b", head)), "world")
        raise ScenarioError(path, *_key_pos(lines, bad), "valid [world] settings", str(exc)) from None
    scenario = Scenario(name=name, seed=seed, agents=agents, tick_mode=tick_mode, max_ticks=max_ticks,
                        layout=layout, world=world, description=description, path=path)
    free = len(scenario.cells_col_row(".A"))
    if agents > free:
        raise ScenarioError(path, *_key_pos(lines, "agents"),
                            f"at most {free} agents (empty cells and A starts in the layout)", str(agents))
    return scenario


def _get(doc, lines, path, key, kind, expected, default=None):
    if key not in doc:
        if default is not None:
            return default
        raise ScenarioError(path, 1, 1, f"a top-level key {key!r}: {expected}", "nothing")
    value = doc[key]
    if not isinstance(value, kind) or (kind is int and isinstance(value, bool)):
        raise ScenarioError(path, *_key_pos(lines, key), expected, repr(value))
    return value


def _key_pos(lines: list[str], key: str) -> tuple[int, int]:
    """1-based (line, column) of `key = ...` (or a `[key]` table header) in the file."""
    pattern = re.compile(rf"^(\s*)(?:{re.escape(key)}\s*=|\[{re.escape(key)}\])")
    for i, line in enumerate(lines):
        m = pattern.match(line)
        if m:
            return i + 1, len(m.group(1)) + 1
    return 1, 1


def _layout_first_line(lines: list[str]) -> int:
    """0-based file line holding layout row 0's raw text (before blank-line trimming)."""
    line, _ = _key_pos(lines, "layout")
    opening = lines[line - 1]
    m = re.search(r'=\s*("""|\'\'\')(.*)$', opening)
    # TOML drops a newline right after the opening quotes, so the text starts on the next line.
    return line if (m and not m.group(2).strip()) else line - 1


def _parse_layout(text: str, lines: list[str], path: str) -> tuple[str, ...]:
    start = _layout_first_line(lines)
    raw = text.split("\n")
    lead = 0
    while lead < len(raw) and not raw[lead].strip():
        lead += 1
    body = [r.rstrip() for r in raw[lead:]]
    while body and not body[-1]:
        body.pop()
    if not body:
        raise ScenarioError(path, start + 1, 1, "a non-empty layout")
    dedented = textwrap.dedent("\n".join(body)).split("\n")
    for i, row in enumerate(dedented):
        indent = len(body[i]) - len(row)  # the common indentation dedent removed
        file_line = start + lead + i + 1
        if not row:
            raise ScenarioError(path, file_line, 1, "a layout row (no blank lines inside the layout)")
        for j, ch in enumerate(row):
            if ch not in LAYOUT_CHARS:
                raise ScenarioError(path, file_line, indent + j + 1,
                                    "one of " + " ".join(f"'{c}' ({d})" for c, d in LAYOUT_CHARS.items()),
                                    repr(ch))
        if len(row) != len(dedented[0]):
            raise ScenarioError(path, file_line, indent + min(len(row), len(dedented[0])) + 1,
                                f"a row of {len(dedented[0])} cells like the first", f"{len(row)} cells")
    return tuple(dedented)

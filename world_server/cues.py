"""Cues: marks on the floor that agents put down, take up and sense (issue 37; docs/society.md).

A cue is a mark of one kind (protocol CUE_KINDS: "site", drop a brick here; "supply", take
bricks from around here) on one layout cell, at the cell's centre. It has no body: nothing
collides with it, and it hides nothing from the range sensors. Agents sense cues on a
channel of their own (`SensorFrame.cues`), laid out as the disc channels: per kind and
sector, the distance to the nearest cue's centre within range. A cue under a disc is
covered and not sensed (a brick on a marked site hides the mark, so a filled site stops
drawing workers by itself); a floor sensor tells the kind of the cue under the body's centre
(`SensorFrame.cue_under`).

Pure numpy, no bus. Readings take the sensors' noise law (zero-mean uniform, standard
deviation noise x distance) from a generator keyed by the tick's sensor seed and a stream of
their own, so turning cues on draws nothing from the world's generator: a world without cues
runs exactly as before.
"""

from __future__ import annotations

import numpy as np

from protocol.messages import CUE_KINDS, NO_READING

MAX_CUES = 4096  # cues one world holds at most (a mark beyond is refused)
_CUE_STREAM = 0xC0E5  # the noise stream of cue readings, beside the tick's sensor seed


class CueBoard:
    """The cues lying in a world, by cell: `place`, `remove`, `kind_at` and their arrays."""

    def __init__(self) -> None:
        self._cells: dict[tuple[int, int], int] = {}  # (col, row) -> index into CUE_KINDS
        self._arrays: tuple[np.ndarray, np.ndarray] | None = None

    def __len__(self) -> int:
        return len(self._cells)

    def place(self, cell: tuple[int, int], kind: str) -> bool:
        """Mark `cell` (col, row) with a cue of `kind` (replacing one there); False when full."""
        if cell not in self._cells and len(self._cells) >= MAX_CUES:
            return False
        self._cells[cell] = CUE_KINDS.index(kind)
        self._arrays = None
        return True

    def remove(self, cell: tuple[int, int]) -> bool:
        """Take the cue off `cell`; False if there was none."""
        found = self._cells.pop(cell, None) is not None
        self._arrays = None
        return found

    def kind_at(self, cell: tuple[int, int]) -> str:
        """The kind of the cue on `cell`, "" for none."""
        k = self._cells.get(cell)
        return "" if k is None else CUE_KINDS[k]

    def items(self) -> list[tuple[int, int, int]]:
        """(col, row, kind index) of every cue, sorted (for checkpoints)."""
        return sorted((c, r, k) for (c, r), k in self._cells.items())

    def arrays(self) -> tuple[np.ndarray, np.ndarray]:
        """(cells (n, 2) int64 as (col, row), kinds (n,) int64), in one fixed order."""
        if self._arrays is None:
            items = self.items()
            cells = np.array([(c, r) for c, r, _ in items], np.int64).reshape(-1, 2)
            self._arrays = (cells, np.array([k for _, _, k in items], np.int64))
        return self._arrays


def sense_cues(agent_xy: np.ndarray, sensing: np.ndarray, cue_xy: np.ndarray, cue_kind: np.ndarray,
               sectors: int, radius: float, *, noise: float = 0.0, seed: int = 0) -> np.ndarray:
    """Cue readings, shape (agents, len(CUE_KINDS), sectors): per kind and sector the distance
    to the nearest cue centre within `radius`, else NO_READING; rows of agents whose `sensing`
    is False stay NO_READING. `cue_xy` / `cue_kind` list the uncovered cues only."""
    n = len(agent_xy)
    out = np.full((n, len(CUE_KINDS), sectors), NO_READING)
    if not n or not len(cue_xy):
        return out
    dx = cue_xy[None, :, 0] - agent_xy[:, None, 0]
    dy = cue_xy[None, :, 1] - agent_xy[:, None, 1]
    d = np.hypot(dx, dy)
    sector = (np.floor(np.mod(np.arctan2(dy, dx), 2 * np.pi) * sectors / (2 * np.pi)).astype(np.int64)) % sectors
    a, c = np.nonzero((d <= radius) & sensing[:, None])
    nearest = np.full(out.shape, np.inf)
    np.minimum.at(nearest, (a, cue_kind[c], sector[a, c]), d[a, c])
    out = np.where(np.isfinite(nearest), nearest, NO_READING)
    if noise > 0:
        u = np.random.default_rng([seed, _CUE_STREAM]).uniform(-1.0, 1.0, out.shape)
        hit = out >= 0
        out[hit] = np.clip(out[hit] * (1 + np.sqrt(3.0) * noise * u[hit]), 0.0, radius)
    return out

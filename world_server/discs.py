"""The discs of the world (food, water, bricks) as arrays: positions, kinds, states.

A disc is IN_WORLD (a physical static circle, sensed), CARRIED (under an agent's belly:
no body, invisible) or GONE (removed by a perturbation). Indices never change, so a
brick keeps its identity through grabs, drops and moves.
"""

from __future__ import annotations

import numpy as np

from protocol.messages import DISC_KINDS

FOOD_DISC, WATER_DISC, BRICK_DISC = (DISC_KINDS.index(k) for k in ("food", "water", "brick"))  # `kind` values
IN_WORLD, CARRIED, GONE = 0, 1, 2


class DiscStore:
    """Every disc of the world (food, water, bricks): positions, kinds and states, by index."""

    def __init__(self, xy: np.ndarray, kinds: np.ndarray):
        self.xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2).copy()
        self.kind = np.asarray(kinds, dtype=np.int64).copy()
        self.state = np.full(len(self.kind), IN_WORLD, dtype=np.int64)
        self._present: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._present_kind: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        self._filled: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None  # (present indices, site codes, filled)

    def __len__(self) -> int:
        return len(self.kind)

    # Every change goes through these methods, so the arrays the sensors read each tick
    # are gathered once per change instead of once per tick.
    def add(self, xy: tuple[float, float], kind: int) -> int:
        """A new disc of `kind` at `xy`, in the world; returns its index."""
        self.xy = np.vstack([self.xy, np.asarray(xy, dtype=np.float64).reshape(1, 2)])
        self.kind = np.append(self.kind, kind)
        self.state = np.append(self.state, IN_WORLD)
        self._present = None
        return len(self.kind) - 1

    def carry(self, index: int) -> None:
        """The disc is grabbed: under an agent, out of the world."""
        self.state[index] = CARRIED
        self._present = None

    def place(self, index: int, xy) -> None:
        """The disc is back in the world at `xy` (dropped or moved)."""
        self.xy[index] = xy
        self.state[index] = IN_WORLD
        self._present = None

    def remove(self, index: int) -> None:
        """The disc is gone for good (a perturbation); its index stays taken."""
        self.state[index] = GONE
        self._present = None

    def present(self) -> np.ndarray:
        """Indices of discs physically in the world."""
        return self.present_arrays()[0]

    def present_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(indices, positions, kinds) of the discs physically in the world."""
        if self._present is None:
            idx = np.flatnonzero(self.state == IN_WORLD)
            self._present = (idx, np.ascontiguousarray(self.xy[idx]), self.kind[idx].copy())
            self._present_kind = {}
        return self._present

    def _present_of_kind(self, kind: int) -> tuple[np.ndarray, np.ndarray]:
        idx, xy, kinds = self.present_arrays()
        if kind not in self._present_kind:
            mine = kinds == kind
            self._present_kind[kind] = (idx[mine], xy[mine])
        return self._present_kind[kind]

    def nearest(self, xy, max_dist: float, kind: int | None = None) -> int:
        """Index of the nearest present disc (of `kind`, if given) within `max_dist`, or -1."""
        idx, pxy = self.present_arrays()[:2] if kind is None else self._present_of_kind(kind)
        if idx.size == 0:
            return -1
        d2 = np.square(pxy[:, 0] - xy[0]) + np.square(pxy[:, 1] - xy[1])
        best = int(np.argmin(d2))
        return int(idx[best]) if d2[best] <= max_dist * max_dist else -1

    def nearest_in_front(self, xy, heading: float, max_dist: float, cone: float, kind: int) -> int:
        """Nearest present disc of `kind` within `max_dist` and within `cone` of `heading`, or -1."""
        idx, pxy = self._present_of_kind(kind)
        if idx.size == 0:
            return -1
        dx, dy = pxy[:, 0] - xy[0], pxy[:, 1] - xy[1]
        d2 = np.square(dx) + np.square(dy)
        off = np.abs((np.arctan2(dy, dx) - heading + np.pi) % (2 * np.pi) - np.pi)
        d2 = np.where((off <= cone) | (d2 < 1e-12), d2, np.inf)
        best = int(np.argmin(d2))
        return int(idx[best]) if d2[best] <= max_dist * max_dist else -1

    def bricks_total(self) -> int:
        """Bricks that exist: in the world or carried. Only a perturbation changes this."""
        return int(np.count_nonzero((self.kind == BRICK_DISC) & (self.state != GONE)))

    def filled_sites(self, site_codes: np.ndarray, cell_code) -> np.ndarray:
        """Boolean per site: a present brick lies in the site's cell (read-only).

        `cell_code` maps (n, 2) world positions to the same integer codes as `site_codes`.
        Asked every tick (progress, completion, the view) but changed only by a grab, a
        drop or a perturbation: kept while the discs in the world (`present_arrays`, made
        anew on every change) and the sites' codes are the same objects.
        """
        idx, xy, kinds = self.present_arrays()
        kept = self._filled
        if kept is None or kept[0] is not idx or kept[1] is not site_codes:
            filled = np.isin(site_codes, cell_code(xy[kinds == BRICK_DISC]))
            filled.setflags(write=False)
            self._filled = kept = (idx, site_codes, filled)
        return kept[2]

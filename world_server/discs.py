"""The discs of the world (food, water, bricks) as arrays: positions, kinds, states.

A disc is IN_WORLD (a physical static circle, sensed), CARRIED (under an agent's belly:
no body, invisible) or GONE (removed by a perturbation). Indices never change, so a
brick keeps its identity through grabs, drops and moves.
"""

from __future__ import annotations

import numpy as np

from protocol.messages import DISC_KINDS

FOOD, WATER, BRICK = (DISC_KINDS.index(k) for k in ("food", "water", "brick"))
IN_WORLD, CARRIED, GONE = 0, 1, 2


class DiscStore:
    def __init__(self, xy: np.ndarray, kinds: np.ndarray):
        self.xy = np.asarray(xy, dtype=np.float64).reshape(-1, 2).copy()
        self.kind = np.asarray(kinds, dtype=np.int64).copy()
        self.state = np.full(len(self.kind), IN_WORLD, dtype=np.int64)

    def __len__(self) -> int:
        return len(self.kind)

    def add(self, xy: tuple[float, float], kind: int) -> int:
        self.xy = np.vstack([self.xy, np.asarray(xy, dtype=np.float64).reshape(1, 2)])
        self.kind = np.append(self.kind, kind)
        self.state = np.append(self.state, IN_WORLD)
        return len(self.kind) - 1

    def present(self) -> np.ndarray:
        """Indices of discs physically in the world."""
        return np.flatnonzero(self.state == IN_WORLD)

    def nearest(self, xy: np.ndarray, max_dist: float, kinds: tuple[int, ...] | None = None) -> int:
        """Index of the nearest present disc (of one of `kinds`) within `max_dist`, or -1."""
        mask = self.state == IN_WORLD
        if kinds is not None:
            mask &= np.isin(self.kind, kinds)
        idx = np.flatnonzero(mask)
        if idx.size == 0:
            return -1
        d = np.hypot(*(self.xy[idx] - np.asarray(xy, dtype=np.float64)).T)
        best = int(np.argmin(d))
        return int(idx[best]) if d[best] <= max_dist else -1

    def bricks_total(self) -> int:
        """Bricks that exist: in the world or carried. Only a perturbation changes this."""
        return int(np.count_nonzero((self.kind == BRICK) & (self.state != GONE)))

    def filled_sites(self, site_codes: np.ndarray, cell_code) -> np.ndarray:
        """Boolean per site: a present brick lies in the site's cell.

        `cell_code` maps (n, 2) world positions to the same integer codes as `site_codes`.
        """
        bricks = np.flatnonzero((self.kind == BRICK) & (self.state == IN_WORLD))
        return np.isin(site_codes, cell_code(self.xy[bricks]))

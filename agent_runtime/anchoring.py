"""Anchoring the maps to landmarks whose place the agent knows (issue 37 item 3; docs/noise.md).

The agent holds the blueprint at fixed cells of its odometry frame and believes it stands
where its odometry, summed since attach, says (`far_memory.FarMemory.pos` plus
`esm.EgocentricMaps.frac`). With the odometry wrong, that belief drifts as a random walk,
and the configuration ESM slides off the true sites with it: a brick dropped on a site of
the map lands beside the real one. Nothing in the paper's agent ever corrects it.

Some things the agent sees lie at places it knows exactly, in the very frame the blueprint
is in, so seeing them says where it is:

* a structure brick: a brick dropped in a site's cell settles on the site's centre
  (`world_server.world.World._settled`), so a site the agent believes filled holds a brick
  at a point of the blueprint;
* the world's edge: the obstacle sensors see it as a ring of points on the centres of the
  cells just outside the world, whose extent came with the Welcome.

The compass is exact (paper §3: it aligns every reading to one global direction), so only a
translation is unknown. A sector reports the distance to the nearest object of its colour
but not the angle inside the sector (22.5 degrees: a cell's width at 2.5 cells), so only
the range is used: a reading d matched to a landmark L, seen from the believed position P
in the direction u, says |L - (P + e)| = d for the belief's error e, or, to first order,
u . e = |L - P| - d, one linear equation in e. A Kalman filter over the 2-D error combines
the equations of all readings and ticks; its process noise is the odometry's own error,
which grows with the distance moved. Each tick the brain moves its belief by the estimate
(`Brain`), as if it had walked that far, so the sites come back under the structure.

Which landmark a reading saw: the one known landmark whose bearing lies in its sector,
widened by a margin for the belief's uncertainty, and whose distance lies within a gate of
the reading; none is used when two fit (a straight wall seen end on: the sector cannot
tell which). A reading much nearer than every landmark is something else (a free brick, a
wall inside the world) and says nothing; so is one farther (the landmark may be hidden,
or the site's brick gone).

A whole cell off, the filter cannot tell: along a straight run of structure bricks a
belief a cell off fits the ranges about as well, and matched readings can pull it there a
little at a time. `Relocaliser` weighs the belief against its eight neighbours a cell off
on what each predicts the sectors see: a landmark it puts well inside a sector and in reach
that the sector did not see (nothing there, or nothing as near), and a reading no landmark
it puts there explains. A neighbour that has had clearly fewer such misses for a while
(decayed counts, `AnchorConfig.jump` fewer, and no other neighbour as good) takes over.

Pure numpy, no bus; the brain supplies the readings (cells), the landmarks and how far it
moved.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from protocol.messages import CHANNELS

BRICK_CHANNEL = CHANNELS.index("brick")
OBSTACLE_CHANNEL = CHANNELS.index("obstacle")


@dataclass(frozen=True)
class AnchorConfig:
    """The filter's assumptions (cells); the defaults cover the noise docs/noise.md measures."""

    odometry_noise: float = 0.15    # std of the odometry's error per cell moved (process noise)
    drift_floor: float = 0.002      # std added per tick regardless (bodies pushed while standing)
    range_noise: float = 0.05       # std of a range reading per cell of its distance (sensor noise 2x: 0.04)
    range_floor: float = 0.05       # std of every range reading on top (a brick a little off its centre)
    gate: float = 0.45              # a reading farther than this (cells) from its landmark's distance is
                                    # something else; under half a cell, so a wall one cell in front is not it
    max_step: float = 0.25          # the largest correction per tick along x or y (cells): an outlier
                                    # that slips through moves the maps a little, not a cell
    assumed_std: float = 0.2        # matching assumes the belief is at most about this far off (cells)
    max_std: float = 1.0            # the belief's std (cells) is never taken as larger than this
    relocalise: bool = True         # weigh the belief against the same belief a whole cell off (`Relocaliser`)
    decay: float = 0.97             # per tick: how long a contradiction counts against an offset
    jump: float = 6.0               # move the belief a whole cell when the neighbour has this many fewer
    inside: float = 0.2             # a landmark counts as in a sector only this fraction of its width inside


@dataclass(frozen=True)
class Landmarks:
    """Known points in the agent's odometry frame (cells, x east, y north, from the attach
    cell's centre), per sensor channel that sees them."""

    sites: np.ndarray       # (k, 2): centres of the blueprint's sites
    filled: np.ndarray      # (k,) bool: those believed to hold a brick, the landmarks among them
    edge: np.ndarray        # (m, 2): centres of the cells just outside the world (empty if unknown)


def edge_ring(bounds: tuple[int, int, int, int] | None) -> np.ndarray:
    """(m, 2) centres of the one-cell ring just outside the world's cells x0 <= x < x1,
    y0 <= y < y1 (relative to the attach cell), where the world puts its edge's obstacle
    points; empty when the extent is unknown."""
    if bounds is None:
        return np.zeros((0, 2))
    x0, y0, x1, y1 = bounds
    xs = np.arange(x0 - 1, x1 + 1)
    ys = np.arange(y0, y1)
    ring = [np.column_stack([xs, np.full(len(xs), y0 - 1)]), np.column_stack([xs, np.full(len(xs), y1)]),
            np.column_stack([np.full(len(ys), x0 - 1), ys]), np.column_stack([np.full(len(ys), x1), ys])]
    return np.vstack(ring).astype(np.float64)


class Anchor:
    """The error of the agent's believed position, estimated from landmarks it sees.

    `predict(moved)` grows the uncertainty by the distance moved; `correct(...)` matches
    one frame's readings to the landmarks and returns the correction (cells) to add to the
    believed position, after which the estimate of the remaining error is zero again.
    """

    def __init__(self, cfg: AnchorConfig | None = None):
        self.cfg = cfg or AnchorConfig()
        self.cov = np.zeros((2, 2))      # exact at attach: the Welcome gives the true pose
        self.used = 0                    # readings matched to a landmark so far

    def predict(self, moved: float) -> None:
        """The agent moved `moved` cells by its odometry: the belief is less certain."""
        var = (self.cfg.odometry_noise * moved) ** 2 + self.cfg.drift_floor ** 2
        self.cov += var * np.eye(2)
        cap = self.cfg.max_std ** 2
        if np.trace(self.cov) > 2 * cap:
            self.cov *= 2 * cap / np.trace(self.cov)

    def equations(self, ranges: np.ndarray, position: np.ndarray,
                  landmarks: Landmarks) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(u, residual, variance): one row per reading matched to a landmark, u the unit
        vector to it from `position`, residual its distance from there minus the reading.
        `ranges`: (channels, sectors) in cells, negative for none."""
        rows: list[tuple[np.ndarray, np.ndarray]] = []
        sectors = ranges.shape[1]
        edge = np.asarray(landmarks.edge, np.float64).reshape(-1, 2)
        for channel, points, known in ((BRICK_CHANNEL, landmarks.sites, landmarks.filled),
                                       (OBSTACLE_CHANNEL, edge, np.ones(len(edge), bool))):
            if np.any(known):
                rel = np.asarray(points, np.float64).reshape(-1, 2) - position
                rows.append(self._match(ranges[channel], rel, np.asarray(known, bool), sectors))
        if not rows:
            return np.zeros((0, 2)), np.zeros(0), np.zeros(0)
        u = np.vstack([r[0] for r in rows])
        dist = np.concatenate([r[1][:, 0] for r in rows])
        read = np.concatenate([r[1][:, 1] for r in rows])
        var = (self.cfg.range_noise * read) ** 2 + self.cfg.range_floor ** 2
        return u, dist - read, var

    def _match(self, readings: np.ndarray, rel: np.ndarray, known: np.ndarray,
               sectors: int) -> tuple[np.ndarray, np.ndarray]:
        """(u, [distance, reading]) of the readings of one channel that saw one landmark of
        `rel` (offsets from the believed position) unambiguously. Only the `known` points
        are landmarks, but every point may be what a reading saw: a reading that fits an
        open site as well as a filled one is left out (the agent may have taken a brick
        on one site for a brick on its neighbour, and would lock on a cell off)."""
        dist = np.hypot(rel[:, 0], rel[:, 1])
        near = dist > 0.5       # a landmark under the agent's own body is no help
        rel, dist, known = rel[near], dist[near], known[near]
        width = 2 * math.pi / sectors
        bearing = np.mod(np.arctan2(rel[:, 1], rel[:, 0]), 2 * math.pi)
        # How far the bearing may be off, as the belief may be off: its std, twice, and a
        # tenth of a cell for the points themselves. Capped: a belief that has gone long
        # without a landmark would otherwise allow no sector at all to be sure of one, and
        # never be anchored again; the gate still refuses a reading far from its landmark.
        std = min(math.sqrt(max(float(np.linalg.eigvalsh(self.cov)[-1]), 0.0)), self.cfg.assumed_std)
        margin = np.arcsin(np.minimum((2 * std + 0.1) / np.maximum(dist, 1e-9), 1.0))
        us, pairs = [], []
        for s in np.flatnonzero(readings >= 0):
            lo = s * width
            off = np.mod(bearing - lo + math.pi, 2 * math.pi) - math.pi   # from the sector's first edge
            d = float(readings[s])
            fits = np.flatnonzero((off > -margin) & (off < width + margin) & (np.abs(dist - d) < self.cfg.gate))
            if len(fits) != 1 or not known[fits[0]]:
                continue      # none, two the reading cannot tell apart, or not a landmark
            j = fits[0]
            us.append(rel[j] / dist[j])
            pairs.append((dist[j], d))
        if not us:
            return np.zeros((0, 2)), np.zeros((0, 2))
        return np.asarray(us), np.asarray(pairs)

    def correct(self, ranges: np.ndarray, position: np.ndarray, landmarks: Landmarks) -> np.ndarray:
        """The correction (dx, dy) in cells to add to the believed `position` (cells, the
        frame of `landmarks`), from one frame's `ranges` (channels, sectors) in cells."""
        u, residual, var = self.equations(ranges, position, landmarks)
        if not len(u):
            return np.zeros(2)
        # The Kalman update of the error (mean zero before it) with all of them at once.
        s = u @ self.cov @ u.T + np.diag(var)
        gain = self.cov @ u.T @ np.linalg.solve(s, np.eye(len(u)))
        step = gain @ residual
        self.cov = (np.eye(2) - gain @ u) @ self.cov
        self.cov = (self.cov + self.cov.T) / 2      # symmetric, against rounding
        self.used += len(u)
        # The belief moves by at most max_step: what is not applied stays as uncertainty.
        applied = np.clip(step, -self.cfg.max_step, self.cfg.max_step)
        left = step - applied
        self.cov += np.diag(left ** 2)
        return applied


OFFSETS = np.array([(dx, dy) for dx in (-1, 0, 1) for dy in (-1, 0, 1)], np.float64)   # (0, 0) is index 4
HERE = 4


class Relocaliser:
    """The belief against the same belief a whole cell off (see the module).

    Each tick, for the belief moved by each of OFFSETS, it counts the sectors of the frame
    that speak against it (`contradictions`), and keeps the counts with a decay. A reading
    of something nobody knows of (a free brick, a wall inside the world) counts against
    every offset alike and so moves none. When one neighbour alone has had `jump` fewer than
    the belief, the belief moves to it (`update`): two neighbours alike, as along a wall seen
    from its middle, say nothing.
    """

    def __init__(self, cfg: AnchorConfig, sectors: int, reach: float, occluding: bool):
        self.cfg, self.sectors, self.reach, self.occluding = cfg, sectors, reach, occluding
        self.counts = np.zeros(len(OFFSETS))
        self.jumps = 0

    def _slack(self, dist):
        """How much farther than a landmark a reading may lie and still be of it (cells): the
        matching gate, widened by the sensor's noise, which grows with the distance."""
        return self.cfg.gate + 0.1 * dist

    def contradictions(self, ranges: np.ndarray, position: np.ndarray, landmarks: Landmarks) -> np.ndarray:
        """(9,): for the belief moved by each of OFFSETS, the sectors of this frame that speak
        against it: a landmark (a believed-filled site on the brick channel, the world's edge on
        the obstacle channel) well inside a sector and in reach that the sector did not see as
        near (unless, with occlusion, something of any colour stood before it), and a reading
        that no landmark in or beside its sector explains. `ranges`: (channels, sectors) in
        cells, negative for none."""
        out = np.zeros(len(OFFSETS))
        width = 2 * math.pi / self.sectors
        seen = np.where(ranges >= 0, ranges, np.inf)
        nearest = seen.min(axis=0)            # the nearest thing of any colour, per sector
        edge = np.asarray(landmarks.edge, np.float64).reshape(-1, 2)
        sites = np.asarray(landmarks.sites, np.float64).reshape(-1, 2)[np.asarray(landmarks.filled, bool)]
        for channel, points in ((BRICK_CHANNEL, sites), (OBSTACLE_CHANNEL, edge)):
            if not len(points):
                continue
            rel = points[None, :, :] - (position[None, None, :] + OFFSETS[:, None, :])     # (9, k, 2)
            dist = np.hypot(rel[..., 0], rel[..., 1])
            turn = np.mod(np.arctan2(rel[..., 1], rel[..., 0]), 2 * math.pi) / width
            sector = np.minimum(turn.astype(np.int64), self.sectors - 1)
            frac = turn - sector
            # Sure to be in its sector and in reach: away from the sector's edges, not under the body.
            inside = (frac > self.cfg.inside) & (frac < 1 - self.cfg.inside)
            sure = inside & (dist > 0.5) & (dist + self._slack(dist) < self.reach)
            expect = np.full((len(OFFSETS), self.sectors), np.inf)
            o, k = np.nonzero(sure)
            np.minimum.at(expect, (o, sector[o, k]), dist[o, k])
            limit = expect + self._slack(expect)
            missed = np.isfinite(expect) & (seen[channel][None, :] > limit)
            if self.occluding:      # the sector stopped at something nearer, of any colour
                missed &= ~(nearest[None, :] < limit)
            out += np.count_nonzero(missed, axis=1)
            # A reading no landmark of the belief can have given (one in the sector, or near
            # its edges, at that distance) counts too: a free brick or an inner wall counts
            # against every offset alike, the structure seen a cell off against one.
            near = dist > 0.5
            fits = np.zeros((len(OFFSETS), self.sectors), bool)
            sides = ((0, near), (-1, near & (frac < self.cfg.inside)), (1, near & (frac > 1 - self.cfg.inside)))
            for side, could in sides:      # its own sector, and the next one when near that edge
                where = (sector + side) % self.sectors
                o, k = np.nonzero(could & (np.abs(seen[channel][where] - dist) < self._slack(dist)))
                fits[o, where[o, k]] = True
            out += np.count_nonzero(np.isfinite(seen[channel])[None, :] & ~fits, axis=1)
        return out

    def update(self, ranges: np.ndarray, position: np.ndarray, landmarks: Landmarks) -> np.ndarray:
        """Count this frame; returns the whole-cell move (dx, dy) of the belief, or zeros."""
        self.counts = self.counts * self.cfg.decay + self.contradictions(ranges, position, landmarks)
        order = np.argsort(self.counts, kind="stable")
        best, low, second = int(order[0]), float(self.counts[order[0]]), float(self.counts[order[1]])
        # Only to one neighbour that is clearly best: two alike (along a wall) say nothing.
        if best != HERE and self.counts[HERE] - low >= self.cfg.jump and second - low >= 1.0:
            self.counts[:] = 0.0
            self.jumps += 1
            return OFFSETS[best].copy()
        return np.zeros(2)

"""Per-colour sector range sensors (paper §3; W2), for every agent in one call.

Each agent has, per channel (food, water, brick, agent), `sectors` sensors covering
360°: sector k sees compass angles [k, k+1) * 2*pi/sectors counter-clockwise from east
(the compass aligns all readings to one global direction). A sector reports the
distance to the nearest object of its colour within range, or NO_READING; it cannot
tell two discs apart nor the angle inside the sector. Zero-mean noise with a standard
deviation proportional to the distance is added to every reading that saw something,
so near objects are sensed more accurately (the paper asks only that the mean error
grow with distance; a uniform error of +-sqrt(3) x noise x d has exactly that spread).

Two options make the readings less faithful (docs/noise.md; both off by default, and
then they cost nothing): occlusion, where a sector reports only the nearest object of
any channel, as one range sensor would (a brick behind a food disc is not seen), and
perceptual aliasing, where a sector of a disc colour that holds two discs of it reports
the second nearest instead of the nearest with a given probability.

The sweep is compiled: objects are bucketed on a uniform grid, so each agent only looks
at nearby ones, O(objects + agents x neighbours). The noise comes from a counter-based
generator (splitmix64) keyed by one seed per tick, which the caller draws from its
injected numpy Generator: the same seed gives the same readings, with no global state.
Many agents are swept on all cores; rows of different agents never overlap.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from protocol.messages import CHANNELS, DISC_KINDS, NO_READING

AGENT_CHANNEL = CHANNELS.index("agent")
# Channels 0 .. DISC_CHANNELS - 1 are the discs' (food, water, brick: a disc's kind is its channel).
DISC_CHANNELS = len(DISC_KINDS)
assert CHANNELS[:DISC_CHANNELS] == DISC_KINDS


@njit(cache=True)
def _bucket(xy, cell, nx, ny):
    """Counting sort of points into grid buckets: (starts[nx*ny+1], order[n])."""
    n = xy.shape[0]
    key = np.empty(n, np.int64)
    counts = np.zeros(nx * ny + 1, np.int64)
    for i in range(n):
        cx = min(max(int(xy[i, 0] / cell), 0), nx - 1)
        cy = min(max(int(xy[i, 1] / cell), 0), ny - 1)
        key[i] = cx * ny + cy
        counts[key[i] + 1] += 1
    for b in range(nx * ny):
        counts[b + 1] += counts[b]
    fill = np.empty(nx * ny, np.int64)
    for b in range(nx * ny):
        fill[b] = counts[b]
    order = np.empty(n, np.int64)
    for i in range(n):
        order[fill[key[i]]] = i
        fill[key[i]] += 1
    return counts, order


@njit(cache=True, inline="always")
def _compass_angle(dx, dy):
    """atan2(dy, dx) in [0, 2*pi) to within 3e-4 rad, several times cheaper than libm's.

    The sweep calls this for every object in range of every agent; at 1,000 agents the
    library atan2 alone took most of a tick. 3e-4 rad only matters for a disc lying on a
    sector border, where either sector is a correct reading.
    """
    ax = abs(dx)
    ay = abs(dy)
    hi = max(ax, ay)
    if hi == 0.0:
        return 0.0
    t = min(ax, ay) / hi
    t2 = t * t
    r = ((-0.0464964749 * t2 + 0.15931422) * t2 - 0.327622764) * t2 * t + t
    if ay > ax:
        r = 0.5 * np.pi - r
    if dx < 0.0:
        r = np.pi - r
    if dy < 0.0:
        r = 2.0 * np.pi - r
    return r


@njit(cache=True, inline="always")
def _unit_random(seed, counter):
    """A uniform number in [0, 1) from (seed, counter): splitmix64's finaliser."""
    z = np.uint64(seed) + np.uint64(counter + 1) * np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    z = z ^ (z >> np.uint64(31))
    return np.float64(z >> np.uint64(11)) * (1.0 / 9007199254740992.0)


@njit(cache=True)
def _index(agent_xy, disc_xy, disc_channel, radius, width, height, agent_channel):
    """Discs then agents, bucketed: (cell, nx, ny, starts, xs, ys, channels, object ids).

    `agent_channel` is an argument, not the module constant: numba's on-disk cache would
    keep a global's old value after CHANNELS changed in another module.
    Buckets are half the sensing radius wide: an agent scans at most 5 x 5 of them,
    about 30% less area than 3 x 3 buckets of the full radius.
    """
    cell = radius / 2.0
    nx = max(int(width / cell) + 1, 1)
    ny = max(int(height / cell) + 1, 1)
    n_discs = disc_xy.shape[0]
    m = n_discs + agent_xy.shape[0]
    # Loops, not slice assignments: numba compiles those to a great deal of code (this
    # function took 3.4 s to compile with them, 0.4 s without), and every fresh checkout,
    # test worker and world pays for it before its first tick.
    obj_xy = np.empty((m, 2))
    for i in range(n_discs):
        obj_xy[i, 0] = disc_xy[i, 0]
        obj_xy[i, 1] = disc_xy[i, 1]
    for i in range(agent_xy.shape[0]):
        obj_xy[n_discs + i, 0] = agent_xy[i, 0]
        obj_xy[n_discs + i, 1] = agent_xy[i, 1]
    starts, order = _bucket(obj_xy, cell, nx, ny)
    # Gathered in bucket order, so each bucket is a contiguous run in memory.
    sx = np.empty(m)
    sy = np.empty(m)
    sch = np.empty(m, np.int64)
    for k in range(m):
        j = order[k]
        sx[k] = obj_xy[j, 0]
        sy[k] = obj_xy[j, 1]
        sch[k] = disc_channel[j] if j < n_discs else agent_channel
    return cell, nx, ny, starts, sx, sy, sch, order


@njit(cache=True)
def _buckets_around(ax, ay, radius, cell, nx, ny):
    """The grid's bucket columns x0..x1 and rows y0..y1 that a disc of `radius` round (ax, ay) touches."""
    x0 = min(max(int((ax - radius) / cell), 0), nx - 1)
    x1 = min(max(int((ax + radius) / cell), 0), nx - 1)
    y0 = min(max(int((ay - radius) / cell), 0), ny - 1)
    y1 = min(max(int((ay + radius) / cell), 0), ny - 1)
    return x0, x1, y0, y1


@njit(cache=True)
def _scan(a, agent_xy, n_discs, grid, radius, sectors, noise, seed, out):
    """One agent's readings into out[a]: nearest per (channel, sector), then the noise."""
    cell, nx, ny, starts, sx, sy, sch, sid = grid
    ax, ay = agent_xy[a, 0], agent_xy[a, 1]
    x0, x1, y0, y1 = _buckets_around(ax, ay, radius, cell, nx, ny)
    me = n_discs + a
    r2 = radius * radius
    scale = sectors / (2.0 * np.pi)
    for bx in range(x0, x1 + 1):
        for by in range(y0, y1 + 1):
            b = bx * ny + by
            for k in range(starts[b], starts[b + 1]):
                dx = sx[k] - ax
                dy = sy[k] - ay
                d2 = dx * dx + dy * dy
                if d2 > r2 or sid[k] == me:  # an agent does not sense its own body
                    continue
                s = int(_compass_angle(dx, dy) * scale) % sectors
                d = np.sqrt(d2)
                ch = sch[k]
                cur = out[a, ch, s]
                if cur < 0.0 or d < cur:
                    out[a, ch, s] = d
    if noise > 0.0:
        _add_noise(a, radius, sectors, noise, seed, out)


@njit(cache=True)
def _add_noise(a, radius, sectors, noise, seed, out):
    """Zero-mean uniform noise of std noise x d on every reading of agent a that saw something."""
    spread = np.sqrt(3.0) * noise
    channels = out.shape[1]
    for ch in range(channels):
        for s in range(sectors):
            d = out[a, ch, s]
            if d >= 0.0:
                u = 2.0 * _unit_random(seed, (a * channels + ch) * sectors + s) - 1.0
                out[a, ch, s] = min(max(d + spread * u * d, 0.0), radius)


@njit(cache=True)
def _scan_degraded(a, agent_xy, n_discs, grid, radius, sectors, noise, seed, out, occlusion, aliasing,
                   alias_seed, disc_channels):
    """`_scan` with occlusion and aliasing between the nearest readings and the noise."""
    _scan(a, agent_xy, n_discs, grid, radius, sectors, 0.0, seed, out)
    _occlude_and_alias(a, agent_xy, grid, radius, sectors, out, occlusion, aliasing, alias_seed, disc_channels,
                       n_discs + a)
    if noise > 0.0:
        _add_noise(a, radius, sectors, noise, seed, out)


@njit(cache=True)
def _occlude_and_alias(a, agent_xy, grid, radius, sectors, out, occlusion, aliasing, alias_seed,
                       disc_channels, me):
    """Occlusion and perceptual aliasing on agent a's noise-free nearest readings out[a].

    Aliasing: a sector of a disc channel that holds a second disc of that colour reports
    it instead of the nearest with probability `aliasing` (one draw per reading, keyed
    by `alias_seed`). Occlusion: a sector reports only the nearest object of any channel
    (a range sensor's first return); the other channels read nothing there. With both, a
    second disc hidden behind an object of another channel cannot be reported.
    """
    channels = out.shape[1]
    second = np.full((channels, sectors), NO_READING)
    if aliasing > 0.0:
        # The second nearest object per (channel, sector): one more pass over the neighbours.
        cell, nx, ny, starts, sx, sy, sch, sid = grid
        ax, ay = agent_xy[a, 0], agent_xy[a, 1]
        x0, x1, y0, y1 = _buckets_around(ax, ay, radius, cell, nx, ny)
        r2 = radius * radius
        scale = sectors / (2.0 * np.pi)
        for bx in range(x0, x1 + 1):
            for by in range(y0, y1 + 1):
                b = bx * ny + by
                for k in range(starts[b], starts[b + 1]):
                    ch = sch[k]
                    if ch >= disc_channels:
                        continue
                    dx = sx[k] - ax
                    dy = sy[k] - ay
                    d2 = dx * dx + dy * dy
                    if d2 > r2 or sid[k] == me:
                        continue
                    s = int(_compass_angle(dx, dy) * scale) % sectors
                    d = np.sqrt(d2)
                    cur = second[ch, s]
                    if d > out[a, ch, s] and (cur < 0.0 or d < cur):
                        second[ch, s] = d
    for s in range(sectors):
        first = -1.0    # the nearest reading of any channel in this sector
        behind = -1.0   # the nearest of the other channels' readings (what hides a second disc)
        if occlusion:
            for ch in range(channels):
                d = out[a, ch, s]
                if d >= 0.0:
                    if first < 0.0 or d < first:
                        behind = first
                        first = d
                    elif behind < 0.0 or d < behind:
                        behind = d
        for ch in range(channels):
            d = out[a, ch, s]
            if d < 0.0:
                continue
            if occlusion and d > first:
                out[a, ch, s] = NO_READING
                continue
            alt = second[ch, s]
            hidden = occlusion and behind >= 0.0 and alt > behind
            if alt >= 0.0 and not hidden and _unit_random(alias_seed, (a * channels + ch) * sectors + s) < aliasing:
                out[a, ch, s] = alt


# Four sweeps, chosen in Python: plain or with occlusion and aliasing, serial or shared
# among the cores. One kernel holding both paths compiled both (8 s of a fresh checkout's
# first tick); split, a run compiles only the one it uses.
@njit(cache=True)
def _sweep(agent_xy, disc_xy, disc_channel, sensing, sectors, radius, width, height, noise, seed, out,
           agent_channel):
    grid = _index(agent_xy, disc_xy, disc_channel, radius, width, height, agent_channel)
    for a in range(agent_xy.shape[0]):
        if sensing[a]:
            _scan(a, agent_xy, disc_xy.shape[0], grid, radius, sectors, noise, seed, out)


@njit(cache=True, parallel=True)
def _sweep_parallel(agent_xy, disc_xy, disc_channel, sensing, sectors, radius, width, height, noise, seed, out,
                    agent_channel):
    """`_sweep` with the agents shared among the cores (rows of different agents never overlap)."""
    grid = _index(agent_xy, disc_xy, disc_channel, radius, width, height, agent_channel)
    for a in prange(agent_xy.shape[0]):
        if sensing[a]:
            _scan(a, agent_xy, disc_xy.shape[0], grid, radius, sectors, noise, seed, out)


@njit(cache=True)
def _sweep_degraded(agent_xy, disc_xy, disc_channel, sensing, sectors, radius, width, height, noise, seed, out,
                    agent_channel, occlusion, aliasing, alias_seed, disc_channels):
    """`_sweep` with occlusion and aliasing (`_scan_degraded`)."""
    grid = _index(agent_xy, disc_xy, disc_channel, radius, width, height, agent_channel)
    for a in range(agent_xy.shape[0]):
        if sensing[a]:
            _scan_degraded(a, agent_xy, disc_xy.shape[0], grid, radius, sectors, noise, seed, out, occlusion,
                           aliasing, alias_seed, disc_channels)


@njit(cache=True, parallel=True)
def _sweep_degraded_parallel(agent_xy, disc_xy, disc_channel, sensing, sectors, radius, width, height, noise, seed,
                             out, agent_channel, occlusion, aliasing, alias_seed, disc_channels):
    """`_sweep_degraded` with the agents shared among the cores."""
    grid = _index(agent_xy, disc_xy, disc_channel, radius, width, height, agent_channel)
    for a in prange(agent_xy.shape[0]):
        if sensing[a]:
            _scan_degraded(a, agent_xy, disc_xy.shape[0], grid, radius, sectors, noise, seed, out, occlusion,
                           aliasing, alias_seed, disc_channels)


# Below this many agents, starting threads costs more than it saves.
PARALLEL_FROM = 128


def sense(agent_xy: np.ndarray, sensing: np.ndarray, disc_xy: np.ndarray, disc_channel: np.ndarray,
          sectors: int, radius: float, size: tuple[float, float], *, noise: float = 0.0,
          seed: int = 0, occlusion: bool = False, aliasing: float = 0.0, alias_seed: int = 0) -> np.ndarray:
    """Sector ranges, shape (agents, len(CHANNELS), sectors); noise-free unless `noise` > 0.

    `disc_xy`/`disc_channel` list only discs present in the world (carried bricks are
    invisible, so the caller leaves them out). Agents sense each other on AGENT_CHANNEL.
    Rows of agents whose `sensing` is False stay NO_READING. `seed` keys the noise.
    With `occlusion` a sector reports only the nearest object of any channel; with
    `aliasing` > 0 a disc channel's sector holding two discs reports the second nearest
    with that probability (`alias_seed` keys the draws). Both off cost nothing.
    """
    n = agent_xy.shape[0]
    out = np.full((n, len(CHANNELS), sectors), NO_READING)
    if n:
        args = (np.ascontiguousarray(agent_xy, np.float64), np.ascontiguousarray(disc_xy, np.float64).reshape(-1, 2),
                np.asarray(disc_channel, np.int64), np.asarray(sensing, np.bool_), sectors,
                float(radius), float(size[0]), float(size[1]), float(noise), int(seed), out, AGENT_CHANNEL)
        parallel = n >= PARALLEL_FROM
        if occlusion or aliasing > 0.0:
            kernel = _sweep_degraded_parallel if parallel else _sweep_degraded
            kernel(*args, bool(occlusion), float(aliasing), int(alias_seed), DISC_CHANNELS)
        else:
            (_sweep_parallel if parallel else _sweep)(*args)
    return out


def warm_up() -> None:
    """Load the one-agent sweep from numba's cache (compiling it on a first run) now, not at
    the first attach: that takes a second or more on a busy machine, long enough for the
    agent to time out and send its Hello again (answered twice, a duplicate Welcome)."""
    sense(np.zeros((1, 2)), np.ones(1, np.bool_), np.ones((1, 2)), np.zeros(1, np.int64), 4, 2.0, (4.0, 4.0),
          noise=0.1, seed=1)

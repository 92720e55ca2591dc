"""Distance fields remembered by their exact inputs: a field is computed again only when
its goals, seeds or obstacles changed.

Most ticks an agent moves a fraction of a cell and its maps do not change, so most of the
navigation maps it asks for are the ones it asked for a tick before (41-89% of calls,
by call site, on the generated layouts of `bench.bench_agent_step`). A distance field is
a pure function of its inputs, so a field looked up by the packed bytes of those inputs
is the field the kernel would compute again, bit for bit: the cache changes no decision.
(The key is the raw bytes: packing bits would take longer than comparing them.) The
dictionary files each key under a compiled 64-bit digest (`_digest`) and compares the
key whole on a find: Python's own hash of tens of kilobytes costs more than most fields.
A caller may also name the `slot` it asks from (the configuration NM, the brick NM, ...):
the slot's last key is compared first, which spares even the digest on the most common
hit, the same inputs as a tick before; and when the inputs are the very arrays the slot
was last asked with, and read-only (nothing can have changed them), not even the key is
made. A plain field the slot has not seen is repaired from the slot's last one when few
cells changed (`field_repair`: another agent's move changes two), bit for bit the field
the kernel would compute.

Fields handed out are read-only: one array may be returned to several callers. A field
with no goal is all inf and needs no kernel (the kernel's answer too).

Numpy and one numba kernel here (the digest); one cache per agent (a few dozen fields: the hits
are on recent inputs), so agents hosted in one process never share or contend for it.
"""

from __future__ import annotations

from collections import OrderedDict

import numpy as np
from numba import njit

from agent_runtime.field_repair import repair_from_bytes
from agent_runtime.spreading import FieldWork, distance_field, seeded_distance_field

DEFAULT_CAPACITY = 32  # fields kept; 32 x 41 x 41 float64 is 430 KB, at 121 x 121 3.7 MB


class FieldCache:
    """`distance` and `seeded` as in `spreading`, each computed once per distinct input."""

    def __init__(self, capacity: int = DEFAULT_CAPACITY):
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1, got {capacity}")
        self.capacity = capacity
        self._fields: OrderedDict[int, tuple[bytes, np.ndarray]] = OrderedDict()  # digest -> (key, field)
        self._nowhere: dict[tuple[int, ...], np.ndarray] = {}  # the all-inf field per shape
        # slot -> (its last key, field, the goals and obstacles it was asked with, and `_at` then)
        self._slots: dict[str, tuple[bytes, np.ndarray, np.ndarray, np.ndarray, tuple[int, int]]] = {}
        self._work: FieldWork | None = None   # the kernels' buffers, for the last shape asked
        self._at = (0, 0)   # how far the maps' contents moved in all (`moved`), in rows and columns
        self.hits = 0
        self.misses = 0      # of which `repairs` were repaired from the slot's last field
        self.repairs = 0

    def distance(self, goals: np.ndarray, obstacles: np.ndarray, slot: str | None = None) -> np.ndarray:
        """`spreading.distance_field(goals, obstacles)`, read-only; `slot`: see the module."""
        if slot is not None:
            last = self._slots.get(slot)
            if last is not None and last[2] is goals and last[3] is obstacles and _frozen(goals) and _frozen(obstacles):
                self.hits += 1
                return last[1]
        asked = (goals, obstacles)
        goals = np.ascontiguousarray(goals, dtype=np.bool_)
        obstacles = np.ascontiguousarray(obstacles, dtype=np.bool_)
        if goals.shape != obstacles.shape:  # let the kernel's own check say what is wrong
            return distance_field(goals, obstacles)
        if not np.count_nonzero(goals):
            return self.no_way(goals.shape)
        key = b"".join((_prefix(b"d", goals.shape), goals.tobytes(), obstacles.tobytes()))
        return self._lookup(key, lambda: distance_field(goals, obstacles, self._work_for(goals.shape)), slot, asked,
                            lambda before, field, moved: _repaired(before, field, key, moved))

    def seeded(self, seed: np.ndarray, obstacles: np.ndarray, slot: str | None = None) -> np.ndarray:
        """`spreading.seeded_distance_field(seed, obstacles)`, read-only; `slot`: see the module."""
        seed = np.ascontiguousarray(seed, dtype=np.float64)
        obstacles = np.ascontiguousarray(obstacles, dtype=np.bool_)
        if seed.shape != obstacles.shape:
            return seeded_distance_field(seed, obstacles)
        key = b"".join((_prefix(b"s", seed.shape), seed.tobytes(), obstacles.tobytes()))
        return self._lookup(key, lambda: seeded_distance_field(seed, obstacles, self._work_for(seed.shape)), slot,
                            (_NOT_ASKED, _NOT_ASKED))

    def _lookup(self, key: bytes, compute, slot: str | None, asked: tuple[np.ndarray, np.ndarray],
                repair=None) -> np.ndarray:
        """The field of `key`: the slot's last, or a kept one, or `repair(the slot's last
        key, its field, how far the map moved since)` (None: cannot), or `compute()`."""
        last = None
        if slot is not None:
            last = self._slots.get(slot)
            if last is not None and last[0] == key:   # compared, not hashed
                self.hits += 1
                return last[1]
        digest = int(_digest(np.frombuffer(key, np.uint8)))
        kept = self._fields.get(digest)
        if kept is not None and kept[0] == key:
            field = kept[1]
            self._fields.move_to_end(digest)
            self.hits += 1
        else:   # not kept, or another input with the same digest: this one replaces it
            self.misses += 1
            repaired = None
            if repair is not None and last is not None:
                repaired = repair(last[0], last[1], (self._at[0] - last[4][0], self._at[1] - last[4][1]))
            if repaired is None:
                field = compute()
            else:
                field = repaired
                self.repairs += 1
            field.setflags(write=False)
            self._fields[digest] = (key, field)
            self._fields.move_to_end(digest)
            if len(self._fields) > self.capacity:
                self._fields.popitem(last=False)
        if slot is not None:
            self._slots[slot] = (key, field, *asked, self._at)
        return field

    def moved(self, rows: int, cols: int) -> None:
        """The maps' contents moved by (rows, cols) (the agent crossed into another cell):
        a slot's next field may be repaired from its last one moved as far."""
        self._at = (self._at[0] + rows, self._at[1] + cols)

    def _work_for(self, shape: tuple[int, ...]) -> FieldWork | None:
        if len(shape) != 2:
            return None   # the kernel's own check says what is wrong
        if self._work is None or self._work.shape != shape:
            self._work = FieldWork((shape[0], shape[1]))
        return self._work

    def no_way(self, shape: tuple[int, ...]) -> np.ndarray:
        """The field of no goal, all inf (read-only): what `distance` gives for no goal."""
        field = self._nowhere.get(shape)
        if field is None:
            field = self._nowhere[shape] = np.full(shape, np.inf)
            field.setflags(write=False)
        return field


# Stands for the inputs of a seeded field in a slot: never the goals of a `distance` call.
_NOT_ASKED = np.zeros(0, bool)


def _frozen(grid: np.ndarray) -> bool:
    """Whether nothing can change `grid` any more: read-only, and so is what it views."""
    base = grid.base
    return not grid.flags.writeable and (not isinstance(base, np.ndarray) or not base.flags.writeable)


@njit(cache=True)
def _digest(key):
    """A 64-bit digest of the bytes `key` (uint8), for the cache's dictionary: a key found
    under its digest is compared whole, so a collision costs a computation, never a wrong
    field. Python's own hash of a key (a keyed SipHash, each word through a chain of
    rounds) is several microseconds at 81 x 81 and over ten at 121 x 121; this reads it
    8 bytes at a time, each word mixed with its index (`_mix`) and summed, so the loop has
    no chain from word to word and vectorises."""
    n8 = key.size // 8
    words = key[:n8 * 8].view(np.uint64)
    h = np.uint64(key.size)
    for i in range(n8):
        h += _mix(words[i] ^ (np.uint64(i) * np.uint64(0x9E3779B97F4A7C15)))
    for i in range(n8 * 8, key.size):
        h += _mix(np.uint64(key[i]) ^ (np.uint64(i) * np.uint64(0xC2B2AE3D27D4EB4F)))
    return h


@njit(cache=True, inline="always")
def _mix(x):
    """A 64-bit finaliser (SplitMix64's): every input bit moves about half the output bits."""
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


def _prefix(kind: bytes, shape: tuple[int, ...]) -> bytes:
    """A key's head: the kind of field and the shape of its grids."""
    head = _PREFIXES.get((kind, shape))
    if head is None:
        head = _PREFIXES[(kind, shape)] = kind + b"".join(int(n).to_bytes(4, "little") for n in shape)
    return head


_PREFIXES: dict[tuple[bytes, tuple[int, ...]], bytes] = {}


def _repaired(before: bytes, field: np.ndarray, key: bytes, moved: tuple[int, int]) -> np.ndarray | None:
    """The distance field of `key` repaired from `field`, the one of the key `before`, on
    a map that moved by `moved` since (`field_repair`); None when `before` is not a plain
    field of the same shape, the map moved more than a cell, or too much changed. Both
    keys hold the grids themselves: they are read where they lie."""
    if len(before) != len(key) or before[:_HEAD] != key[:_HEAD] or max(abs(moved[0]), abs(moved[1])) > 1:
        return None
    return repair_from_bytes(field, np.frombuffer(before, np.uint8), np.frombuffer(key, np.uint8), _HEAD, moved)


_HEAD = 9   # the bytes of a 2-D key's `_prefix`

"""World checkpoints: the whole world as one file, written atomically, read back or refused.

A checkpoint holds everything a `World` is made of: the scenario it was built from (so
`conag world --resume FILE` needs nothing else), the tick, the epoch, the random
generator's state, every disc (position, kind, in the world / carried / gone), the drop
sites and blueprint version, every agent record (alive, the brick it holds, counters,
the tick it was seen gone, so a dead body's grace period goes on where it stopped) and
every per-body array, the bodies' positions and velocities included.

pymunk cannot be saved exactly (its contact caches and spatial index are not state one
can copy), so the space is not saved at all: `World.rebuild_physics` makes a fresh space
from the plain state, and `checkpoint_world` rebuilds the running world's space from the
very state it writes. A run that checkpoints at tick C and a run resumed from that file
thus both step on from identical spaces, and give identical frames (tests/test_checkpoint.py).

The file: an 8-byte magic, the format version (uint32), the payload's length (uint64) and
its SHA-256, then the payload (msgpack). `read_checkpoint` refuses a file that is not a
checkpoint, of another format version, truncated or corrupt, with a `CheckpointError`
saying which. `write_checkpoint` writes a temporary file beside the target, fsyncs it,
reads it back and checks it, keeps the checkpoint it replaces as FILE.prev (a second name
for it, FILE staying in place), renames the new one over FILE and fsyncs the directory: a
crash at any moment leaves a good checkpoint at FILE, and a bad write never replaces it.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import shutil
import struct
from dataclasses import dataclass
from pathlib import Path

import msgpack
import numpy as np

from protocol.messages import CUE_KINDS
from world_server.config import WorldConfig
from world_server.scenario import Scenario
from world_server.world import AgentRecord, World

MAGIC = b"CONAGCKP"
FORMAT_VERSION = 1
DEFAULT_EVERY = 100  # ticks between checkpoints (`conag world --checkpoint-every`)
_HEADER = struct.Struct("<8sIQ32s")  # magic, format version, payload length, SHA-256 of the payload
_ARRAYS = ("heading", "speed", "turn", "action", "alive", "solid", "odometry", "distance", "flags")
_RECORD_FIELDS = tuple(f.name for f in dataclasses.fields(AgentRecord))


class CheckpointError(ValueError):
    """A checkpoint file cannot be used: not one, another format version, truncated, corrupt."""


# plain state ----------------------------------------------------------------------------------
def _pack_array(a: np.ndarray) -> dict:
    a = np.ascontiguousarray(a)
    return {"dtype": a.dtype.str, "shape": list(a.shape), "data": a.tobytes()}


def _unpack_array(d: dict) -> np.ndarray:
    return np.frombuffer(d["data"], dtype=np.dtype(d["dtype"])).reshape(d["shape"]).copy()


def world_state(world: World) -> dict:
    """Everything the world is made of, as plain values (the checkpoint's payload)."""
    pos, vel = world.physics.state()
    scenario = dataclasses.asdict(world.scenario)
    return {
        "scenario": scenario,
        "world_id": world.world_id, "epoch": world.epoch, "tick": world.tick,
        # PCG64's state holds 128-bit integers, which msgpack cannot: JSON text keeps them exact.
        "rng": json.dumps(world.rng.bit_generator.state),
        "blueprint_version": world.blueprint_version, "bad_messages": world.bad_messages,
        "discs": {"xy": _pack_array(world.discs.xy), "kind": _pack_array(world.discs.kind),
                  "state": _pack_array(world.discs.state)},
        "sites_xy": _pack_array(world.sites_xy),
        "agents": [[getattr(rec, name) for name in _RECORD_FIELDS] for rec in world._order],
        "arrays": {name: _pack_array(getattr(world, name)) for name in _ARRAYS},
        "ranges": _pack_array(world._ranges),
        "positions": _pack_array(pos), "velocities": _pack_array(vel),
        "pending_release": sorted([int(b), int(a)] for b, a in world._pending_release.items()),
        "cues": [list(item) for item in world.cues.items()],
    }


def _scenario(d: dict) -> Scenario:
    fields = dict(d)
    fields["world"] = WorldConfig(**fields["world"])
    fields["layout"] = tuple(fields["layout"])
    return Scenario(**fields)


def restore_world(state: dict) -> World:
    """The world a `world_state` describes, its space rebuilt (`World.rebuild_physics`)."""
    try:
        scenario = _scenario(state["scenario"])
        rng_state = json.loads(state["rng"])
        rng = np.random.Generator(getattr(np.random, rng_state["bit_generator"])())
        rng.bit_generator.state = rng_state
        world = World(scenario, rng, world_id=state["world_id"], epoch=state["epoch"])
        _load_into(world, state)
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise CheckpointError(f"the checkpoint's contents do not describe a world: {exc!r}") from exc
    return world


def _load_into(world: World, state: dict) -> None:
    world.tick = int(state["tick"])
    world.blueprint_version = int(state["blueprint_version"])
    world.bad_messages = int(state["bad_messages"])
    discs = state["discs"]
    world.discs.xy, world.discs.kind = _unpack_array(discs["xy"]), _unpack_array(discs["kind"])
    world.discs.state = _unpack_array(discs["state"])
    world.discs._present = None
    world._sense_inputs = None
    world._set_sites(_unpack_array(state["sites_xy"]))
    world.blueprint_version = int(state["blueprint_version"])  # _set_sites counted one more
    world.agents, world._order = {}, []
    for values in state["agents"]:
        rec = AgentRecord(**dict(zip(_RECORD_FIELDS, values)))
        world.agents[rec.agent_id] = rec
        world._order.append(rec)
    for name in _ARRAYS:
        setattr(world, name, _unpack_array(state["arrays"][name]))
    world._ranges = _unpack_array(state["ranges"])
    world._pending_release = {int(b): int(a) for b, a in state["pending_release"]}
    for col, row, kind in state.get("cues", []):  # (checkpoints from before cues hold none)
        world.cues.place((int(col), int(row)), CUE_KINDS[int(kind)])
    world.rebuild_physics(_unpack_array(state["positions"]), _unpack_array(state["velocities"]))


def checkpoint_world(world: World, every: int | None = None) -> bytes:
    """The world's checkpoint file contents; the world's space is rebuilt from that very
    state, so this run and any run resumed from the file step on alike (see the module).
    `every`: the interval the world checkpoints at, kept for a resumed world to go on with."""
    state = world_state(world)
    state["checkpoint_every"] = every
    data = encode_checkpoint(state)
    world.rebuild_physics(_unpack_array(state["positions"]), _unpack_array(state["velocities"]))
    return data


# the file ------------------------------------------------------------------------------------
def encode_checkpoint(state: dict) -> bytes:
    """Header (magic, version, length, checksum) and the msgpack payload."""
    payload = msgpack.packb(state, use_bin_type=True)
    return _HEADER.pack(MAGIC, FORMAT_VERSION, len(payload), hashlib.sha256(payload).digest()) + payload


def decode_checkpoint(data: bytes, name: str = "checkpoint") -> dict:
    """The state in a checkpoint file's contents; CheckpointError saying what is wrong."""
    if len(data) < _HEADER.size:
        raise CheckpointError(f"{name} is truncated: {len(data)} bytes, not even its {_HEADER.size}-byte header")
    magic, version, length, digest = _HEADER.unpack_from(data)
    if magic != MAGIC:
        raise CheckpointError(f"{name} is not a ConAg world checkpoint")
    if version != FORMAT_VERSION:
        raise CheckpointError(f"{name} has checkpoint format version {version}; this conag reads version "
                              f"{FORMAT_VERSION}")
    payload = data[_HEADER.size:]
    if len(payload) != length:
        raise CheckpointError(f"{name} is truncated: {len(payload)} of its {length} payload bytes")
    if hashlib.sha256(payload).digest() != digest:
        raise CheckpointError(f"{name} is corrupt: its checksum does not match its contents")
    try:
        state = msgpack.unpackb(payload, raw=False, strict_map_key=False)
    except (ValueError, msgpack.ExtraData, msgpack.FormatError, msgpack.StackError) as exc:
        raise CheckpointError(f"{name} is corrupt: {exc}") from exc
    if not isinstance(state, dict):
        raise CheckpointError(f"{name} is corrupt: its payload is not a map")
    return state


def previous_path(path: str | Path) -> Path:
    """Where the checkpoint a new one replaced is kept (FILE.prev)."""
    path = Path(path)
    return path.with_name(path.name + ".prev")


def write_checkpoint(path: str | Path, data: bytes) -> None:
    """Write checkpoint bytes to `path` atomically (see the module); on any error the
    checkpoint already there is untouched and the temporary file removed."""
    path = Path(path)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    try:
        with open(tmp, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        decode_checkpoint(tmp.read_bytes(), str(tmp))  # what landed on disk reads back, or nothing changes
        if path.exists():
            _keep_as_previous(path)
        os.replace(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    _fsync_dir(path.parent)


def _keep_as_previous(path: Path) -> None:
    """Make FILE.prev the checkpoint now at `path`, leaving `path` in place: a second name
    for the same file (a copy where the file system has no hard links), renamed over
    FILE.prev. Renaming `path` itself away would leave no FILE until the new one is renamed
    in, and a process killed just then left a `conag world --resume FILE` nothing to read."""
    prev = previous_path(path)
    link = prev.with_name(f".{prev.name}.{os.getpid()}.tmp")
    link.unlink(missing_ok=True)  # (left by a process of the same pid that was killed here)
    try:
        try:
            os.link(path, link)
        except OSError:
            shutil.copyfile(path, link)
        os.replace(link, prev)
    except BaseException:
        link.unlink(missing_ok=True)
        raise


def _fsync_dir(directory: Path) -> None:
    fd = os.open(directory, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def read_checkpoint(path: str | Path) -> dict:
    """The state in the checkpoint file `path` (CheckpointError, FileNotFoundError)."""
    path = Path(path)
    return decode_checkpoint(path.read_bytes(), str(path))


def load_state(path: str | Path) -> dict:
    """The state in checkpoint `path`; a CheckpointError also says whether FILE.prev is intact
    (and is raised for a missing FILE when it is: FileNotFoundError otherwise)."""
    path = Path(path)
    try:
        return read_checkpoint(path)
    except CheckpointError as exc:
        raise CheckpointError(f"{exc}{_previous_intact(path)}") from exc
    except FileNotFoundError as exc:
        hint = _previous_intact(path)
        if not hint:
            raise
        raise CheckpointError(f"no checkpoint at {path}{hint}") from exc


def _previous_intact(path: Path) -> str:
    """'; the checkpoint before it, FILE.prev (tick N), is intact: ...' if it is, else ''."""
    prev = previous_path(path)
    try:
        tick = read_checkpoint(prev)["tick"]
    except (OSError, CheckpointError, KeyError):
        return ""
    return f"; the checkpoint before it, {prev} (tick {tick}), is intact: resume from that"


def load_world(path: str | Path) -> World:
    """The world saved in checkpoint `path`, ready to step on from its tick."""
    return restore_world(load_state(path))


def newest_good(path: str | Path) -> Path | None:
    """The checkpoint to resume from: `path` if it reads back, else FILE.prev if that does
    (FILE damaged or removed since it was written), else None."""
    for candidate in (Path(path), previous_path(path)):
        try:
            read_checkpoint(candidate)
            return candidate
        except (OSError, CheckpointError):
            continue
    return None


@dataclass(frozen=True)
class CheckpointPlan:
    """When a world server checkpoints: every `every` ticks (the ticks that are multiples of
    it) and when it stops, to `path`. Without a path the space is still rebuilt at those
    ticks and nothing is written: a replay of a checkpointing run steps the same way."""

    path: str | None = None
    every: int = DEFAULT_EVERY

    def __post_init__(self) -> None:
        if not (isinstance(self.every, int) and self.every >= 1):
            raise ValueError("the checkpoint interval must be a whole number of ticks >= 1")

    def due(self, tick: int) -> bool:
        """Whether the world checkpoints after stepping to `tick`."""
        return tick > 0 and tick % self.every == 0


def resumed_epoch(world: World) -> int:
    """The epoch of a world resumed from a checkpoint: a new run of the world, told apart
    from the one that died (agents refuse its frames after the new Welcome), and still a
    function of the checkpoint alone."""
    text = f"{world.world_id}|{world.epoch}|resumed at {world.tick}"
    return int.from_bytes(hashlib.blake2b(text.encode(), digest_size=8).digest(), "little") >> 1

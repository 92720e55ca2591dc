"""The one msgpack codec of the ConAg bus.

Wire format: a msgpack map {"v": SCHEMA_VERSION, "t": type name, "f": [field values in
declaration order]}. Tuples of floats (sensor readings, site coordinates, ...) travel as
one msgpack bin of little-endian float64s: exact, and decoded by a single C call, which
keeps the per-tick frame cheap on both ends of the bus. Decoding anything malformed
(random bytes, wrong types, missing or extra fields, NaN/inf, unknown type, wrong
version, oversize) raises ProtocolError and nothing else, so a receiver can count and
drop bad input without ever crashing.
"""

from __future__ import annotations

import dataclasses
import functools
import struct
import typing
from typing import Any

import msgpack

from protocol.messages import MAX_STRING, MESSAGE_TYPES, SCHEMA_VERSION

MAX_MESSAGE_BYTES = 256 * 1024
MAX_TUPLE = 8192


class ProtocolError(ValueError):
    """A message could not be decoded or is not valid; the receiver should drop it."""


_BY_NAME = {cls.__name__: cls for cls in MESSAGE_TYPES}


@functools.cache
def _field_types(cls: type) -> tuple[tuple[str, Any], ...]:
    hints = typing.get_type_hints(cls)
    return tuple((f.name, hints[f.name]) for f in dataclasses.fields(cls))


@functools.cache
def _wire_spec(cls: type) -> tuple[tuple[str, type, bool, str], ...]:
    """(name, scalar type, is a tuple of them, "Class.name" for errors) per field, worked
    out once per class."""
    spec: list[tuple[str, type, bool, str]] = []
    for name, hint in _field_types(cls):
        is_tuple = typing.get_origin(hint) is tuple
        spec.append((name, typing.get_args(hint)[0] if is_tuple else hint, is_tuple, f"{cls.__name__}.{name}"))
    return tuple(spec)


def encode(msg: object) -> bytes:
    """Encode a protocol message to bytes."""
    cls: type = type(msg)  # (a `type` for mypy, which does not take type[object] as hashable)
    name = cls.__name__
    if _BY_NAME.get(name) is not cls:
        raise TypeError(f"not a protocol message: {cls!r}")
    values = [_pack_floats(v) if is_tuple and kind is float else list(v) if is_tuple else v
              for v, (_, kind, is_tuple, _) in zip((getattr(msg, n) for n, _ in _field_types(cls)), _wire_spec(cls))]
    return encode_checked_fields(cls, values)


def encode_checked_fields(cls: type, values: list) -> bytes:
    """The wire bytes of a `cls` message from its field values as they go on the wire (in
    declaration order; a float tuple as its little-endian float64 bytes), which the caller
    vouches for: nothing is checked. For a sender that builds many messages of one kind
    straight from arrays every tick (the world's sensor frames, `World.encoded_frames`),
    where building and checking each dataclass first cost more than the rest of sending it;
    a test holds its bytes equal to `encode`'s."""
    return msgpack.packb({"v": SCHEMA_VERSION, "t": cls.__name__, "f": values}, use_bin_type=True)


def _check_scalar(value: object, kind: type, where: str) -> object:
    # bool is a subclass of int: keep the two apart in both directions.
    if kind is bool:
        if isinstance(value, bool):
            return value
    elif kind is int:
        if isinstance(value, int) and not isinstance(value, bool) and -(2**63) <= value < 2**63:
            return value
    elif kind is float:
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
    elif kind is str:  # noqa: SIM102 -- one branch per kind, like those above
        if isinstance(value, str) and len(value) <= MAX_STRING:
            return value
    raise ProtocolError(f"{where}: expected {kind.__name__}, got {type(value).__name__}")


def _pack_floats(values: tuple[float, ...]) -> bytes:
    return struct.pack(f"<{len(values)}d", *values)


def _check_field(value: object, kind: type, is_tuple: bool, where: str) -> object:
    if not is_tuple:
        return _check_scalar(value, kind, where)
    if kind is float:
        if not isinstance(value, bytes) or len(value) % 8 or len(value) > 8 * MAX_TUPLE:
            raise ProtocolError(f"{where}: expected packed float64s (bytes, a multiple of 8 long)")
        return struct.unpack(f"<{len(value) // 8}d", value)  # NaN/inf: the message rejects them
    if not isinstance(value, list) or len(value) > MAX_TUPLE:
        raise ProtocolError(f"{where}: expected a list of at most {MAX_TUPLE} items")
    if kind is int and _plain_ints(value):
        return tuple(value)
    return tuple(_check_scalar(v, kind, where) for v in value)


def _plain_ints(values: list) -> bool:
    """Whether every item is an int (not a bool) within int64, as `_check_scalar` wants,
    checked in C (map, set, min, max) rather than item by item: a map snapshot holds
    thousands (the item-by-item check is the fallback, for its error message)."""
    return set(map(type, values)) <= {int} and (not values or (min(values) >= -(2**63) and max(values) < 2**63))


def decode(data: bytes, expected: type | tuple[type, ...] | None = None) -> object:
    """Decode bytes into a protocol message, or raise ProtocolError.

    With `expected`, a valid message of another type is also a ProtocolError.
    """
    if not isinstance(data, (bytes, bytearray, memoryview)):
        raise ProtocolError(f"expected bytes, got {type(data).__name__}")
    size = data.nbytes if isinstance(data, memoryview) else len(data)  # len() of a view counts items
    if size > MAX_MESSAGE_BYTES:
        raise ProtocolError(f"message of {size} bytes exceeds {MAX_MESSAGE_BYTES}")
    try:
        raw = msgpack.unpackb(bytes(data), raw=False, strict_map_key=True, use_list=True)
    except Exception as exc:  # noqa: BLE001 -- msgpack raises many types; all mean "not a message"
        raise ProtocolError(f"not msgpack: {exc}") from None
    if not isinstance(raw, dict) or set(raw) != {"v", "t", "f"}:
        raise ProtocolError("not a ConAg envelope")
    if type(raw["v"]) is not int or raw["v"] != SCHEMA_VERSION:
        raise ProtocolError(f"schema version {raw['v']!r}, expected {SCHEMA_VERSION}")
    cls = _BY_NAME.get(raw["t"]) if isinstance(raw["t"], str) else None
    if cls is None:
        raise ProtocolError(f"unknown message type {raw['t']!r}")
    if expected is not None and not issubclass(cls, expected):
        raise ProtocolError(f"unexpected message type {cls.__name__}")
    spec = _wire_spec(cls)
    values = raw["f"]
    if not isinstance(values, list) or len(values) != len(spec):
        raise ProtocolError(f"{cls.__name__}: expected {len(spec)} fields")
    kwargs = {name: _check_field(v, kind, is_tuple, where) for (name, kind, is_tuple, where), v in zip(spec, values)}
    try:
        return cls(**kwargs)
    except (TypeError, ValueError) as exc:
        raise ProtocolError(str(exc)) from None

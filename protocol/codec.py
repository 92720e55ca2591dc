"""The one msgpack codec of the ConAg bus.

Wire format: a msgpack map {"v": SCHEMA_VERSION, "t": type name, "f": [field values in
declaration order]}. Decoding anything malformed (random bytes, wrong types, missing or
extra fields, NaN/inf, unknown type, wrong version, oversize) raises ProtocolError and
nothing else, so a receiver can count and drop bad input without ever crashing.
"""

from __future__ import annotations

import dataclasses
import functools
import typing

import msgpack

from protocol.messages import MAX_STRING, MESSAGE_TYPES, SCHEMA_VERSION

MAX_MESSAGE_BYTES = 256 * 1024
MAX_TUPLE = 8192


class ProtocolError(ValueError):
    """A message could not be decoded or is not valid; the receiver should drop it."""


_BY_NAME = {cls.__name__: cls for cls in MESSAGE_TYPES}


@functools.cache
def _field_types(cls: type) -> tuple[tuple[str, object], ...]:
    hints = typing.get_type_hints(cls)
    return tuple((f.name, hints[f.name]) for f in dataclasses.fields(cls))


def encode(msg: object) -> bytes:
    """Encode a protocol message to bytes."""
    name = type(msg).__name__
    if _BY_NAME.get(name) is not type(msg):
        raise TypeError(f"not a protocol message: {type(msg)!r}")
    values = [list(v) if isinstance(v, tuple) else v for v in
              (getattr(msg, n) for n, _ in _field_types(type(msg)))]
    return msgpack.packb({"v": SCHEMA_VERSION, "t": name, "f": values}, use_bin_type=True)


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
    elif kind is str:
        if isinstance(value, str) and len(value) <= MAX_STRING:
            return value
    raise ProtocolError(f"{where}: expected {kind.__name__}, got {type(value).__name__}")


def _check_field(value: object, hint: object, where: str) -> object:
    if typing.get_origin(hint) is tuple:
        item = typing.get_args(hint)[0]
        if not isinstance(value, list) or len(value) > MAX_TUPLE:
            raise ProtocolError(f"{where}: expected a list of at most {MAX_TUPLE} items")
        return tuple(_check_scalar(v, item, where) for v in value)
    return _check_scalar(value, hint, where)  # type: ignore[arg-type]


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
    except Exception as exc:  # msgpack raises many types; all mean "not a message"
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
    spec = _field_types(cls)
    values = raw["f"]
    if not isinstance(values, list) or len(values) != len(spec):
        raise ProtocolError(f"{cls.__name__}: expected {len(spec)} fields")
    kwargs = {name: _check_field(v, hint, f"{cls.__name__}.{name}")
              for (name, hint), v in zip(spec, values)}
    try:
        return cls(**kwargs)
    except (TypeError, ValueError) as exc:
        raise ProtocolError(str(exc)) from None

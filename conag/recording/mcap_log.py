"""Bus recordings as MCAP files: what `conag record` writes and `conag replay` reads.

A recording holds every message published under one world's keys, as the bytes that
travelled (the one msgpack codec of `protocol`), so a replay re-publishes them unchanged:

* one MCAP channel per key expression, message encoding `msgpack`, no schema (the
  envelope names its type; the channel's metadata says which type it carried first);
* per message: `log_time` is when the recorder received it (ns since the epoch, from
  the clock it is given), `publish_time` the world tick the message belongs to, as
  simulated time (`tick * tick_ns`, `tick_ns` in the metadata; 20 ms at the default
  50 ticks per second), and `sequence` counts the messages of its channel from 1. Every
  key of the ConAg bus has one publisher (the world for frames, status, blueprints,
  welcomes and perturbations; an agent for its commands, decisions and states; the
  teacher for reinforcements), so that count is the per-publisher sequence MCAP asks a
  recorder to fill in when the publisher does not. The tick is the message's own `tick`
  field; a message without one (none is published today) gets the newest tick seen;
* a metadata record `conag` (scenario text, seed, configs, project and schema versions,
  whatever the recorder was told) written first, and `conag.end` (message counts, last
  tick) written on close;
* with `derive` (the recorder passes `conag.foxglove.convert.Translator.feed`), more
  channels beside those: Foxglove's well-known schemas (protobuf) and JSON with a JSON
  schema, each channel with its schema, the same `log_time` as the message it came from,
  `publish_time` its tick and its own sequence. They are made as the file is closed, from
  the messages it holds, read back in the order they were added: during a run the
  recorder then only receives and writes, and translating after it costs the run nothing
  (while it went on, translating each message as it came was half the recorder's CPU, at
  a time when its caches were the run's). Reading a recording (`read_recording`) takes
  the msgpack channels only: a replay never sees the others.

The file is written by `conag.recording.mcap_write` (a chunked, indexed MCAP file, in few
Python steps a message) and read with the `mcap` package. `McapRecorder` writes to
`OUT.part` and renames it to `OUT` once the summary and footer are written, so `OUT` is
always a complete file. A recorder killed outright (SIGKILL) leaves `OUT.part`: a chunk is
written whole when it fills (`chunk_size`) or when the recorder's `flush` ends it (the
recorder process does so every second), so `read_recording` reads such a file up to its
last complete chunk and says it is incomplete; only the messages of the chunk in progress
are lost (and the derived channels, which are made on close: `add_derived_channels` makes
them for such a file).
"""

from __future__ import annotations

import dataclasses
import functools
import io
import os
import time
from collections.abc import Callable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Protocol

import msgpack
from mcap.exceptions import EndOfFile, McapError
from mcap.reader import make_reader
from mcap.records import Channel, Chunk, Message, Metadata
from mcap.stream_reader import StreamReader, get_chunk_data_stream

from conag.recording.mcap_write import CHANNEL, CHANNEL_HEAD, MESSAGE, MESSAGE_HEAD, RECORD, ChunkedWriter
from protocol.messages import MESSAGE_TYPES, SCHEMA_VERSION

MESSAGE_ENCODING = "msgpack"
PROFILE = "conag"
METADATA = "conag"          # the metadata record written first
END_METADATA = "conag.end"  # the one written on close
DEFAULT_TICK_NS = 20_000_000  # one tick of simulated time at the default 50 ticks per second
CHUNK_SIZE = 256 * 1024       # bytes of messages per chunk: what a SIGKILL can lose at most


class DerivedSchema(Protocol):
    """A derived channel's schema (`conag.foxglove.convert.SchemaDef`)."""

    @property
    def name(self) -> str: ...
    @property
    def encoding(self) -> str: ...
    @property
    def data(self) -> bytes: ...
    @property
    def message_encoding(self) -> str: ...


class DerivedMessage(Protocol):
    """A message made from a bus message (`conag.foxglove.convert.Derived`)."""

    @property
    def topic(self) -> str: ...
    @property
    def schema(self) -> DerivedSchema: ...
    @property
    def tick(self) -> int: ...
    @property
    def data(self) -> bytes: ...


Derive = Callable[[str, bytes, int], Iterable[DerivedMessage]]  # (key, bytes, log time) -> derived messages


@functools.cache
def _tick_index() -> dict[str, int]:
    """Type name -> position of its `tick` field in the wire envelope's field list."""
    out = {}
    for cls in MESSAGE_TYPES:
        names = [f.name for f in dataclasses.fields(cls)]
        if "tick" in names:
            out[cls.__name__] = names.index("tick")
    return out


def peek(data: bytes) -> tuple[str, int | None]:
    """(type name, tick) of an encoded ConAg message without decoding it fully; ("", None)
    for bytes that are not one. Cheap: the recorder calls it on every message."""
    try:
        raw = msgpack.unpackb(data, raw=False)
        name = raw["t"]
        i = _tick_index().get(name)
        tick = raw["f"][i] if i is not None else None
        return (name, tick) if tick is None or (type(tick) is int and tick >= 0) else (name, None)
    except Exception:  # noqa: BLE001 -- anything malformed is simply not a message we can read
        return "", None


class McapRecorder:
    """Writes bus messages to an MCAP file (see the module): `add` each, then `close`.

    `metadata` goes into the file's `conag` metadata record; `derive(key, data, log_time)`
    gives the messages to write beside each one (see the module). Not thread-safe: one
    thread adds (the recorder process's loop).
    """

    def __init__(self, out: str | Path, metadata: Mapping[str, str] | None = None, *,
                 tick_ns: int = DEFAULT_TICK_NS, chunk_size: int = CHUNK_SIZE, derive: Derive | None = None):
        self.path = Path(out)
        self.part = self.path.with_name(self.path.name + ".part")
        self.tick_ns = tick_ns
        self.tick = 0                       # the newest tick seen
        self.counts: dict[str, int] = {}    # messages per key (their sequence numbers so far)
        self._channels: dict[str, int] = {}
        self.derive = derive
        self.derived: dict[str, int] = {}   # derived messages per topic (their sequence numbers so far)
        self._derived_channels: dict[str, int] = {}
        self._schemas: dict[str, int] = {}
        self.derived_until: int | None = None  # set by `close` when the deadline cut the derived channels short
        self.derive_error = ""                 # ... and this when `derive` failed there (the file is finished)
        self._file: IO[bytes] = open(self.part, "wb")  # noqa: SIM115 -- closed by close()
        self._writer = ChunkedWriter(self._file, chunk_size=chunk_size)
        self._writer.start(profile=PROFILE, library=f"conag {_conag_version()} (conag.recording.mcap_write)")
        meta = {"schema_version": str(SCHEMA_VERSION), "tick_ns": str(tick_ns)}
        meta.update({k: str(v) for k, v in (metadata or {}).items()})
        self._writer.add_metadata(METADATA, meta)
        self._closed = False

    @property
    def messages(self) -> int:
        """Messages written so far."""
        return sum(self.counts.values())

    def add(self, key: str, data: bytes, log_time_ns: int) -> tuple[str, int | None]:
        """Write one message published on `key`, received at `log_time_ns`; returns its type's
        name and its own tick (None if it has none: `peek`)."""
        name, own = peek(data)
        tick = self.tick if own is None else own
        self.tick = max(self.tick, tick)
        channel = self._channels.get(key)
        if channel is None:
            channel = self._writer.register_channel(key, MESSAGE_ENCODING, 0, {"type": name})
            self._channels[key] = channel
        seq = self.counts.get(key, 0) + 1
        self.counts[key] = seq
        self._writer.add_message(channel, log_time=log_time_ns, data=data, publish_time=tick * self.tick_ns,
                                 sequence=seq & 0xFFFFFFFF)
        return name, own

    def _derive_recorded(self, deadline: float | None) -> int | None:
        """Write the derived channels of every message added so far (see the module), reading
        them back from the file in the order they were added. Stops at `deadline` (a
        `time.monotonic()` value): returns the tick of the last message derived, or None when
        all were."""
        assert self.derive is not None
        self._writer.flush()  # every message added is in a complete chunk, on disk
        end = self._file.tell()
        with open(self.part, "rb") as f:
            for i, (key, log_time, publish_time, data) in enumerate(
                    _bus_messages(_Capped(f, end), set(self._channels.values()))):
                if deadline is not None and i % 1024 == 0 and time.monotonic() > deadline:
                    return publish_time // self.tick_ns
                for d in self.derive(key, data, log_time):
                    self._add_derived(d, log_time)
        return None

    def _add_derived(self, d: DerivedMessage, log_time_ns: int) -> None:
        channel = self._derived_channels.get(d.topic)
        if channel is None:
            schema = self._schemas.get(d.schema.name)
            if schema is None:
                schema = self._writer.register_schema(d.schema.name, d.schema.encoding, d.schema.data)
                self._schemas[d.schema.name] = schema
            channel = self._writer.register_channel(d.topic, d.schema.message_encoding, schema)
            self._derived_channels[d.topic] = channel
        seq = self.derived.get(d.topic, 0) + 1
        self.derived[d.topic] = seq
        self._writer.add_message(channel, log_time=log_time_ns, data=d.data, publish_time=d.tick * self.tick_ns,
                                 sequence=seq & 0xFFFFFFFF)

    def flush(self) -> None:
        """End the chunk in progress and flush the file: what was added so far survives
        the recorder being killed outright (the shell calls this every second or so)."""
        self._writer.flush()

    def close(self, end: Mapping[str, str] | None = None, derive_deadline: float | None = None) -> Path:
        """Write the derived channels (until `derive_deadline`, a `time.monotonic()` value, if
        given), the `conag.end` metadata, the summary and the footer; rename `OUT.part` to
        `OUT`. Returns the path of the finished file. A second call does nothing."""
        if self._closed:
            return self.path
        self._closed = True
        try:
            meta = {"messages": str(self.messages), "last_tick": str(self.tick), "channels": str(len(self.counts))}
            if self.derive is not None:
                try:
                    cut = self._derive_recorded(derive_deadline)
                except Exception as exc:  # noqa: BLE001 -- the bus's messages are written: finish the file all the same
                    self.derive_error = f"{type(exc).__name__}: {exc}"
                    meta.update(derived_error=self.derive_error)
                    cut = None
                meta.update(derived_messages=str(sum(self.derived.values())), derived_channels=str(len(self.derived)))
                if cut is not None:
                    self.derived_until = cut
                    meta.update(derived_until_tick=str(cut))
            meta.update({k: str(v) for k, v in (end or {}).items()})
            self._writer.add_metadata(END_METADATA, meta)
            self._writer.finish()
        finally:
            self._file.close()
        os.replace(self.part, self.path)
        return self.path

    def __enter__(self) -> McapRecorder:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


def _conag_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("conag")
    except PackageNotFoundError:
        return "unknown"


# --- reading ----------------------------------------------------------------------------

@dataclass(frozen=True)
class Entry:
    """One recorded message: its key, tick, sequence number in its channel, receive time
    (ns) and the bytes that travelled."""

    key: str
    tick: int
    seq: int
    log_time: int
    data: bytes


@dataclass
class Recording:
    """What `read_recording` found: metadata records by name, the messages in the order
    they were received, and whether the file was complete (else `problem` says why)."""

    metadata: dict[str, dict[str, str]] = field(default_factory=dict)
    entries: list[Entry] = field(default_factory=list)
    complete: bool = True
    problem: str = ""

    @property
    def info(self) -> dict[str, str]:
        """The `conag` metadata record (scenario, seed, configs, versions)."""
        return self.metadata.get(METADATA, {})

    @property
    def last_tick(self) -> int:
        """The newest tick of any message (0 for an empty recording)."""
        return max((e.tick for e in self.entries), default=0)

    def keys(self) -> list[str]:
        """Every key recorded, in the order each first appeared."""
        return list(dict.fromkeys(e.key for e in self.entries))


class RecordingError(ValueError):
    """A file that is no ConAg recording: unreadable, empty, not MCAP, or without the
    `conag` metadata record every recording starts with. The message names the file."""


MCAP_MAGIC = b"\x89MCAP0\r\n"  # the 8 bytes every MCAP file starts with


def read_recording(path: str | Path, keep: Callable[[str], bool] | None = None) -> Recording:
    """Read a recording (a finished file, or the `.part` a killed recorder left: up to its
    last complete chunk). `keep(key)` selects channels; None keeps all. Raises
    FileNotFoundError, or RecordingError for a file that is no ConAg recording."""
    try:
        f = open(path, "rb")  # noqa: SIM115 -- closed below; the with statement would wrap the OSError too
    except FileNotFoundError:
        raise
    except OSError as exc:
        raise RecordingError(f"{path}: cannot read it ({exc.strerror or exc})") from None
    with f:
        try:
            start = f.read(len(MCAP_MAGIC))
        except OSError as exc:
            raise RecordingError(f"{path}: cannot read it ({exc.strerror or exc})") from None
        if not start:
            raise RecordingError(f"{path}: not a recording (the file is empty)")
        if start != MCAP_MAGIC:
            raise RecordingError(f"{path}: not a recording (not an MCAP file: it does not start with MCAP's magic)")
        f.seek(0)
        try:
            rec = _read_indexed(f, keep)
        except Exception:  # noqa: BLE001 -- no summary or footer (McapError), or damage mcap reports otherwise
            f.seek(0)  # a recording cut short: read it as a stream
            rec = _read_stream(f, keep)
    if METADATA not in rec.metadata:
        raise RecordingError(f"{path}: not a ConAg recording (no {METADATA!r} metadata record"
                             + (f"; {rec.problem}" if rec.problem else "") + ")")
    return rec


def read_end(path: str | Path) -> dict[str, str]:
    """The `conag.end` metadata of a finished recording, from its summary alone (empty for
    a recording cut short, or one that is not there)."""
    try:
        with open(path, "rb") as f:
            return next((dict(m.metadata) for m in make_reader(f).iter_metadata() if m.name == END_METADATA), {})
    except Exception:  # noqa: BLE001 -- no summary (McapError), no file: nothing to say
        return {}


def world_cut_short(end: Mapping[str, str], final_tick: int) -> str:
    """What a run's recording lacks of the world ('' if nothing): the world publishes a
    status as it stops, so a recording that heard the whole run holds one of the run's last
    tick (`end["ticks"]`, the newest heard). An idle recorder starved longer than zenoh
    waits on a full queue (5 s) had the world's link to it closed, and heard no more."""
    try:
        heard = int(end.get("ticks", ""))
    except ValueError:
        return "holds no status of the world"
    if heard >= final_tick:
        return ""
    return (f"holds the world's messages only up to about tick {heard} of {final_tick} (the recorder fell too far "
            "behind and the world's link to it was closed: record with --record-priority low or normal on a busy "
            "machine)")


def _entry(channel: Channel, message: Message, tick_ns: int) -> Entry:
    return Entry(channel.topic, message.publish_time // tick_ns, message.sequence, message.log_time,
                 bytes(message.data))


def _read_indexed(f: IO[bytes], keep: Callable[[str], bool] | None) -> Recording:
    reader = make_reader(f)
    summary = reader.get_summary()
    if summary is None:
        raise McapError("no summary section")
    rec = Recording()
    rec.metadata = {m.name: dict(m.metadata) for m in reader.iter_metadata()}
    tick_ns = int(rec.info.get("tick_ns", DEFAULT_TICK_NS))
    topics = [c.topic for c in summary.channels.values()
              if c.message_encoding == MESSAGE_ENCODING and (keep is None or keep(c.topic))]
    rec.entries = [_entry(channel, message, tick_ns)
                   for _, channel, message in reader.iter_messages(topics=topics, log_time_order=False)]
    return rec


class _Capped(io.RawIOBase):
    """The first `end` bytes of a file opened for reading: what a writer still appending to
    it had written when the reading began."""

    def __init__(self, f: IO[bytes], end: int):
        self.f, self.left = f, end

    def readable(self) -> bool:
        return True

    def readinto(self, b) -> int:
        n = self.f.readinto(memoryview(b)[:min(len(b), self.left)]) or 0  # type: ignore[attr-defined]
        self.left -= n
        return n


def _bus_messages(raw: io.RawIOBase, channel_ids: set[int]) -> Iterator[tuple[str, int, int, bytes]]:
    """(key, log time, publish time, bytes) of every message of the given channels, in the
    order the file holds them (a stream read up to its end: no summary or footer needed).
    The chunks are cut into records here, not by `mcap`, whose Message records took half the
    time of the translation they fed: most messages (commands, decisions, most frames) are
    only skipped by it."""
    topics: dict[int, str] = {}
    records = StreamReader(io.BufferedReader(raw), skip_magic=False, emit_chunks=True).records
    while True:
        try:
            record = next(records)
        except (StopIteration, EndOfFile):  # the end of what was written: no footer yet
            return
        if isinstance(record, Chunk):
            stream, size = get_chunk_data_stream(record)
            yield from _chunk_messages(stream.read(size), channel_ids, topics)
        elif isinstance(record, Channel) and record.id in channel_ids:
            topics[record.id] = record.topic
        elif isinstance(record, Message) and record.channel_id in topics:
            yield topics[record.channel_id], record.log_time, record.publish_time, bytes(record.data)


def _chunk_messages(data: bytes, channel_ids: set[int],
                    topics: dict[int, str]) -> Iterator[tuple[str, int, int, bytes]]:
    """The messages of the given channels in one chunk's records (MCAP's layout: opcode,
    length, body), learning the channels the chunk declares into `topics`."""
    pos, end = 0, len(data)
    while pos < end:
        opcode, length = RECORD.unpack_from(data, pos)
        body = pos + RECORD.size
        if opcode == MESSAGE:
            channel, _, log_time, publish_time = MESSAGE_HEAD.unpack_from(data, body)
            key = topics.get(channel)
            if key is not None:
                yield key, log_time, publish_time, data[body + MESSAGE_HEAD.size:body + length]
        elif opcode == CHANNEL:
            channel, _, n = CHANNEL_HEAD.unpack_from(data, body)
            if channel in channel_ids:
                topics[channel] = data[body + CHANNEL_HEAD.size:body + CHANNEL_HEAD.size + n].decode()
        pos = body + length


def add_derived_channels(src: str | Path, out: str | Path, derive: Derive) -> Recording:
    """Write `src`'s bus messages to `out` with the derived channels beside them, as a
    recorder would have (for a recording made without them, or the `.part` a killed
    recorder left, read up to its last complete chunk). Returns what was read from `src`."""
    rec = read_recording(src)
    tick_ns = int(rec.info.get("tick_ns", DEFAULT_TICK_NS))
    end = {k: v for k, v in rec.metadata.get(END_METADATA, {}).items() if not k.startswith("derived_")}
    with McapRecorder(out, rec.info, tick_ns=tick_ns, derive=derive) as writer:
        for e in rec.entries:
            writer.add(e.key, e.data, e.log_time)
        writer.close(end)
    return rec


def _read_stream(f: IO[bytes], keep: Callable[[str], bool] | None) -> Recording:
    rec = Recording(complete=False, problem="no summary or footer: the recorder did not finish; "
                                            "read up to the last complete chunk")
    channels: dict[int, Channel] = {}
    tick_ns = DEFAULT_TICK_NS
    try:
        for record in StreamReader(f, skip_magic=False).records:
            if isinstance(record, Channel):
                channels[record.id] = record
            elif isinstance(record, Metadata):
                rec.metadata[record.name] = dict(record.metadata)
                if record.name == METADATA:
                    tick_ns = int(record.metadata.get("tick_ns", DEFAULT_TICK_NS))
            elif isinstance(record, Message):
                channel = channels[record.channel_id]
                if channel.message_encoding == MESSAGE_ENCODING and (keep is None or keep(channel.topic)):
                    rec.entries.append(_entry(channel, record, tick_ns))
    except Exception as exc:  # noqa: BLE001 -- a truncated record ends the readable part, whatever mcap raises
        rec.problem += f" ({type(exc).__name__}: {exc})"
    return rec


def iter_entries(entries: list[Entry], from_tick: int = 0) -> Iterator[Entry]:
    """The entries of tick >= `from_tick`, in recorded order."""
    return (e for e in entries if e.tick >= from_tick)

"""A small MCAP writer: what a recorder writes at the rate the bus delivers, in few Python steps.

The `mcap` package's `Writer` builds each message as a record object and writes it field by
field (some 3 us a message here); a recorder does that for every message of a run, on a core
the run would otherwise have (`bench.bench_record_windows`: writing was most of what a
recording cost a run). This writer packs a message's header in one `struct` call into the
chunk in progress and keeps its index entry; the rest of the file is written as chunks end
and on `finish`. It writes what the MCAP specification (https://mcap.dev/spec) calls a
chunked, indexed file:

* the magic and a Header; then zstd-compressed Chunks, each followed by one MessageIndex per
  channel it holds; Schemas and Channels go into the chunk in progress as they are
  registered, so every chunk can be read on its own (a file cut short is read as a stream);
* Metadata records between chunks (a chunk in progress is ended first);
* on `finish`: DataEnd, then the summary (every Schema and Channel again, Statistics, a
  ChunkIndex per chunk, a MetadataIndex per metadata record), its SummaryOffsets, the
  Footer and the magic. Every CRC is filled in.

The same calls as `mcap.writer.Writer` (those `McapRecorder` makes), one thread.
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Mapping
from typing import IO

import zstandard

MAGIC = b"\x89MCAP0\r\n"
# opcodes (the specification's)
HEADER, FOOTER, SCHEMA, CHANNEL, MESSAGE, CHUNK, MESSAGE_INDEX, CHUNK_INDEX = 0x01, 0x02, 0x03, 0x04, 0x05, 0x06, \
    0x07, 0x08
STATISTICS, METADATA, METADATA_INDEX, SUMMARY_OFFSET, DATA_END = 0x0B, 0x0C, 0x0D, 0x0E, 0x0F

RECORD = struct.Struct("<BQ")           # every record starts with its opcode and the length of its body
MESSAGE_HEAD = struct.Struct("<HIQQ")   # a Message's body before its data: channel id, sequence, log and publish time
CHANNEL_HEAD = struct.Struct("<HHI")    # a Channel's body up to its topic: id, schema id, the topic's length
_MESSAGE = struct.Struct("<BQHIQQ")     # RECORD and MESSAGE_HEAD in one call, as a message is written


def _string(s: str) -> bytes:
    b = s.encode("utf-8")
    return struct.pack("<I", len(b)) + b


def _string_map(m: Mapping[str, str]) -> bytes:
    body = b"".join(_string(k) + _string(v) for k, v in sorted(m.items()))
    return struct.pack("<I", len(body)) + body


def _record(opcode: int, body: bytes) -> bytes:
    return struct.pack("<BQ", opcode, len(body)) + body


class ChunkedWriter:
    """Writes an MCAP file to a binary stream (see the module): `start`, then schemas,
    channels, messages and metadata, then `finish`. `flush` ends the chunk in progress and
    flushes the stream, so that what was added so far is on disk whole."""

    def __init__(self, stream: IO[bytes], chunk_size: int = 256 * 1024, level: int = 3):
        self._stream, self._chunk_size = stream, chunk_size
        self._zstd = zstandard.ZstdCompressor(level=level)
        self._offset = 0            # bytes written so far
        self._crc = 0               # of the data section so far
        self._schemas: dict[int, bytes] = {}    # id -> the Schema record
        self._channels: dict[int, bytes] = {}   # id -> the Channel record
        self._chunk = bytearray()
        self._chunk_index: dict[int, list[tuple[int, int]]] = {}  # channel -> (log time, offset in the chunk)
        self._chunk_start = self._chunk_end = 0
        self._chunk_indexes: list[bytes] = []
        self._metadata_indexes: list[bytes] = []
        self._counts: dict[int, int] = {}        # messages per channel
        self._start_time: int | None = None     # the earliest and latest log time of any chunk
        self._end_time = 0

    # --- writing ---------------------------------------------------------------------------------
    def _write(self, data: bytes) -> None:
        self._stream.write(data)
        self._crc = zlib.crc32(data, self._crc)
        self._offset += len(data)

    def start(self, profile: str, library: str) -> None:
        self._write(MAGIC + _record(HEADER, _string(profile) + _string(library)))

    def register_schema(self, name: str, encoding: str, data: bytes) -> int:
        sid = len(self._schemas) + 1  # 0 means "no schema"
        rec = _record(SCHEMA, struct.pack("<H", sid) + _string(name) + _string(encoding)
                      + struct.pack("<I", len(data)) + data)
        self._schemas[sid] = rec
        self._chunk += rec
        return sid

    def register_channel(self, topic: str, message_encoding: str, schema_id: int,
                         metadata: Mapping[str, str] | None = None) -> int:
        cid = len(self._channels)
        rec = _record(CHANNEL, struct.pack("<HH", cid, schema_id) + _string(topic) + _string(message_encoding)
                      + _string_map(metadata or {}))
        self._channels[cid] = rec
        self._counts[cid] = 0
        self._chunk += rec
        return cid

    def add_message(self, channel_id: int, log_time: int, data: bytes, publish_time: int, sequence: int = 0) -> None:
        chunk = self._chunk
        if not self._chunk_index:
            self._chunk_start = self._chunk_end = log_time
        elif log_time < self._chunk_start:
            self._chunk_start = log_time
        elif log_time > self._chunk_end:
            self._chunk_end = log_time
        index = self._chunk_index.get(channel_id)
        if index is None:
            index = self._chunk_index[channel_id] = []
        index.append((log_time, len(chunk)))
        chunk += _MESSAGE.pack(MESSAGE, MESSAGE_HEAD.size + len(data), channel_id, sequence, log_time, publish_time)
        chunk += data
        self._counts[channel_id] += 1
        if len(chunk) >= self._chunk_size:
            self._end_chunk()

    def add_metadata(self, name: str, data: Mapping[str, str]) -> None:
        self._end_chunk()
        rec = _record(METADATA, _string(name) + _string_map(data))
        self._metadata_indexes.append(_record(METADATA_INDEX, struct.pack("<QQ", self._offset, len(rec))
                                              + _string(name)))
        self._write(rec)

    def flush(self) -> None:
        self._end_chunk()
        self._stream.flush()

    def _end_chunk(self) -> None:
        """Write the chunk in progress (if it holds anything) and its message indexes."""
        if not self._chunk:
            return
        raw = bytes(self._chunk)
        packed = self._zstd.compress(raw)
        body = (struct.pack("<QQQI", self._chunk_start, self._chunk_end, len(raw), zlib.crc32(raw))
                + _string("zstd") + struct.pack("<Q", len(packed)) + packed)
        chunk_offset = self._offset
        self._write(_record(CHUNK, body))
        chunk_length = self._offset - chunk_offset
        offsets = {}
        for cid, entries in sorted(self._chunk_index.items()):
            offsets[cid] = self._offset
            pairs = struct.pack(f"<{2 * len(entries)}Q", *(x for pair in entries for x in pair))
            self._write(_record(MESSAGE_INDEX, struct.pack("<HI", cid, len(pairs)) + pairs))
        if not self._chunk_index:  # a chunk of schemas and channels alone: no times to index
            self._chunk_start = self._chunk_end = 0
        else:
            self._start_time = min(self._chunk_start, self._chunk_start if self._start_time is None
                                   else self._start_time)
            self._end_time = max(self._end_time, self._chunk_end)
        index_map = b"".join(struct.pack("<HQ", cid, off) for cid, off in offsets.items())
        self._chunk_indexes.append(_record(CHUNK_INDEX, struct.pack("<QQQQ", self._chunk_start, self._chunk_end,
                                                                    chunk_offset, chunk_length)
                                           + struct.pack("<I", len(index_map)) + index_map
                                           + struct.pack("<Q", self._offset - chunk_offset - chunk_length)
                                           + _string("zstd") + struct.pack("<QQ", len(packed), len(raw))))
        self._chunk.clear()
        self._chunk_index.clear()

    def finish(self) -> None:
        """End the chunk in progress; write DataEnd, the summary and the footer (the stream
        is left open)."""
        self._end_chunk()
        self._write(_record(DATA_END, struct.pack("<I", self._crc)))
        summary_start = self._offset
        groups: list[tuple[int, list[bytes]]] = [
            (SCHEMA, list(self._schemas.values())), (CHANNEL, list(self._channels.values())),
            (STATISTICS, [self._statistics()]), (CHUNK_INDEX, self._chunk_indexes),
            (METADATA_INDEX, self._metadata_indexes)]
        self._crc = 0  # from here: the summary's CRC
        offsets = []
        for opcode, records in groups:
            if records:
                start = self._offset
                self._write(b"".join(records))
                offsets.append(_record(SUMMARY_OFFSET, struct.pack("<BQQ", opcode, start, self._offset - start)))
        summary_offset_start = self._offset
        self._write(b"".join(offsets))
        footer_head = struct.pack("<BQQQ", FOOTER, 8 + 8 + 4, summary_start, summary_offset_start)
        crc = zlib.crc32(footer_head, self._crc)
        self._stream.write(footer_head + struct.pack("<I", crc) + MAGIC)
        self._stream.flush()

    def _statistics(self) -> bytes:
        counts = b"".join(struct.pack("<HQ", cid, n) for cid, n in sorted(self._counts.items()))
        return _record(STATISTICS, struct.pack("<QHIIII", sum(self._counts.values()), len(self._schemas),
                                               len(self._channels), 0, len(self._metadata_indexes),
                                               len(self._chunk_indexes))
                       + struct.pack("<QQ", self._start_time or 0, self._end_time)
                       + struct.pack("<I", len(counts)) + counts)

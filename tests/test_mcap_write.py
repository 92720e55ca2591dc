"""The recorder's MCAP writer (`conag.recording.mcap_write`) writes files that the `mcap`
package's readers, which nobody here wrote, read whole: indexed (summary, statistics, chunk
and message indexes, metadata), as a stream, and with every CRC checked. The Node reader
(`@mcap/core`) reads a real recording in tests/test_foxglove.py's slow tier."""

from __future__ import annotations

import io

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from mcap.exceptions import EndOfFile
from mcap.reader import make_reader
from mcap.records import Chunk, Footer, Header, Message, Metadata
from mcap.stream_reader import StreamReader

from conag.recording.mcap_write import ChunkedWriter


def _written(messages, chunk_size=64 * 1024, metadata_after=()):
    """A file of two msgpack channels and one with a schema: (bytes, ids)."""
    out = io.BytesIO()
    w = ChunkedWriter(out, chunk_size=chunk_size)
    w.start("conag", "test")
    w.add_metadata("conag", {"seed": "1", "tick_ns": "20000000"})
    a = w.register_channel("w/a", "msgpack", 0, {"type": "SensorFrame"})
    b = w.register_channel("w/b", "msgpack", 0)
    sid = w.register_schema("foxglove.Log", "protobuf", b"\x01\x02schema")
    c = w.register_channel("/log", "protobuf", sid)
    ids = [a, b, c]
    for i, (which, log_time, data) in enumerate(messages):
        w.add_message(ids[which], log_time, data, publish_time=1000 * i, sequence=i + 1)
        if i in metadata_after:
            w.add_metadata(f"m{i}", {"i": str(i)})
    w.add_metadata("conag.end", {"messages": str(len(messages))})
    w.finish()
    return out.getvalue(), ids


MESSAGES = [(i % 3, 1_000 + 7 * i - (5 if i % 4 == 0 else 0), bytes([i % 256]) * (1 + 37 * i % 300))
            for i in range(400)]


def test_an_indexed_reader_finds_every_message_channel_schema_and_metadata_record():
    data, ids = _written(MESSAGES, chunk_size=2048, metadata_after=(100, 250))
    reader = make_reader(io.BytesIO(data), validate_crcs=True)
    summary = reader.get_summary()
    assert summary is not None and len(summary.chunk_indexes) > 10
    assert {c.topic: (c.message_encoding, c.schema_id) for c in summary.channels.values()} == {
        "w/a": ("msgpack", 0), "w/b": ("msgpack", 0), "/log": ("protobuf", summary.channels[ids[2]].schema_id)}
    assert summary.channels[ids[0]].metadata == {"type": "SensorFrame"}
    [schema] = summary.schemas.values()
    assert (schema.name, schema.encoding, schema.data) == ("foxglove.Log", "protobuf", b"\x01\x02schema")
    stats = summary.statistics
    assert stats.message_count == 400 and stats.channel_count == 3 and stats.schema_count == 1
    assert stats.chunk_count == len(summary.chunk_indexes) and stats.metadata_count == 4
    assert stats.channel_message_counts == {ids[k]: sum(1 for m in MESSAGES if m[0] == k) for k in range(3)}
    assert (stats.message_start_time, stats.message_end_time) == (min(m[1] for m in MESSAGES),
                                                                  max(m[1] for m in MESSAGES))
    # in the order written, and in log-time order through the message indexes, one topic at a time
    got = [(c.topic, m.log_time, m.sequence, m.publish_time, m.data)
           for _, c, m in reader.iter_messages(log_time_order=False)]
    assert got == [(["w/a", "w/b", "/log"][k], t, i + 1, 1000 * i, d) for i, (k, t, d) in enumerate(MESSAGES)]
    by_time = [m.log_time for _, _, m in reader.iter_messages(topics=["w/b"], log_time_order=True)]
    assert by_time == sorted(t for k, t, _ in MESSAGES if k == 1)
    assert [m.name for m in reader.iter_metadata()] == ["conag", "m100", "m250", "conag.end"]


def test_a_stream_reader_checking_every_crc_reads_the_file_front_to_back():
    data, _ = _written(MESSAGES, chunk_size=4096, metadata_after=(10,))
    records = list(StreamReader(io.BytesIO(data), validate_crcs=True).records)
    assert isinstance(records[0], Header) and (records[0].profile, records[0].library) == ("conag", "test")
    assert isinstance(records[-1], Footer)
    assert [r.data for r in records if isinstance(r, Message)] == [d for _, _, d in MESSAGES]
    assert [r.name for r in records if isinstance(r, Metadata)] == ["conag", "m10", "conag.end"]


def test_a_flushed_file_ends_on_a_whole_chunk_that_a_stream_reader_reads():
    out = io.BytesIO()
    w = ChunkedWriter(out)
    w.start("conag", "test")
    cid = w.register_channel("w/a", "msgpack", 0)
    for i in range(5):
        w.add_message(cid, i, b"x%d" % i, i, i + 1)
    w.flush()
    chunks = [r for r in _until_the_end(out.getvalue(), emit_chunks=True) if isinstance(r, Chunk)]
    assert len(chunks) == 1
    messages = [r for r in _until_the_end(out.getvalue()) if isinstance(r, Message)]
    assert [m.data for m in messages] == [b"x%d" % i for i in range(5)]


def _until_the_end(data: bytes, **kw) -> list:
    """The records of a file with no footer yet, up to its end (checking every CRC)."""
    out, records = [], StreamReader(io.BytesIO(data), validate_crcs=True, **kw).records
    while True:
        try:
            out.append(next(records))
        except (StopIteration, EndOfFile):
            return out


def test_a_file_without_messages_is_read_whole():
    out = io.BytesIO()
    w = ChunkedWriter(out)
    w.start("conag", "test")
    w.add_metadata("conag", {})
    w.finish()
    summary = make_reader(io.BytesIO(out.getvalue()), validate_crcs=True).get_summary()
    assert summary.statistics.message_count == 0 and not summary.chunk_indexes


@settings(max_examples=30, deadline=None, derandomize=True)
@given(st.lists(st.tuples(st.integers(0, 2), st.integers(0, 2**40), st.binary(max_size=600)), max_size=120),
       st.integers(64, 4096))
def test_any_messages_come_back_as_written_whatever_the_chunk_size(messages, chunk_size):
    data, _ = _written(messages, chunk_size=chunk_size)
    reader = make_reader(io.BytesIO(data), validate_crcs=True)
    got = [(m.log_time, m.data) for _, _, m in reader.iter_messages(log_time_order=False)]
    assert got == [(t, d) for _, t, d in messages]
    assert reader.get_summary().statistics.message_count == len(messages)


def test_a_message_of_an_unknown_channel_is_refused():
    w = ChunkedWriter(io.BytesIO())
    w.start("conag", "test")
    with pytest.raises(KeyError):
        w.add_message(7, 0, b"", 0)

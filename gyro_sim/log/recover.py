"""Recovering a damaged log (SIGKILL, power loss, full disk, flipped bytes): ``gyro-sim recover``.

A gyro_sim log is written as a stream: header, the ``gyro_sim`` metadata and the scene
attachment, then compressed chunks, each holding the schemas and channels it first uses and
its messages, each followed by its message indexes. A run that is killed never writes the
summary and footer, and the chunk in progress at that moment is lost or cut in half; every
chunk before it (at most ``flush_period`` old, 0.25 s by default) is complete.

:func:`recover` reads the file record by record from the start, as MCAP allows without a
summary, and writes everything intact to a new, well-formed file (same schemas, channels,
metadata, attachments and messages in the same order, with a summary and indexes):

- a chunk whose CRC does not match, or that does not decompress or parse, is skipped, and
  reading goes on with the next record: every intact chunk after it is kept. Its messages are
  counted from the message indexes that follow it;
- a record whose header is damaged (unknown opcode, or a length running past the end) is
  skipped by searching forward for the next well-formed chunk record; when there is none, the
  file is taken as cut short there;
- channels declared only in a skipped chunk are taken from the input's summary when it has
  one (a complete file with damaged chunks).

The input is never modified, and the output may not be the input (by identity: a hard link or
symlink to the input is refused too, :mod:`.safe_paths`).

(``rerun mcap convert --recover`` also reads such files, in memory, for viewing only.)
"""
from __future__ import annotations

import io
import mmap
import os
from dataclasses import dataclass, field
from pathlib import Path

from gyro_sim.log.mcap_log import OP_CHUNK, ChunkError, LogError, chunk_records, decode_chunk
from gyro_sim.safe_paths import OutputError, check_output

#: MCAP magic (8 bytes) at both ends of a file
MAGIC = b"\x89MCAP0\r\n"
#: opcodes of the MCAP specification (header 1 ... summary offset 14, data end 15)
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE = 1, 2, 3, 4, 5
OP_MESSAGE_INDEX, OP_ATTACHMENT, OP_METADATA, OP_DATA_END = 7, 9, 12, 15
KNOWN_OPCODES = frozenset(range(1, 16))
#: compression names a chunk may carry (MCAP specification)
COMPRESSIONS = (b"", b"lz4", b"zstd")
#: fixed part of a chunk record's body before its compression string: start, end, size, crc
CHUNK_FIXED = 8 + 8 + 8 + 4
#: at most this many damaged places are listed in the report (all are counted)
REPORT_DAMAGE = 5


@dataclass
class Recovery:
    """What was recovered."""

    messages: int = 0
    start_ns: int | None = None
    end_ns: int | None = None
    channels: int = 0
    metadata: int = 0
    attachments: int = 0
    chunks: int = 0  # intact chunks kept
    skipped_chunks: int = 0  # damaged chunks skipped
    skipped_messages: int = 0  # messages in them (from their message indexes)
    skipped_unknown: int = 0  # damaged chunks whose message count is unknown (index lost too)
    skipped_records: int = 0  # other damaged records skipped
    orphans: int = 0  # messages of channels declared nowhere readable (dropped)
    damage: list = field(default_factory=list)  # (byte offset, what) of each damaged place
    complete: bool = False  # the input had its footer
    stopped_at: int = 0  # byte offset where reading stopped (the size when complete)
    size: int = 0  # bytes of the input
    reason: str = ""  # why reading stopped before the footer
    per_topic: dict = field(default_factory=dict)

    def report(self) -> str:
        span = 0.0 if self.start_ns is None else (self.end_ns - self.start_ns) / 1e9
        t0 = 0.0 if self.start_ns is None else self.start_ns / 1e9
        t1 = 0.0 if self.end_ns is None else self.end_ns / 1e9
        lines = [
            f"recovered {self.messages} messages in {self.chunks} chunks on {self.channels} channels, "
            f"log time {t0:.6g} .. {t1:.6g} s ({span:.6g} s), {self.metadata} metadata and "
            f"{self.attachments} attachments",
            f"skipped {self.skipped_chunks} damaged chunks holding {self.skipped_messages} messages"
            + (f" (and {self.skipped_unknown} chunks whose message count was lost)" if self.skipped_unknown else "")
            + (f", {self.skipped_records} other damaged records" if self.skipped_records else "")
            + (f", {self.orphans} messages of undeclared channels" if self.orphans else ""),
        ]
        for offset, what in self.damage[:REPORT_DAMAGE]:
            lines.append(f"  at byte {offset}: {what}")
        if len(self.damage) > REPORT_DAMAGE:
            lines.append(f"  ... and {len(self.damage) - REPORT_DAMAGE} more")
        lines.append("the input was complete (it had its footer)" if self.complete else
                     f"the input is cut short at byte {self.stopped_at} of {self.size} ({self.reason}): "
                     f"{self.size - self.stopped_at} bytes dropped")
        return "\n".join(lines)


def _u32(m, pos: int) -> int:
    return int.from_bytes(m[pos:pos + 4], "little")


def _u64(m, pos: int) -> int:
    return int.from_bytes(m[pos:pos + 8], "little")


def _is_chunk_at(m, q: int, size: int) -> bool:
    """Whether a well-formed chunk record header starts at byte `q` (lengths consistent)."""
    if q + 9 + CHUNK_FIXED + 4 > size or m[q] != OP_CHUNK:
        return False
    length = _u64(m, q + 1)
    if q + 9 + length > size:
        return False
    c = _u32(m, q + 9 + CHUNK_FIXED)
    if c > 4 or q + 9 + CHUNK_FIXED + 4 + c + 8 > size:
        return False
    name = bytes(m[q + 9 + CHUNK_FIXED + 4:q + 9 + CHUNK_FIXED + 4 + c])
    if name not in COMPRESSIONS:
        return False
    data_length = _u64(m, q + 9 + CHUNK_FIXED + 4 + c)
    return CHUNK_FIXED + 4 + c + 8 + data_length == length


def _next_chunk(m, start: int, size: int) -> int | None:
    """Offset of the next well-formed chunk record at or after `start`, or None."""
    q = start
    while True:
        q = m.find(bytes([OP_CHUNK]), q, size)
        if q < 0:
            return None
        if _is_chunk_at(m, q, size):
            return q
        q += 1


def _summary_definitions(f):
    """(schemas, channels) by id from the input's summary, or empty dicts if it has none."""
    from mcap.reader import make_reader

    try:
        summary = make_reader(f).get_summary()
    except Exception:  # noqa: BLE001 - no or damaged summary: nothing to fall back on
        summary = None
    finally:
        f.seek(0)
    if summary is None:
        return {}, {}
    return dict(summary.schemas), dict(summary.channels)


def recover(src: str | os.PathLike, dst: str | os.PathLike, *, overwrite: bool = False) -> Recovery:
    """Rewrite what is intact in `src` as a well-formed MCAP file `dst` (module docstring).

    `dst` may not exist unless `overwrite`, and may never be `src` (OutputError, a ValueError).
    LogError if `src` is not an MCAP file at all.
    """
    from mcap.data_stream import ReadDataStream
    from mcap.records import Attachment, Channel, Header, Message, MessageIndex, Metadata, Schema
    from mcap.writer import Writer

    from gyro_sim.log.mcap_log import CHUNK_SIZE, _compression

    src, dst = Path(src), Path(dst)
    check_output(dst, inputs=[src], force=overwrite)
    out = Recovery(size=src.stat().st_size)
    with open(src, "rb") as f:
        if out.size < len(MAGIC) or f.read(len(MAGIC)) != MAGIC:
            raise LogError(f"{src}: not an MCAP file (no MCAP magic at its start)")
        fallback_schemas, fallback_channels = _summary_definitions(f)
        m = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
        try:
            _scan(m, out, dst, overwrite, fallback_schemas, fallback_channels,
                  (ReadDataStream, Attachment, Channel, Header, Message, MessageIndex, Metadata, Schema),
                  lambda g: Writer(g, chunk_size=CHUNK_SIZE, compression=_compression()))
        finally:
            m.close()
    return out


def _scan(m, out: Recovery, dst: Path, overwrite: bool, fallback_schemas, fallback_channels, records, new_writer):
    ReadDataStream, Attachment, Channel, Header, Message, MessageIndex, Metadata, Schema = records
    size = out.size
    new_schema: dict[int, int] = {}
    new_channel: dict[int, int] = {}
    topics: dict[int, str] = {}
    try:
        g = open(dst, "wb" if overwrite else "xb")
    except FileExistsError:
        raise OutputError(f"output {dst}: exists; refused to overwrite it (use --force)") from None
    with g:
        writer = new_writer(g)
        started = False

        def start(profile="", library="gyro_sim recover"):
            nonlocal started
            if not started:
                writer.start(profile=profile, library=library)
                started = True

        def schema(rec):
            if rec.id not in new_schema:
                new_schema[rec.id] = writer.register_schema(rec.name, rec.encoding, rec.data)

        def channel(rec):
            if rec.id in new_channel:
                return
            if rec.schema_id and rec.schema_id not in new_schema and rec.schema_id in fallback_schemas:
                schema(fallback_schemas[rec.schema_id])
            new_channel[rec.id] = writer.register_channel(rec.topic, rec.message_encoding,
                                                          new_schema.get(rec.schema_id, 0), dict(rec.metadata))
            topics[rec.id] = rec.topic
            out.channels += 1

        def message(rec):
            if rec.channel_id not in new_channel and rec.channel_id in fallback_channels:
                channel(fallback_channels[rec.channel_id])
            cid = new_channel.get(rec.channel_id)
            if cid is None:
                out.orphans += 1
                return
            writer.add_message(cid, rec.log_time, rec.data, rec.publish_time, rec.sequence)
            out.messages += 1
            out.start_ns = rec.log_time if out.start_ns is None else min(out.start_ns, rec.log_time)
            out.end_ns = rec.log_time if out.end_ns is None else max(out.end_ns, rec.log_time)
            topic = topics[rec.channel_id]
            out.per_topic[topic] = out.per_topic.get(topic, 0) + 1

        pos = len(MAGIC)
        # a skipped chunk's messages are counted from the message indexes that follow it
        skip = {"open": False, "counted": False}

        def close_skip():
            if skip["open"] and not skip["counted"]:
                out.skipped_unknown += 1
            skip["open"] = skip["counted"] = False

        while True:
            if pos >= size:
                out.stopped_at, out.reason = size, "no footer"
                break
            if pos + 9 > size:
                out.stopped_at, out.reason = pos, "incomplete record header"
                break
            op, length = m[pos], _u64(m, pos + 1)
            end = pos + 9 + length
            if op not in KNOWN_OPCODES or end > size:
                nxt = _next_chunk(m, pos + 1, size)
                if nxt is None:  # nothing well-formed after: the file is cut short here
                    out.stopped_at = pos
                    out.reason = ("incomplete record (cut short)" if op in KNOWN_OPCODES
                                  else f"unreadable record (opcode {op:#04x}) with no intact chunk after it")
                    break
                out.damage.append((pos, f"damaged record header (opcode {op:#04x}, length {length}): "
                                        f"{nxt - pos} bytes skipped to the next chunk"))
                out.skipped_records += 1
                close_skip()
                pos = nxt
                continue
            body = m[pos + 9:end]
            stream = ReadDataStream(io.BytesIO(body))
            try:
                if op == OP_CHUNK:
                    from mcap.records import Chunk

                    close_skip()
                    try:
                        chunk = Chunk.read(stream)
                        recs = chunk_records(chunk, decode_chunk(chunk))
                    except ChunkError:
                        raise
                    except Exception as exc:  # noqa: BLE001 - a damaged chunk header
                        raise ChunkError(f"unreadable chunk header ({type(exc).__name__}: {exc})") from None
                    start()
                    for rec in recs:
                        if isinstance(rec, Schema):
                            schema(rec)
                        elif isinstance(rec, Channel):
                            channel(rec)
                        elif isinstance(rec, Message):
                            message(rec)
                    out.chunks += 1
                elif op == OP_MESSAGE_INDEX:
                    if skip["open"]:
                        out.skipped_messages += len(MessageIndex.read(stream).records)
                        skip["counted"] = True
                elif op == OP_HEADER:
                    h = Header.read(stream)
                    start(h.profile, h.library)
                elif op == OP_FOOTER:
                    out.complete = True
                    out.stopped_at = size
                    break
                elif op == OP_DATA_END:  # the summary after it repeats what the data section held
                    out.complete = True
                    out.stopped_at = size
                    break
                else:
                    start()
                    if op == OP_SCHEMA:
                        schema(Schema.read(stream))
                    elif op == OP_CHANNEL:
                        channel(Channel.read(stream))
                    elif op == OP_MESSAGE:
                        message(Message.read(stream, length))
                    elif op == OP_METADATA:
                        rec = Metadata.read(stream)
                        writer.add_metadata(rec.name, dict(rec.metadata))
                        out.metadata += 1
                    elif op == OP_ATTACHMENT:
                        rec = Attachment.read(stream)
                        writer.add_attachment(rec.create_time, rec.log_time, rec.name, rec.media_type, rec.data)
                        out.attachments += 1
            except ChunkError as exc:
                out.damage.append((pos, f"chunk skipped: {exc}"))
                out.skipped_chunks += 1
                skip["open"] = True
            except Exception as exc:  # noqa: BLE001 - any other damaged record
                out.damage.append((pos, f"record (opcode {op:#04x}) skipped: {type(exc).__name__}: {exc}"))
                out.skipped_records += 1
            pos = end
        close_skip()
        start()
        writer.finish()

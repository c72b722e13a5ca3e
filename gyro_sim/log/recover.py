"""Recovering a damaged log (SIGKILL, power loss, full disk, flipped bytes): ``gyro-sim recover``.

A gyro_sim log is written as a stream: header, the ``gyro_sim`` metadata and the scene
attachment, then compressed chunks, each holding the schemas and channels it first uses and
its messages, each followed by its message indexes; a complete file ends with the summary
(schemas, channels, chunk indexes, statistics: its CRC is in the footer) and the footer. A run
that is killed never writes the summary and footer, and the chunk in progress at that moment
is lost or cut in half; every chunk before it (at most ``flush_period`` old) is complete.

:func:`recover` reads the file record by record from the start, as MCAP allows without a
summary, and writes everything intact to a new, well-formed file (same schemas, channels,
metadata, attachments and messages in the same order, with a summary and indexes):

- every chunk is checked (its CRC, that it decompresses and parses); a damaged one is skipped
  and every intact chunk after it is kept. A chunk's end is taken from its own fields (checked
  against its record length), so a damaged length does not lose the chunks after it;
- a record whose header is damaged (unknown opcode, a length running past the end or not
  matching what the record holds) is skipped by searching forward, from just after the last
  record known good, for the next chunk that checks; when there is none the file is taken as
  cut short there (or, with an intact summary, as complete up to its data section's end);
- an attachment is kept only if its CRC checks; the summary is used only if its CRC checks:
  then it supplies the definitions of channels declared only in a skipped chunk, and the exact
  number of messages lost;
- the header and metadata records have no CRC in MCAP: they are copied as read when they parse
  exactly.

What was skipped is said in one line (chunks, records, bytes, messages lost as far as known,
and where). The output is written under a temporary name and published only when complete
(:func:`.safe_paths.atomic_output`): an interruption leaves nothing under the output's name.
The input is never modified, and the output may not be the input (by identity: a hard link or
symlink to the input is refused too).

(``rerun mcap convert --recover`` also reads such files, in memory, for viewing only.)
"""
from __future__ import annotations

import io
import mmap
import os
import zlib
from dataclasses import dataclass, field
from pathlib import Path

from gyro_sim.progress import plural
from gyro_sim.log.mcap_log import OP_CHUNK, ChunkError, LogError, chunk_records, decode_chunk
from gyro_sim.safe_paths import atomic_output, check_output, raise_interrupt_behind

#: MCAP magic (8 bytes) at both ends of a file
MAGIC = b"\x89MCAP0\r\n"
#: opcodes of the MCAP specification (header 1 ... summary offset 14, data end 15)
OP_HEADER, OP_FOOTER, OP_SCHEMA, OP_CHANNEL, OP_MESSAGE = 1, 2, 3, 4, 5
OP_MESSAGE_INDEX, OP_ATTACHMENT, OP_METADATA, OP_DATA_END = 7, 9, 12, 15
KNOWN_OPCODES = frozenset(range(1, 16))
#: compression names a chunk may carry (MCAP specification)
COMPRESSIONS = (b"", b"lz4", b"zstd")
#: bytes of a record's opcode and length
RECORD_HEAD = 1 + 8
#: fixed part of a chunk record's body before its compression string: start, end, size, crc
CHUNK_FIXED = 8 + 8 + 8 + 4
#: the footer record: opcode, length, summary start, summary offset start, summary CRC
FOOTER_BYTES = RECORD_HEAD + 8 + 8 + 4
#: the data end record: opcode, length, data section CRC
DATA_END_BYTES = RECORD_HEAD + 4
#: a message index entry: log time and offset
MESSAGE_INDEX_ENTRY = 8 + 8
#: a message index's fixed part: channel id and the byte length of its entries
MESSAGE_INDEX_FIXED = 2 + 4
#: summary records read (MCAP specification)
OP_CHUNK_INDEX, OP_STATISTICS = 8, 11
#: at most this many damaged places are named in the report (all are counted)
REPORT_DAMAGE = 5


@dataclass
class Recovery:
    """What was recovered, and what was skipped."""

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
    skipped_bytes: int = 0  # bytes of the input not used because damaged
    orphans: int = 0  # messages of channels declared nowhere readable (dropped)
    damage: list = field(default_factory=list)  # (byte offset, what) of each damaged place
    complete: bool = False  # the input had its end (data end record, or an intact summary)
    stopped_at: int = 0  # byte offset where reading stopped (the size when complete)
    size: int = 0  # bytes of the input
    reason: str = ""  # why reading stopped before the end
    summary: str = "absent"  # the input's summary: "intact", "absent" or "damaged"
    summary_messages: int | None = None  # message count of the input's intact summary
    per_topic: dict = field(default_factory=dict)

    @property
    def damaged(self) -> bool:
        """Whether anything in the input failed a check."""
        return bool(self.damage)

    @property
    def lost(self) -> int | None:
        """Messages of the input not in the output: exact with an intact summary, else those
        counted by the message indexes of skipped chunks and orphans (None: some count lost)."""
        if self.summary_messages is not None:
            return self.summary_messages - self.messages
        return None if self.skipped_unknown else self.skipped_messages + self.orphans

    def skipped_line(self) -> str:
        """One line: what was skipped, how much, and where."""
        if not self.damaged:
            return "nothing damaged: every chunk's CRC checked" + (
                ", and the summary's" if self.summary == "intact" else "")
        lost = self.lost
        counted = self.skipped_messages + self.orphans
        if lost is not None:
            lost_text = f"{plural(lost, 'message')} lost"
        else:
            lost_text = (f"at least {plural(counted, 'message')} lost ({plural(self.skipped_unknown, 'chunk')} "
                         "whose message count was lost with them)")
        where = "; ".join(f"at byte {offset}: {what}" for offset, what in self.damage[:REPORT_DAMAGE])
        more = f"; ... and {len(self.damage) - REPORT_DAMAGE} more" if len(self.damage) > REPORT_DAMAGE else ""
        return (f"skipped {plural(self.skipped_chunks, 'damaged chunk')} and "
                f"{plural(self.skipped_records, 'other damaged record')} ({plural(self.skipped_bytes, 'byte')}): "
                f"{lost_text}"
                + (f" ({self.orphans} of them of channels declared only in a skipped chunk)" if self.orphans else "")
                + f"; {where}{more}")

    def report(self) -> str:
        span = 0.0 if self.start_ns is None else (self.end_ns - self.start_ns) / 1e9
        t0 = 0.0 if self.start_ns is None else self.start_ns / 1e9
        t1 = 0.0 if self.end_ns is None else self.end_ns / 1e9
        lines = [
            f"recovered {self.messages} messages in {self.chunks} chunks on {self.channels} channels, "
            f"log time {t0:.6g} .. {t1:.6g} s ({span:.6g} s), {self.metadata} metadata and "
            f"{self.attachments} attachments",
            self.skipped_line(),
        ]
        if not self.complete:
            lines.append(f"the input is cut short at byte {self.stopped_at} of {self.size} ({self.reason}): "
                         f"{self.size - self.stopped_at} bytes dropped")
        elif self.damaged:
            lines.append("the input was complete (it had its end) but damaged: the output holds its intact part only")
        else:
            lines.append("the input was complete (it had its end) and intact: the output holds the same messages")
        return "\n".join(lines)


def _u32(m, pos: int) -> int:
    return int.from_bytes(m[pos:pos + 4], "little")


def _u64(m, pos: int) -> int:
    return int.from_bytes(m[pos:pos + 8], "little")


def _chunk_end(m, q: int, size: int) -> int | None:
    """End offset of a chunk record at byte `q` computed from its own fields (compression name
    one of MCAP's, data length within the file), or None if its header is not well-formed."""
    head = q + RECORD_HEAD + CHUNK_FIXED
    if head + 4 > size or m[q] != OP_CHUNK:
        return None
    c = _u32(m, head)
    if c > 4 or head + 4 + c + 8 > size:
        return None
    if bytes(m[head + 4:head + 4 + c]) not in COMPRESSIONS:
        return None
    end = head + 4 + c + 8 + _u64(m, head + 4 + c)
    return end if end <= size else None


def _is_chunk_at(m, q: int, size: int) -> bool:
    """Whether a well-formed chunk record header starts at byte `q` (its record length and its
    own fields agree)."""
    end = _chunk_end(m, q, size)
    return end is not None and end == q + RECORD_HEAD + _u64(m, q + 1)


class _Strict(io.BytesIO):
    """Bytes that refuse a short read (mcap's readers take what is there)."""

    def read(self, n: int = -1) -> bytes:
        data = super().read(n)
        if n is not None and n >= 0 and len(data) != n:
            raise EOFError(f"record ends {n - len(data)} bytes early")
        return data


def _parse_exact(cls, body: bytes):
    """`cls.read` over the whole of `body`: ValueError unless it reads exactly all of it."""
    from mcap.data_stream import ReadDataStream

    stream = ReadDataStream(_Strict(body))
    try:
        rec = cls.read(stream)
    except Exception as exc:  # noqa: BLE001 - mcap's readers fail in many ways on bad bytes
        raise_interrupt_behind(exc)
        raise ValueError(f"does not parse ({type(exc).__name__}: {exc})") from None
    if stream.count != len(body):
        raise ValueError(f"its fields take {stream.count} of its {len(body)} bytes")
    return rec


def _summary(m, size: int):
    """(state, summary, data end) from the input's footer: "intact" with the mcap Summary and
    the offset where the summary starts when the footer is there and the summary's CRC
    checks; "absent" or "damaged" (with why) and None otherwise."""
    footer = size - len(MAGIC) - FOOTER_BYTES
    if footer < len(MAGIC):
        return "absent", None, None
    magic = bytes(m[size - len(MAGIC):size]) == MAGIC
    record = m[footer] == OP_FOOTER and _u64(m, footer + 1) == FOOTER_BYTES - RECORD_HEAD
    if not (magic or record):
        return "absent", None, None  # cut short: no footer
    if not record:
        return "damaged", "the footer record is damaged (the magic after it is there)", None
    start = _u64(m, footer + RECORD_HEAD)
    crc = _u32(m, footer + RECORD_HEAD + 16)
    if start == 0:
        return "absent", None, None
    if not len(MAGIC) < start <= footer:
        return "damaged", f"the footer's summary offset {start} is not in the file", None
    if crc == 0:
        return "absent", None, None  # written without CRCs: nothing trustworthy to fall back on
    computed = zlib.crc32(m[start:footer + FOOTER_BYTES - 4])
    if computed != crc:
        return "damaged", f"summary CRC mismatch (stored {crc:#010x}, computed {computed:#010x})", None
    try:
        summary = _read_summary(m, start, footer)
    except ValueError as exc:  # an intact CRC over records that do not parse
        return "damaged", f"summary does not parse ({exc})", None
    if not magic:
        return "intact, magic damaged", summary, start
    return "intact", summary, start


def _read_summary(m, start: int, footer: int):
    """The summary section's records, read without copying the data section."""
    from mcap.records import Channel, ChunkIndex, Schema, Statistics
    from mcap.summary import Summary

    summary = Summary()
    pos = start
    while pos < footer:
        op, length = m[pos], _u64(m, pos + 1)
        if pos + RECORD_HEAD + length > footer:
            raise ValueError(f"a record at byte {pos} runs past the footer")
        body = bytes(m[pos + RECORD_HEAD:pos + RECORD_HEAD + length])
        if op == OP_SCHEMA:
            rec = _parse_exact(Schema, body)
            summary.schemas[rec.id] = rec
        elif op == OP_CHANNEL:
            rec = _parse_exact(Channel, body)
            summary.channels[rec.id] = rec
        elif op == OP_CHUNK_INDEX:
            summary.chunk_indexes.append(_parse_exact(ChunkIndex, body))
        elif op == OP_STATISTICS:
            summary.statistics = _parse_exact(Statistics, body)
        pos += RECORD_HEAD + length
    return summary


def recover(src: str | os.PathLike, dst: str | os.PathLike, *, overwrite: bool = False) -> Recovery:
    """Rewrite what is intact in `src` as a well-formed MCAP file `dst` (module docstring).

    `dst` may not exist unless `overwrite`, and may never be `src` (OutputError, a ValueError;
    also when another writer creates `dst` meanwhile). LogError if `src` is not an MCAP file at
    all. An exception (KeyboardInterrupt included) leaves nothing at `dst`.
    """
    src, dst = Path(src), Path(dst)
    check_output(dst, inputs=[src], force=overwrite)
    with open(src, "rb") as f:
        size = os.fstat(f.fileno()).st_size
        out = Recovery(size=size)
        head = f.read(len(MAGIC) + 1)
        if len(head) < len(MAGIC) + 1:
            raise LogError(f"{src}: not an MCAP file ({size} bytes: shorter than a header)")
        if head[:len(MAGIC)] != MAGIC:
            if head[len(MAGIC)] != OP_HEADER:
                raise LogError(f"{src}: not an MCAP file (no MCAP magic at its start, and no header after it)")
            out.damage.append((0, "the magic at the start is damaged (the header after it is there)"))
            out.skipped_bytes += len(MAGIC)
        m = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
        try:
            with atomic_output(dst, inputs=[src], force=overwrite) as target:
                with open(target.tmp, "wb") as g:
                    _Scan(m, out, g).run()
        finally:
            m.close()
    return out


class _Scan:
    """One pass over the input `m` (an mmap), writing what is intact to the file `g`."""

    def __init__(self, m, out: Recovery, g):
        from mcap.writer import Writer

        from gyro_sim.log.mcap_log import CHUNK_SIZE, compression

        self.m, self.out, self.size = m, out, out.size
        self.writer = Writer(g, chunk_size=CHUNK_SIZE, compression=compression())
        self.started = False
        self.new_schema: dict[int, int] = {}
        self.new_channel: dict[int, int] = {}
        self.topics: dict[int, str] = {}
        state, summary, data_end = _summary(m, self.size)
        if state == "intact, magic damaged":
            state = "intact"
            out.damage.append((self.size - len(MAGIC), "the magic at the end is damaged (the footer before it "
                                                       "and the summary check)"))
            out.skipped_bytes += len(MAGIC)
        out.summary = state
        if state == "damaged":
            out.damage.append((self.size - len(MAGIC) - FOOTER_BYTES, f"summary not used: {summary}"))
            out.skipped_records += 1
            summary = None
        self.fallback_schemas = dict(summary.schemas) if summary is not None else {}
        self.fallback_channels = dict(summary.channels) if summary is not None else {}
        if summary is not None and summary.statistics is not None:
            out.summary_messages = summary.statistics.message_count
        # the data section ends where the summary starts (its data end record just before)
        self.limit = data_end if data_end is not None else self.size
        self.skip_open = False  # a skipped chunk whose message indexes may follow
        self.skip_counted = False
        # channel id -> [(log time, offset)] of the last chunk kept, checked against its indexes
        self.expected_index: dict | None = None

    # --- writing -------------------------------------------------------------------------------
    def start(self, profile: str = "", library: str = "gyro_sim recover") -> None:
        if not self.started:
            self.writer.start(profile=profile, library=library)
            self.started = True

    def schema(self, rec) -> None:
        if rec.id not in self.new_schema:
            self.new_schema[rec.id] = self.writer.register_schema(rec.name, rec.encoding, rec.data)

    def channel(self, rec) -> None:
        if rec.id in self.new_channel:
            return
        if rec.schema_id and rec.schema_id not in self.new_schema and rec.schema_id in self.fallback_schemas:
            self.schema(self.fallback_schemas[rec.schema_id])
        self.new_channel[rec.id] = self.writer.register_channel(
            rec.topic, rec.message_encoding, self.new_schema.get(rec.schema_id, 0), dict(rec.metadata))
        self.topics[rec.id] = rec.topic
        self.out.channels += 1

    def message(self, rec) -> None:
        out = self.out
        if rec.channel_id not in self.new_channel and rec.channel_id in self.fallback_channels:
            self.channel(self.fallback_channels[rec.channel_id])
        cid = self.new_channel.get(rec.channel_id)
        if cid is None:
            out.orphans += 1
            return
        self.writer.add_message(cid, rec.log_time, rec.data, rec.publish_time, rec.sequence)
        out.messages += 1
        out.start_ns = rec.log_time if out.start_ns is None else min(out.start_ns, rec.log_time)
        out.end_ns = rec.log_time if out.end_ns is None else max(out.end_ns, rec.log_time)
        topic = self.topics[rec.channel_id]
        out.per_topic[topic] = out.per_topic.get(topic, 0) + 1

    # --- damage --------------------------------------------------------------------------------
    def close_skip(self) -> None:
        if self.skip_open and not self.skip_counted:
            self.out.skipped_unknown += 1
        self.skip_open = self.skip_counted = False

    def skipped_chunk(self, pos: int, end: int, why: str) -> None:
        self.close_skip()
        self.expected_index = None
        self.out.damage.append((pos, f"chunk skipped: {why}"))
        self.out.skipped_chunks += 1
        self.out.skipped_bytes += end - pos
        self.skip_open = True

    def unused_damage(self, pos: int, what: str) -> None:
        """Damage in a field that is not copied (indexes and ranges the writer rebuilds)."""
        self.out.damage.append((pos, what))
        self.out.skipped_records += 1

    def skipped_record(self, pos: int, end: int, what: str) -> None:
        self.out.damage.append((pos, what))
        self.out.skipped_records += 1
        self.out.skipped_bytes += end - pos

    def resync(self, pos: int, from_: int, what: str) -> int | None:
        """Offset of the next chunk at or after `from_` that decodes and checks, the bytes up to
        it counted as skipped from `pos`; None if there is none before the data section's end."""
        q = from_
        while True:
            q = self.m.find(bytes([OP_CHUNK]), q, self.limit)
            if q < 0:
                return None
            if _is_chunk_at(self.m, q, self.limit) and self.decodes(q):
                self.close_skip()
                # q < pos: the record before `pos` claimed too many bytes; none are lost
                self.skipped_record(pos, max(q, pos), f"{what}: {max(q - pos, 0)} bytes skipped to the next "
                                                      f"intact chunk, at byte {q}")
                return q
            q += 1

    def decodes(self, q: int) -> bool:
        try:
            self.chunk_records(q, _chunk_end(self.m, q, self.limit))
            return True
        except ChunkError:
            return False

    def chunk_records(self, pos: int, end: int) -> tuple:
        """(chunk, its records, its uncompressed bytes) of the chunk record at `pos` taken to end
        at `end` (its data: what lies between its data length field and `end`); ChunkError if
        it does not parse, decompress or check."""
        from mcap.records import Chunk

        m = self.m
        head = pos + RECORD_HEAD + CHUNK_FIXED
        c = _u32(m, head)
        start = head + 4 + c + 8
        if not start <= end <= self.size:
            raise ChunkError("unreadable chunk header (its data would end before it starts)")
        chunk = Chunk(compression=bytes(m[head + 4:head + 4 + c]).decode(),
                      data=bytes(m[start:end]), message_start_time=_u64(m, pos + RECORD_HEAD),
                      message_end_time=_u64(m, pos + RECORD_HEAD + 8),
                      uncompressed_size=_u64(m, pos + RECORD_HEAD + 16),
                      uncompressed_crc=_u32(m, pos + RECORD_HEAD + 24))
        data = decode_chunk(chunk)
        return chunk, chunk_records(chunk, data), data

    def plausible_record_at(self, q: int) -> bool:
        """Whether a record can start at `q`: the data section's end, or a known opcode (its own
        length is checked when it is read: a record is not blamed for its successor's)."""
        if q == self.limit or q == self.size - len(MAGIC):
            return True
        return q < self.size and self.m[q] in KNOWN_OPCODES

    # --- the pass ------------------------------------------------------------------------------
    def run(self) -> None:
        from mcap.records import Attachment, Channel, Header, Message, MessageIndex, Metadata, Schema

        m, out, size = self.m, self.out, self.size
        pos = len(MAGIC)
        # start of the record before `pos` when its length decided where `pos` is (None after a
        # chunk, whose end its own fields fix): a search after damage starts just after it
        prev = None
        while True:
            if pos >= self.limit:
                if self.limit < size:  # the data end record was damaged: the summary marks the end
                    out.complete = True
                    out.stopped_at = size
                else:
                    out.stopped_at, out.reason = size, "no footer"
                break
            if pos + RECORD_HEAD > self.limit:
                out.stopped_at, out.reason = pos, "incomplete record header"
                break
            op, length = m[pos], _u64(m, pos + 1)
            end = pos + RECORD_HEAD + length
            fits = op in KNOWN_OPCODES and end <= self.limit and self.plausible_record_at(end)
            nxt = None
            if op == OP_CHUNK and _chunk_end(m, pos, self.limit) is not None:
                nxt = self.chunk(pos, end)
                damage = "damaged chunk header"
            elif op == OP_CHUNK and fits:  # its fields are damaged, its length leads to a record
                self.skipped_chunk(pos, end, "damaged chunk header")
                nxt = end
            elif fits:
                self.record(op, pos, end, (Attachment, Channel, Header, Message, MessageIndex, Metadata, Schema))
                if out.complete:
                    break
                nxt = end
            else:
                damage = f"damaged record header (opcode {op:#04x}, length {length})"
            if nxt is None:  # damage with no known end: search for the next intact chunk
                nxt = self.resync(pos, (pos if prev is None else prev) + 1, damage)
                if nxt is None:
                    self.cut_or_end(pos, "incomplete record (cut short)" if op in KNOWN_OPCODES and end > size
                                    else f"{damage}, with no intact chunk after it")
                    break
                prev = None
            else:
                prev = None if op == OP_CHUNK else pos
            pos = nxt
        self.close_skip()
        self.start()
        self.writer.finish()

    def record(self, op: int, pos: int, end: int, types) -> None:
        """Use the record (not a chunk) at `pos`; one that does not parse exactly is skipped."""
        Attachment, Channel, Header, Message, MessageIndex, Metadata, Schema = types
        out = self.out
        length = end - pos - RECORD_HEAD
        body = bytes(self.m[pos + RECORD_HEAD:end])
        if op != OP_MESSAGE_INDEX:  # a chunk's message indexes follow it directly
            self.expected_index = None
        try:
            if op == OP_MESSAGE_INDEX:
                if length < MESSAGE_INDEX_FIXED or (length - MESSAGE_INDEX_FIXED) % MESSAGE_INDEX_ENTRY:
                    raise ValueError(f"length {length} is not that of a message index")
                rec = _parse_exact(MessageIndex, body)
                if self.skip_open:
                    out.skipped_messages += len(rec.records)
                    self.skip_counted = True
                elif self.expected_index is not None and \
                        self.expected_index.pop(rec.channel_id, None) != list(rec.records):
                    self.unused_damage(pos, "message index damaged: it does not match its chunk (not copied: "
                                            "the output's indexes are rebuilt)")
            elif op == OP_HEADER:
                h = _parse_exact(Header, body)
                self.start(h.profile, h.library)
            elif op in (OP_FOOTER, OP_DATA_END):  # the summary after it repeats the data section
                out.complete = True
                out.stopped_at = self.size
                stored = int.from_bytes(body[:4], "little") if op == OP_DATA_END and length == 4 else 0
                if stored:  # written by writers with data CRCs on (gyro_sim's are off: 0)
                    with memoryview(self.m) as view, view[:pos] as data:  # no copy of the data section
                        computed = zlib.crc32(data)
                    if computed != stored:
                        self.unused_damage(pos, f"data section CRC mismatch (stored {stored:#010x}, computed "
                                                f"{computed:#010x}): a record without a CRC of its own "
                                                "(header, metadata) may be damaged")
            elif op == OP_SCHEMA:
                self.start()
                self.schema(_parse_exact(Schema, body))
            elif op == OP_CHANNEL:
                self.start()
                self.channel(_parse_exact(Channel, body))
            elif op == OP_MESSAGE:
                self.start()
                self.message(Message.read(_stream(body), length))
            elif op == OP_METADATA:
                rec = _parse_exact(Metadata, body)
                self.start()
                self.writer.add_metadata(rec.name, dict(rec.metadata))
                out.metadata += 1
            elif op == OP_ATTACHMENT:
                rec = _parse_exact(Attachment, body)
                stored, computed = int.from_bytes(body[-4:], "little"), zlib.crc32(body[:-4])
                if stored and stored != computed:
                    raise ValueError(f"CRC mismatch (stored {stored:#010x}, computed {computed:#010x})")
                self.start()
                self.writer.add_attachment(rec.create_time, rec.log_time, rec.name, rec.media_type, rec.data)
                out.attachments += 1
        except (ValueError, EOFError) as exc:
            what = {OP_ATTACHMENT: "attachment", OP_METADATA: "metadata", OP_HEADER: "header",
                    OP_MESSAGE_INDEX: "message index"}.get(op, f"record (opcode {op:#04x})")
            self.skipped_record(pos, end, f"{what} skipped: {exc}")

    def chunk(self, pos: int, end: int) -> int | None:
        """Keep or skip the chunk at `pos`; the offset after it, or None if its end is unknown."""
        inner = _chunk_end(self.m, pos, self.limit)
        # its record length and its data length field disagree: one of them is damaged, and
        # the data that decodes and checks tells which (the record length first)
        ends = [end] if inner == end else [e for e in (end, inner) if e <= self.limit]
        first = None
        for candidate in ends:
            try:
                chunk, recs, data = self.chunk_records(pos, candidate)
                break
            except ChunkError as exc:
                first = first or exc
        else:
            if inner == end:  # its length and its fields agree: its end is known
                self.skipped_chunk(pos, end, str(first))
                return end
            self.skipped_chunk(pos, pos + RECORD_HEAD, f"{first}; its record length does not match its fields")
            return None
        if inner != end:
            wrong = "data length" if candidate == end else "record length"
            self.unused_damage(pos, f"chunk's {wrong} field damaged ({end - pos - RECORD_HEAD} for "
                                    f"{inner - pos - RECORD_HEAD}); its content checks and is kept")
        from mcap.records import Channel, Message, Schema

        self.close_skip()
        self.expected_index = _message_index(data)
        times = [t for entries in self.expected_index.values() for t, _ in entries]
        span = (min(times), max(times)) if times else (0, 0)
        if (chunk.message_start_time, chunk.message_end_time) != span:
            self.unused_damage(pos, "chunk's time range field damaged (not copied: rebuilt); its content checks "
                                    "and is kept")
        self.start()
        for rec in recs:
            if isinstance(rec, Schema):
                self.schema(rec)
            elif isinstance(rec, Channel):
                self.channel(rec)
            elif isinstance(rec, Message):
                self.message(rec)
        self.out.chunks += 1
        return candidate

    def cut_or_end(self, pos: int, reason: str) -> None:
        """Nothing readable after `pos`: the end (intact summary) or the file is cut short."""
        out = self.out
        if self.limit < self.size:
            self.skipped_record(pos, self.limit, f"damaged records up to the data section's end: "
                                                 f"{self.limit - pos} bytes skipped")
            out.complete = True
            out.stopped_at = self.size
        else:
            out.stopped_at, out.reason = pos, reason


def _message_index(data: bytes) -> dict[int, list[tuple[int, int]]]:
    """channel id -> [(log time, offset in `data`)] of the message records in a chunk's
    uncompressed records `data`, as its message indexes list them."""
    index: dict[int, list[tuple[int, int]]] = {}
    q = 0
    while q + RECORD_HEAD <= len(data):
        if data[q] == OP_MESSAGE:
            cid = int.from_bytes(data[q + RECORD_HEAD:q + RECORD_HEAD + 2], "little")
            log_time = _u64(data, q + RECORD_HEAD + 2 + 4)
            index.setdefault(cid, []).append((log_time, q))
        q += RECORD_HEAD + _u64(data, q + 1)
    return index


def _stream(body: bytes):
    from mcap.data_stream import ReadDataStream

    return ReadDataStream(_Strict(body))

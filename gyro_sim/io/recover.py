"""Recovering a log cut short (SIGKILL, power loss, full disk): ``gyro-sim recover``.

A gyro_sim log is written as a stream: header, the ``gyro_sim`` metadata and the scene
attachment, then compressed chunks, each holding the schemas and channels it first uses and
its messages, each followed by its message indexes. A run that is killed never writes the
summary and footer, and the chunk in progress at that moment is lost or cut in half; every
chunk before it (at most ``flush_period`` old, 1 s by default) is complete.

:func:`recover` reads the file record by record from the start, as MCAP allows without a
summary, keeps every complete record (checking each chunk's CRC), stops at the first
incomplete or corrupt one, and writes everything it kept to a new, well-formed file: same
schemas, channels, metadata, attachments and messages in the same order, with a summary and
indexes. The input is never modified.

(``rerun mcap convert --recover`` also reads such files, in memory, for viewing only.)
"""
from __future__ import annotations

import os
import struct
from dataclasses import dataclass, field
from pathlib import Path

from .mcap_log import LogError


@dataclass
class Recovery:
    """What was recovered."""

    messages: int = 0
    start_ns: int | None = None
    end_ns: int | None = None
    channels: int = 0
    metadata: int = 0
    attachments: int = 0
    complete: bool = False  # the input had its footer (nothing was lost)
    stopped_at: int = 0  # byte offset of the first record that could not be read
    size: int = 0  # bytes of the input
    reason: str = ""  # why reading stopped
    per_topic: dict = field(default_factory=dict)

    def report(self) -> str:
        span = 0.0 if self.start_ns is None else (self.end_ns - self.start_ns) / 1e9
        t0 = 0.0 if self.start_ns is None else self.start_ns / 1e9
        t1 = 0.0 if self.end_ns is None else self.end_ns / 1e9
        lines = [
            f"recovered {self.messages} messages on {self.channels} channels, log time {t0:.6g} .. {t1:.6g} s "
            f"({span:.6g} s), {self.metadata} metadata and {self.attachments} attachments",
            ("the input was complete (it had its footer)" if self.complete else
             f"the input ends in an incomplete record at byte {self.stopped_at} of {self.size} ({self.reason}): "
             f"{self.size - self.stopped_at} bytes dropped"),
        ]
        return "\n".join(lines)


def recover(src: str | os.PathLike, dst: str | os.PathLike) -> Recovery:
    """Rewrite what is readable in `src` as a well-formed MCAP file `dst` (module docstring)."""
    from mcap.exceptions import McapError
    from mcap.records import Attachment, Channel, Footer, Header, Message, Metadata, Schema
    from mcap.stream_reader import StreamReader
    from mcap.writer import Writer

    from .mcap_log import CHUNK_SIZE, _compression

    src, dst = Path(src), Path(dst)
    if src.resolve() == dst.resolve():
        raise LogError("recover writes a new file: give another output path")
    out = Recovery(size=src.stat().st_size)
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    new_schema: dict[int, int] = {}
    new_channel: dict[int, int] = {}
    pending: list = []  # records before the writer exists (it needs the header's profile)
    writer = None
    with open(src, "rb") as f, open(dst, "wb") as g:
        reader = StreamReader(f, validate_crcs=True, record_size_limit=out.size + 1)

        def start(profile: str, library: str):
            w = Writer(g, chunk_size=CHUNK_SIZE, compression=_compression())
            w.start(profile=profile, library=library)
            return w

        def emit(rec):
            if isinstance(rec, Schema):
                if rec.id not in new_schema:
                    schemas[rec.id] = rec
                    new_schema[rec.id] = writer.register_schema(rec.name, rec.encoding, rec.data)
            elif isinstance(rec, Channel):
                if rec.id not in new_channel:
                    channels[rec.id] = rec
                    sid = new_schema.get(rec.schema_id, 0)
                    new_channel[rec.id] = writer.register_channel(rec.topic, rec.message_encoding, sid, dict(rec.metadata))
                    out.channels += 1
            elif isinstance(rec, Message):
                cid = new_channel.get(rec.channel_id)
                if cid is None:
                    return  # a message of a channel never declared: unreadable, dropped
                writer.add_message(cid, rec.log_time, rec.data, rec.publish_time, rec.sequence)
                out.messages += 1
                out.start_ns = rec.log_time if out.start_ns is None else min(out.start_ns, rec.log_time)
                out.end_ns = rec.log_time if out.end_ns is None else max(out.end_ns, rec.log_time)
                topic = channels[rec.channel_id].topic
                out.per_topic[topic] = out.per_topic.get(topic, 0) + 1
            elif isinstance(rec, Metadata):
                writer.add_metadata(rec.name, dict(rec.metadata))
                out.metadata += 1
            elif isinstance(rec, Attachment):
                writer.add_attachment(rec.create_time, rec.log_time, rec.name, rec.media_type, rec.data)
                out.attachments += 1

        try:
            in_summary = False
            for rec in _records(reader, out):
                if isinstance(rec, Header):
                    writer = start(rec.profile, rec.library)
                    continue
                if writer is None:
                    pending.append(rec)
                    continue
                if isinstance(rec, Footer):
                    out.complete = True
                    break
                if type(rec).__name__ == "DataEnd":
                    in_summary = True
                if in_summary:
                    continue  # summary records repeat what the data section held
                emit(rec)
            out.stopped_at = out.size if out.complete else out.stopped_at
        except (McapError, EOFError, struct.error, ValueError, OSError, MemoryError) as exc:
            out.reason = f"{type(exc).__name__}: {exc}" if str(exc) else type(exc).__name__
        except Exception as exc:  # noqa: BLE001 - a corrupt record can fail in any decoder
            out.reason = f"{type(exc).__name__}: {exc}"
        if writer is None:
            raise LogError(f"{src}: not an MCAP file, or cut before its header ({out.reason or 'empty'})")
        for rec in pending:
            emit(rec)
        writer.finish()
    return out


def _records(reader, out: Recovery):
    """The reader's records; `out.stopped_at` follows the end of the last complete one."""
    for rec in reader.records:
        out.stopped_at = reader._stream.count  # noqa: SLF001 - bytes consumed: the record boundary
        yield rec

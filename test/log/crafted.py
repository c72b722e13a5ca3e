"""Helpers of the log-safety tests: damaged and crafted copies of a recorded log."""
from __future__ import annotations

import shutil
from pathlib import Path


def chunk_offsets(path) -> list[tuple[int, int]]:
    """(start, length) of every chunk record of a well-formed log, from its chunk indexes."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    return sorted((c.chunk_start_offset, c.chunk_length) for c in summary.chunk_indexes)


def flip(src, dst, offset: int) -> Path:
    """A copy of `src` with the byte at `offset` inverted."""
    shutil.copyfile(src, dst)
    with open(dst, "r+b") as f:
        f.seek(offset)
        b = f.read(1)
        f.seek(offset)
        f.write(bytes([b[0] ^ 0xFF]))
    return Path(dst)


def truncate(src, dst, size: int) -> Path:
    with open(src, "rb") as f, open(dst, "wb") as g:
        g.write(f.read(size))
    return Path(dst)


def rewrite(src, dst, *, params_json: str | None = None, scene_text: str | None = None,
            schemas: dict | None = None, retime=None) -> Path:
    """A copy of the log `src` written anew with mcap's own writer, replacing the gyro_sim
    metadata's params (JSON text), the scene attachment's text, or schema definitions
    ({schema name: definition text}), or log times (``retime(topic, index, t) -> t``; index: the
    message's rank on its topic)."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    with open(src, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        header = reader.get_header()
        metadata = list(reader.iter_metadata())
        attachments = list(reader.iter_attachments())
        messages, ranks = [], {}
        for _, c, m in reader.iter_messages(log_time_order=False):
            rank = ranks[c.topic] = ranks.get(c.topic, -1) + 1
            t = m.log_time if retime is None else retime(c.topic, rank, m.log_time)
            messages.append((c.id, t, bytes(m.data), m.publish_time, m.sequence))
    with open(dst, "wb") as g:
        w = Writer(g)
        w.start(profile=header.profile, library=header.library)
        for m in metadata:
            meta = dict(m.metadata)
            if m.name == "gyro_sim" and params_json is not None:
                meta["params"] = params_json
            w.add_metadata(m.name, meta)
        for a in attachments:
            data = scene_text.encode() if (a.name == "scene.yaml" and scene_text is not None) else a.data
            w.add_attachment(a.create_time, a.log_time, a.name, a.media_type, data)
        sid, cid = {}, {}
        for s in summary.schemas.values():
            text = (schemas or {}).get(s.name)
            sid[s.id] = w.register_schema(s.name, s.encoding, text.encode() if text is not None else s.data)
        for c in summary.channels.values():
            cid[c.id] = w.register_channel(c.topic, c.message_encoding, sid[c.schema_id], dict(c.metadata))
        for ch, t, data, pt, seq in messages:
            w.add_message(cid[ch], t, data, pt, seq)
        w.finish()
    return Path(dst)

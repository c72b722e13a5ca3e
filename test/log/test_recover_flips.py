"""`gyro-sim recover` against systematic one-byte flips over a real log, in every region (magic,
header, metadata, attachment, chunks, message indexes, data end, summary, footer): every message
of every chunk whose bytes were not touched is kept, nothing damaged is passed on, and damage in
a complete log is found and reported.

What a kept or lost message is, is decided here with mcap's own reader (``breakup_chunk`` over
the input's chunks, ``make_reader`` over the output), not with gyro_sim's."""
from __future__ import annotations

from pathlib import Path

import pytest

from gyro_sim.log.recover import recover

from test.log.crafted import truncate

#: bytes between two flips inside a record's body (every byte of every record's opcode and
#: length, and of the magic, footer and data end, is flipped)
BODY_STRIDE = 61
#: opcodes of the MCAP specification used here
OP_CHUNK, OP_MESSAGE_INDEX, OP_FOOTER, OP_DATA_END = 6, 7, 2, 15
#: bytes of a record's opcode and length
HEAD = 9
MAGIC = 8


def records(data: bytes) -> list[tuple[int, int, int]]:
    """(start, opcode, end) of every record between the two magics of a complete file."""
    return records_until(data[:len(data) - MAGIC])


def records_until(data: bytes) -> list[tuple[int, int, int]]:
    """(start, opcode, end) of every complete record after the leading magic (in a file cut
    short, the last, cut one left out)."""
    out, pos = [], MAGIC
    while pos + HEAD <= len(data):
        op, length = data[pos], int.from_bytes(data[pos + 1:pos + HEAD], "little")
        if pos + HEAD + length > len(data):
            break
        out.append((pos, op, pos + HEAD + length))
        pos += HEAD + length
    return out


def chunk_messages(data: bytes, recs) -> dict[int, set]:
    """chunk start -> {(topic, log time, bytes)} of its messages, by mcap's reader."""
    import io

    from mcap.data_stream import ReadDataStream
    from mcap.reader import breakup_chunk
    from mcap.records import Channel, Chunk, Message

    topics, out = {}, {}
    for start, op, end in recs:
        if op != OP_CHUNK:
            continue
        chunk = Chunk.read(ReadDataStream(io.BytesIO(data[start + HEAD:end])))
        msgs = set()
        for r in breakup_chunk(chunk, validate_crc=True):
            if isinstance(r, Channel):
                topics[r.id] = r.topic
            elif isinstance(r, Message):
                msgs.add((topics[r.channel_id], r.log_time, bytes(r.data)))
        out[start] = msgs
    return out


def output(path: Path):
    """([(topic, log time, bytes)], {attachment name: bytes}) of a recovered file, read with CRCs
    checked."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        reader = make_reader(f, validate_crcs=True)
        msgs = [(c.topic, m.log_time, bytes(m.data)) for _, c, m in reader.iter_messages(log_time_order=False)]
        attachments = {a.name: bytes(a.data) for a in reader.iter_attachments()}
    return msgs, attachments


def flip_offsets(size: int, recs) -> list[int]:
    """Every byte of both magics and of each record's opcode and length, every byte of the
    data end and footer records, and a stride through every record's body."""
    offsets = set(range(MAGIC)) | set(range(size - MAGIC, size))
    for start, op, end in recs:
        offsets |= set(range(start, min(start + HEAD, end)))
        if op in (OP_DATA_END, OP_FOOTER):
            offsets |= set(range(start, end))
        offsets |= set(range(start + HEAD, end, BODY_STRIDE))
        offsets.add(end - 1)
    return sorted(o for o in offsets if o < size)


def _attachments(path: Path) -> dict:
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return {a.name: bytes(a.data) for a in make_reader(f).iter_attachments()}


def _region(recs, offset: int) -> tuple[int, int] | None:
    for start, op, end in recs:
        if start <= offset < end:
            return start, op
    return None


def _sweep(log: Path, tmp_path: Path, complete: bool):
    """Flip each byte of `flip_offsets` in turn, recover, and list what breaks a promise."""
    data = log.read_bytes()
    recs = records(data) if complete else records_until(data)
    per_chunk = chunk_messages(data, recs)
    everything = set().union(*per_chunk.values())
    originals = _attachments(log) if complete else None
    regions = {}
    problems = []
    for offset in flip_offsets(len(data), recs):
        damaged = bytearray(data)
        damaged[offset] ^= 0xFF
        bad, fixed = tmp_path / "bad.mcap", tmp_path / "fixed.mcap"
        bad.write_bytes(damaged)
        fixed.unlink(missing_ok=True)
        rec = recover(bad, fixed)
        region = _region(recs, offset)
        regions[region[1] if region else "magic"] = regions.get(region[1] if region else "magic", 0) + 1
        touched = region[0] if region and region[1] == OP_CHUNK else None
        kept, attachments = output(fixed)
        keep = set().union(*(m for start, m in per_chunk.items() if start != touched))
        missing = keep - set(kept)
        if complete:
            if missing:
                problems.append((offset, region, f"{len(missing)} messages of intact chunks lost", rec.report()))
            if not rec.damaged:
                problems.append((offset, region, "damage not reported", rec.report()))
            if rec.lost != len(everything) - len(kept):
                problems.append((offset, region, f"lost {rec.lost}, really {len(everything) - len(kept)}",
                                 rec.report()))
            if any(attachments.get(k, v) != v for k, v in originals.items()) or set(attachments) - set(originals):
                problems.append((offset, region, "an attachment differs", rec.report()))
        elif len(missing) != rec.orphans:  # cut short: no summary to declare channels lost with a chunk
            problems.append((offset, region, f"{len(missing)} messages of intact chunks lost, "
                                             f"{rec.orphans} said", rec.report()))
        if not set(kept) <= everything:
            problems.append((offset, region, "a message that is not in the input", rec.report()))
        if len(kept) != len(set(kept)) or len(kept) != rec.messages:
            problems.append((offset, region, "messages duplicated or miscounted", rec.report()))
    return problems, regions


@pytest.mark.slow
def test_every_intact_chunk_survives_a_flipped_byte_anywhere_in_a_complete_log(chunked, tmp_path):
    log, chunks, _ = chunked
    problems, regions = _sweep(log, tmp_path, complete=True)
    # every region was hit: header, metadata, attachment, chunks, message indexes, data end,
    # summary records (schemas, channels, indexes, statistics, offsets) and the footer
    assert {1, 12, 9, OP_CHUNK, OP_MESSAGE_INDEX, OP_DATA_END, 3, 4, 8, 11, 14, OP_FOOTER, "magic"} <= set(regions)
    assert not problems, f"{len(problems)} of {sum(regions.values())} flips: {problems[:3]}"


@pytest.mark.slow
def test_every_intact_chunk_survives_a_flipped_byte_in_a_log_cut_short(chunked, tmp_path):
    log, chunks, _ = chunked
    start, length = chunks[-2]
    cut = truncate(log, tmp_path / "cut.mcap", start + length // 2)  # killed while writing a chunk
    work = tmp_path / "work"
    work.mkdir()
    problems, regions = _sweep(cut, work, complete=False)
    assert {1, 12, 9, OP_CHUNK, OP_MESSAGE_INDEX} <= set(regions)
    assert not problems, f"{len(problems)} of {sum(regions.values())} flips: {problems[:3]}"


def test_the_report_of_an_intact_log_says_it_is_intact(chunked, tmp_path):
    log, _, msgs = chunked
    rec = recover(log, tmp_path / "copy.mcap")
    assert not rec.damaged and rec.lost == 0 and rec.messages == len(msgs)
    assert "nothing damaged" in rec.report() and "intact" in rec.report()


def test_the_report_says_in_one_line_what_was_skipped(chunked, tmp_path):
    log, chunks, msgs = chunked
    data = bytearray(log.read_bytes())
    for start, length in chunks[1:3]:  # two chunks damaged in their compressed data
        data[start + length - 10] ^= 0xFF
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    rec = recover(bad, tmp_path / "fixed.mcap")
    line = rec.skipped_line()
    kept, _ = output(tmp_path / "fixed.mcap")
    assert "\n" not in line
    assert line.startswith("skipped 2 damaged chunks and 0 other damaged records "
                           f"({chunks[1][1] + chunks[2][1]} bytes): {len(msgs) - len(kept)} messages lost")
    assert f"at byte {chunks[1][0]}" in line and f"at byte {chunks[2][0]}" in line
    assert line in rec.report().splitlines()
    assert "complete (it had its end) but damaged" in rec.report()


@pytest.mark.parametrize("where", ["magic", "footer"])
def test_a_damaged_magic_does_not_cost_the_log(chunked, tmp_path, where):
    log, _, msgs = chunked
    data = bytearray(log.read_bytes())
    data[3 if where == "magic" else len(data) - 3] ^= 0xFF
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    rec = recover(bad, tmp_path / "fixed.mcap")
    assert rec.messages == len(msgs) and rec.damaged and rec.lost == 0


def test_with_data_crcs_a_flipped_metadata_byte_is_reported(tmp_path):
    """MCAP's metadata has no CRC of its own; a writer with data CRCs on covers it with the
    data section's: recover checks it."""
    from mcap.writer import Writer

    log = tmp_path / "crc.mcap"
    with open(log, "wb") as f:
        w = Writer(f, enable_data_crcs=True)
        w.start(profile="ros2", library="test")
        w.add_metadata("gyro_sim", {"params": '{"advance_dt": 0.01}'})
        sid = w.register_schema("std_msgs/msg/String", "ros2msg", b"string data\n")
        cid = w.register_channel("/x", "cdr", sid)
        for i in range(10):
            w.add_message(cid, i, b"\x00\x01\x00\x00\x02\x00\x00\x00a\x00", i, i)
        w.finish()
    assert not recover(log, tmp_path / "a.mcap").damaged
    data = bytearray(log.read_bytes())
    data[data.find(b"0.01") + 3] ^= 0x01  # 0.01 -> 0.00: still a valid number
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    rec = recover(bad, tmp_path / "b.mcap")
    assert rec.damaged and "data section CRC mismatch" in rec.skipped_line()

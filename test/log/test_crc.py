"""Logs verified when read: chunk CRCs checked by every reader, damaged logs refused
with the chunk's offset, and `recover` keeping every intact chunk after a damaged one."""
from __future__ import annotations


import pytest

from gyro_sim.log.mcap_log import LogError, iter_messages, read_info
from gyro_sim.log.recover import recover

from test.conftest import gyro_sim, rosbags_messages
from test.log.crafted import flip, truncate

#: the chunk header's fixed fields before its CRC: start time, end time, uncompressed size
CRC_FIELD = 9 + 8 + 8 + 8


def _middle(chunks):
    return chunks[len(chunks) // 2]


def test_an_intact_log_reads(chunked):
    path, _, msgs = chunked
    assert read_info(path).message_count == len(msgs)
    assert len(list(iter_messages(path))) == len(msgs)


@pytest.mark.parametrize("where, reason", [("data", "does not decompress"), ("crc", "CRC mismatch")])
def test_a_damaged_chunk_is_refused_with_its_offset_by_every_reader(chunked, tmp_path, where, reason):
    path, chunks, _ = chunked
    start, length = _middle(chunks)
    bad = flip(path, tmp_path / "bad.mcap", start + (length - 10 if where == "data" else CRC_FIELD))
    for read in (read_info, lambda p: list(iter_messages(p)), lambda p: list(iter_messages(p, decode=False))):
        with pytest.raises(LogError) as info:
            read(bad)
        text = str(info.value)
        assert f"chunk at byte {start}" in text and reason in text and "gyro-sim recover" in text, text
        assert "\n" not in text


def test_recover_skips_a_damaged_chunk_and_keeps_every_intact_one_after_it(chunked, tmp_path):
    path, chunks, msgs = chunked
    start, length = _middle(chunks)
    bad = flip(path, tmp_path / "bad.mcap", start + length - 10)
    fixed = tmp_path / "fixed.mcap"
    rec = recover(bad, fixed)
    assert rec.skipped_chunks == 1 and rec.chunks == len(chunks) - 1
    assert 0 < rec.skipped_messages and rec.messages + rec.skipped_messages == len(msgs)
    kept = rosbags_messages(fixed)
    assert len(kept) == rec.messages
    assert set(kept) < set(msgs)
    assert max(t for _, t in kept) == max(t for _, t in msgs)  # the chunks after the damage are there
    report = rec.report()
    assert f"at byte {start}" in report and "skipped 1 damaged chunk " in report
    assert read_info(fixed).message_count == rec.messages  # the output verifies


def test_recover_calls_a_crc_failure_a_crc_failure(chunked, tmp_path):
    path, chunks, msgs = chunked
    start, _ = _middle(chunks)
    bad = flip(path, tmp_path / "bad.mcap", start + CRC_FIELD)
    rec = recover(bad, tmp_path / "fixed.mcap")
    report = rec.report()
    assert "CRC mismatch" in report and "incomplete" not in report and "cut short" not in report, report
    assert rec.complete and rec.messages + rec.skipped_messages == len(msgs)


def test_recover_keeps_a_chunk_whose_record_length_is_damaged(chunked, tmp_path):
    path, chunks, msgs = chunked
    start, _ = _middle(chunks)
    bad = flip(path, tmp_path / "bad.mcap", start + 8)  # the top byte of the chunk's length
    rec = recover(bad, tmp_path / "fixed.mcap")
    kept = rosbags_messages(tmp_path / "fixed.mcap")
    assert rec.chunks == len(chunks) and kept == msgs  # its own fields give its end; its CRC checks
    assert f"at byte {start}: chunk's record length field damaged" in rec.report()


def test_recover_resynchronises_after_a_damaged_record_length(chunked, tmp_path):
    path, chunks, msgs = chunked
    start, length = _middle(chunks)
    data = bytearray(path.read_bytes())
    data[start + 8] ^= 0xFF  # the chunk's length, and its data length field: its end is unknown
    data[start + 9 + 8 + 8 + 8 + 4 + 4 + 4 + 7] ^= 0xFF
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    rec = recover(bad, tmp_path / "fixed.mcap")
    kept = rosbags_messages(tmp_path / "fixed.mcap")
    assert rec.chunks == len(chunks) - 1 and len(kept) == rec.messages
    assert max(t for _, t in kept) == max(t for _, t in msgs)  # the chunks after it are there
    assert rec.lost == len(msgs) - len(kept) > 0


def test_recover_of_a_log_cut_in_a_chunk_keeps_the_chunks_before(chunked, tmp_path):
    path, chunks, msgs = chunked
    start, length = _middle(chunks)
    cut = truncate(path, tmp_path / "cut.mcap", start + length // 2)
    with pytest.raises(LogError, match="gyro-sim recover"):
        read_info(cut)
    rec = recover(cut, tmp_path / "fixed.mcap")
    assert not rec.complete and rec.stopped_at == start and rec.chunks == chunks.index((start, length))
    kept = rosbags_messages(tmp_path / "fixed.mcap")
    assert len(kept) == rec.messages and kept == [m for m in msgs if m in set(kept)]
    assert "cut short" in rec.report()


@pytest.mark.parametrize("command", [("view", "--save", "{out}"), ("replay", "--resimulate")])
@pytest.mark.slow
def test_commands_refuse_a_damaged_log_with_exit_2_and_one_line(chunked, tmp_path, command):
    path, chunks, _ = chunked
    start, length = _middle(chunks)
    bad = flip(path, tmp_path / "bad.mcap", start + length - 10)
    if command[0] == "view":
        pytest.importorskip("rerun", reason="view needs rerun-sdk")
    args = [a.format(out=tmp_path / "out.rrd") for a in command]
    r = gyro_sim(args[0], bad, *args[1:])
    err = r.stderr.strip()
    assert r.returncode == 2, (r.returncode, err)
    assert "Traceback" not in err and f"chunk at byte {start}" in err, err
    assert len([line for line in err.splitlines() if "gyro-sim" in line]) == 1, err
    assert not (tmp_path / "out.rrd").exists()

"""Recovery of truncated bags (pure): files cut at arbitrary points, zero-filled tails, stale metadata.yaml.

A writer that is killed leaves only finished chunks on disk (test_recording_writer.py); here the file is
cut by hand at many offsets and recovered, and the recovered bag must hold exactly the messages of the
complete chunks before the cut, readable by rosbags.
"""
from __future__ import annotations

import shutil

import pytest
import yaml
from mcap.reader import make_reader
from rclpy.serialization import serialize_message
from sensor_msgs.msg import Imu

from hindrax_bringup.recording.metadata import read_metadata
from hindrax_bringup.recording.qos import default_profile
from hindrax_bringup.recording.recover import RecoverError, is_complete, recover_bag, recover_file
from hindrax_bringup.recording.writer import BagWriter, WriterOptions
from hindrax_onboard.cli import main as cli_main

T0 = 1_700_000_000_000_000_000
N = 400


def imu(i: int) -> bytes:
    m = Imu()
    m.header.frame_id = "imu_link"
    m.linear_acceleration.x = float(i)
    return serialize_message(m)


@pytest.fixture
def complete_bag(tmp_path):
    """A finished bag of N Imu messages in small chunks, and the byte offset where each chunk ends."""
    bag = tmp_path / "src" / "bag"
    with BagWriter(bag, WriterOptions(chunk_size_bytes=3000)) as w:
        w.add_topic("/imu", "sensor_msgs/msg/Imu", [default_profile("best_effort")])
        for i in range(N):
            w.write("/imu", T0 + i * 10_000_000, imu(i))
    with open(bag / "bag_0.mcap", "rb") as f:
        summary = make_reader(f).get_summary()
    # (end offset of the chunk's message indexes, messages up to and including that chunk)
    ends, total = [], 0
    counts = _messages_per_chunk(bag / "bag_0.mcap")
    for ci, n in zip(sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset), counts):
        total += n
        ends.append((ci.chunk_start_offset + ci.chunk_length, total))
    return bag, ends


def _messages_per_chunk(path):
    from mcap.records import Chunk
    from mcap.stream_reader import StreamReader, breakup_chunk

    out = []
    with open(path, "rb") as f:
        for rec in StreamReader(f, emit_chunks=True).records:
            if isinstance(rec, Chunk):
                out.append(sum(1 for r in breakup_chunk(rec) if type(r).__name__ == "Message"))
    return out


def expected_after_cut(ends, cut: int) -> int:
    """Messages of the chunks that lie completely before byte offset ``cut``."""
    return max([n for end, n in ends if end <= cut], default=0)


def cut_copy(bag, tmp_path, cut: int, zero_fill: int = 0):
    dst = tmp_path / f"cut{cut}" / "bag"
    shutil.copytree(bag, dst)
    f = dst / "bag_0.mcap"
    data = f.read_bytes()[:cut] + b"\x00" * zero_fill
    f.write_bytes(data)
    return dst


def test_recovered_file_holds_every_complete_chunk_before_the_cut(complete_bag, tmp_path):
    from rosbags.highlevel import AnyReader

    bag, ends = complete_bag
    size = (bag / "bag_0.mcap").stat().st_size
    assert len(ends) >= 8
    # cuts inside chunks, exactly at chunk ends, inside a record header, and just before the summary
    cuts = sorted({ends[2][0] - 1, ends[2][0], ends[2][0] + 5, ends[5][0] + 100, ends[-1][0] - 3, 8 + 13})
    for cut in cuts:
        assert cut < size
        dst = cut_copy(bag, tmp_path, cut)
        assert not is_complete(dst / "bag_0.mcap")
        meta, (res,) = recover_bag(dst)
        want = expected_after_cut(ends, cut)
        assert res.message_count == want, f"cut at {cut}"
        assert is_complete(dst / "bag_0.mcap")
        assert meta.message_count == want and read_metadata(dst).message_count == want
        if want:
            with AnyReader([dst]) as reader:
                xs = [reader.deserialize(raw, c.msgtype).linear_acceleration.x for c, _, raw in reader.messages()]
            assert xs == [float(i) for i in range(want)]  # the first `want` messages, in order, intact


def test_zero_filled_tail_after_power_loss_is_discarded(complete_bag, tmp_path):
    bag, ends = complete_bag
    # zeros after a complete chunk: opcode 0 ends the data
    dst = cut_copy(bag, tmp_path, ends[4][0] + 37, zero_fill=4096)
    meta, (res,) = recover_bag(dst)
    assert res.message_count == ends[4][1] and res.corrupt_chunks == 0
    assert res.truncated_bytes >= 4096 - 200  # at most a (skipped) message index reaches into the zeros
    # zeros inside a chunk (its declared length filled with zeros): the CRC rejects it, earlier chunks stay
    dst = cut_copy(bag, tmp_path, ends[4][0] - 50, zero_fill=4096)
    meta, (res,) = recover_bag(dst)
    assert res.message_count == ends[3][1] and res.corrupt_chunks == 1


def test_corrupt_chunk_is_skipped_and_later_chunks_are_kept(complete_bag, tmp_path):
    bag, ends = complete_bag
    dst = tmp_path / "corrupt" / "bag"
    shutil.copytree(bag, dst)
    f = dst / "bag_0.mcap"
    data = bytearray(f.read_bytes()[: ends[6][0]])
    # flip bytes in the middle of the compressed data of the 4th chunk (between ends[2] and ends[3])
    mid = (ends[2][0] + ends[3][0]) // 2
    data[mid:mid + 8] = bytes(b ^ 0xFF for b in data[mid:mid + 8])
    f.write_bytes(bytes(data))
    meta, (res,) = recover_bag(dst)
    lost = ends[3][1] - ends[2][1]
    assert res.corrupt_chunks == 1
    assert res.message_count == ends[6][1] - lost


def test_complete_files_are_left_alone_and_stale_metadata_is_rebuilt(complete_bag, tmp_path):
    bag, ends = complete_bag
    before = (bag / "bag_0.mcap").read_bytes()
    doc = yaml.safe_load((bag / "metadata.yaml").read_text())
    doc["rosbag2_bagfile_information"]["message_count"] = 1
    doc["rosbag2_bagfile_information"]["files"] = []
    (bag / "metadata.yaml").write_text(yaml.safe_dump(doc))
    meta, (res,) = recover_bag(bag)
    assert res.was_complete and res.message_count == N
    assert (bag / "bag_0.mcap").read_bytes() == before
    m = read_metadata(bag)
    assert m.message_count == N and m.topic("/imu").message_count == N
    assert m.topic("/imu").offered_qos_profiles[0]["reliability"] == "best_effort"  # from channel metadata


def test_recovered_file_carries_a_rosbag2_metadata_record_and_keep_original(complete_bag, tmp_path):
    bag, ends = complete_bag
    dst = cut_copy(bag, tmp_path, ends[3][0] + 10)
    res = recover_file(dst / "bag_0.mcap", keep_original=True)
    assert (dst / "bag_0.mcap.truncated").stat().st_size == ends[3][0] + 10
    with open(dst / "bag_0.mcap", "rb") as f:
        metas = [m for m in make_reader(f).iter_metadata() if m.name == "rosbag2"]
    assert len(metas) == 1
    info = yaml.safe_load(metas[0].metadata["serialized_metadata"])
    assert info["version"] == 9 and info["message_count"] == res.message_count == ends[3][1]


def test_not_an_mcap_file_and_missing_bag_raise(tmp_path):
    (tmp_path / "x").mkdir()
    (tmp_path / "x" / "x_0.mcap").write_bytes(b"not mcap at all")
    with pytest.raises(RecoverError, match="not an MCAP file"):
        recover_bag(tmp_path / "x")
    with pytest.raises(FileNotFoundError):
        recover_bag(tmp_path / "missing")


def test_hindrax_bag_recover_command(complete_bag, tmp_path, capsys):
    bag, ends = complete_bag
    dst = cut_copy(bag, tmp_path, ends[5][0] + 1)
    assert cli_main(["bag", "recover", str(dst)]) == 0
    out = capsys.readouterr().out
    assert f"recovered {ends[5][1]} messages" in out
    assert cli_main(["bag", "recover", str(tmp_path / "nothing")]) == 1
    assert "no such bag" in capsys.readouterr().err

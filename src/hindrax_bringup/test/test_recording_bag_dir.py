"""Every start of the recorder makes a new bag under the output root; an existing name never stops it
(recording/bag_dir.py, docs/deployment.md §5)."""
from __future__ import annotations

import datetime as dt
import threading

import pytest
from rclpy.parameter import Parameter

from hindrax_bringup.recording.bag_dir import bag_dir_name, new_bag_dir
from hindrax_bringup.recording.metadata import read_metadata
from hindrax_bringup.recording.recorder_node import RecorderNode
from hindrax_common.testing import config_parameters, ros_context

NOW = dt.datetime(2026, 11, 22, 9, 30, 5)


def test_name_is_rosbag2s_and_a_taken_name_gets_a_suffix(tmp_path):
    root = tmp_path / "runs" / "day1"  # missing parents are created
    assert bag_dir_name(NOW) == "hindrax_2026_11_22-09_30_05"  # rosbag2_YYYY_MM_DD-HH_MM_SS with our prefix
    first = new_bag_dir(root, NOW)
    (first / "metadata.yaml").write_text("a bag\n")
    second = new_bag_dir(root, NOW)
    third = new_bag_dir(root, NOW)  # an empty directory of an earlier start is not reused either
    assert [p.name for p in (first, second, third)] == [
        "hindrax_2026_11_22-09_30_05", "hindrax_2026_11_22-09_30_05_1", "hindrax_2026_11_22-09_30_05_2"]
    assert all(p.is_dir() for p in (first, second, third)) and not any(second.iterdir())


def test_concurrent_starts_each_get_their_own_directory(tmp_path):
    out: list = []
    threads = [threading.Thread(target=lambda: out.append(new_bag_dir(tmp_path, NOW))) for _ in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert len(set(out)) == 8  # os.mkdir is atomic: no two recorders share a bag


def test_a_root_that_is_a_file_is_an_oserror_naming_it(tmp_path):
    (tmp_path / "runs").write_text("not a directory")
    with pytest.raises(OSError):
        new_bag_dir(tmp_path / "runs", NOW)


@pytest.mark.ros
def test_recorder_starts_again_when_the_timestamped_names_exist(tmp_path):
    root = tmp_path / "runs"
    # bags of an earlier launch under the names this start and the next second's would take
    now = dt.datetime.now()
    taken = [root / bag_dir_name(now + dt.timedelta(seconds=s)) for s in range(0, 3)]
    for d in taken:
        d.mkdir(parents=True)
        (d / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    with ros_context() as ctx:
        params = config_parameters({"recording.output_root": str(root)}) + [
            Parameter("all_topics", value=True), Parameter("exclude_regex", value="^/esc/heartbeat")]
        node = RecorderNode(context=ctx, parameter_overrides=params)
        try:
            # exclude_regex (pool_test.launch.xml) takes a topic out of "all topics"
            sel = node.default_selection()
            assert sel.matches("/wrench") and not sel.matches("/esc/heartbeat")
            bags = []
            for _ in range(2):
                bags.append(node.start_recording())
                assert node.stop_recording() is not None
        finally:
            node.destroy_node()
    assert len(set(bags)) == 2 and not set(bags) & set(taken)
    for bag in bags:
        assert bag.parent == root and bag.name.startswith("hindrax_")
        assert read_metadata(bag).relative_file_paths  # a finished bag of its own

"""Result folders (hindrax_tools.output_dirs): new per result, named by input and time, latest moved atomically."""
import datetime as dt
import os

import pytest

from hindrax_tools.output_dirs import OutputDirError, explicit_result_dir, new_result_dir, point_latest

NOW = dt.datetime(2026, 11, 25, 12, 0, 0)


def test_a_taken_name_gets_the_next_suffix_and_one_notice(tmp_path):
    first, note1 = new_result_dir(tmp_path, "sim_surge", NOW)
    second, note2 = new_result_dir(tmp_path, "sim_surge", NOW)
    assert first.name == "sim_surge_2026_11_25-12_00_00" and note1 is None
    assert second.name == "sim_surge_2026_11_25-12_00_00_1"
    assert note2 == f"{first} exists: writing to {second}"
    assert first.is_dir() and second.is_dir() and not any(first.iterdir())


def test_a_named_folder_must_be_new_or_empty(tmp_path):
    assert explicit_result_dir(tmp_path / "new").is_dir()
    assert explicit_result_dir(tmp_path / "new") == tmp_path / "new"  # still empty: usable
    (tmp_path / "new" / "identification.yaml").write_text("x")
    with pytest.raises(OutputDirError, match="not empty"):
        explicit_result_dir(tmp_path / "new")
    (tmp_path / "file").write_text("x")
    with pytest.raises(OutputDirError, match="not a folder"):
        explicit_result_dir(tmp_path / "file")


def test_latest_is_replaced_by_a_relative_link(tmp_path):
    a, _ = new_result_dir(tmp_path, "run", NOW)
    b, _ = new_result_dir(tmp_path, "run", NOW + dt.timedelta(seconds=1))
    point_latest(a)
    point_latest(b)
    assert os.readlink(tmp_path / "latest") == b.name
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([a.name, b.name, "latest"])  # no temporary left

"""Issue 16, items 6 and 8: the listing never leads outside the data folders (not even through
one file of a ROS 2 bag folder), and survives symlink loops, unreadable folders and folders
too large to walk, with a warning."""

from __future__ import annotations

import os
import time

import pytest

from estimator.errors import RoutefuseError
from inspector.folders import DataFolders


def _bag_folder(folder, storage_target=None):
    folder.mkdir(parents=True)
    (folder / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    storage = folder / "bag_0.mcap"
    if storage_target is None:
        storage.write_bytes(b"x")
    else:
        os.symlink(storage_target, storage)
    return folder


def test_a_bag_folder_whose_storage_file_leads_outside_is_not_listed_nor_opened(tmp_path):
    secret = tmp_path / "outside" / "secret.mcap"
    secret.parent.mkdir()
    secret.write_bytes(b"\x89MCAP0\r\n")
    data = tmp_path / "data"
    _bag_folder(data / "good_bag")
    _bag_folder(data / "leaky_bag", storage_target=secret)
    folders = DataFolders.of(data)
    listing = folders.listing()
    assert "data/good_bag" in listing.logs
    assert "data/leaky_bag" not in listing.logs
    assert any("leaky_bag" in w and "outside" in w for w in listing.warnings)
    with pytest.raises(RoutefuseError, match="no such log"):
        folders.resolve("data/leaky_bag", "log")


def test_a_bag_folder_that_became_leaky_after_listing_is_refused_when_opened(tmp_path):
    secret = tmp_path / "secret.mcap"
    secret.write_bytes(b"x")
    data = tmp_path / "data"
    bag = _bag_folder(data / "bag")
    folders = DataFolders.of(data)
    assert "data/bag" in folders.listing().logs
    (bag / "bag_0.mcap").unlink()
    os.symlink(secret, bag / "bag_0.mcap")
    with pytest.raises(RoutefuseError):
        folders.resolve("data/bag", "log")


def test_symlink_loops_and_unreadable_folders_are_skipped_with_a_warning(tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    (data / "drive.mcap").write_bytes(b"x")
    os.symlink(data / "loop_a.mcap", data / "loop_b.mcap")
    os.symlink(data / "loop_b.mcap", data / "loop_a.mcap")
    os.symlink(data / "self.geojson", data / "self.geojson")
    os.symlink(data, data / "up")  # a loop through a folder
    _bag_folder(data / "bag")
    os.symlink(data / "bag" / "x.db3", data / "bag" / "x.db3")
    locked = data / "locked"
    locked.mkdir()
    (locked / "hidden.mcap").write_bytes(b"x")
    locked.chmod(0)
    try:
        folders = DataFolders.of(data, data / "up")
        listing = folders.listing()
    finally:
        locked.chmod(0o755)
    readable = {"data/locked/hidden.mcap"} if os.geteuid() == 0 else set()  # root reads all
    assert set(listing.logs) == {"data/drive.mcap"} | readable
    text = " ".join(listing.warnings)
    assert "loop" in text and "bag" in text
    if os.geteuid() != 0:  # root reads any folder
        assert "locked" in text


def test_a_huge_data_folder_is_walked_within_bounds_and_says_so(tmp_path):
    data = tmp_path / "data"
    data.mkdir()
    for i in range(3000):
        (data / f"note{i:05d}.txt").touch()
    (data / "zz_last.mcap").write_bytes(b"x")
    folders = DataFolders.of(data, max_scanned=1000)
    t0 = time.perf_counter()
    listing = folders.listing()
    assert time.perf_counter() - t0 < 2.0
    assert any("1000" in w and "not all" in w for w in listing.warnings)
    slow = DataFolders.of(data, max_seconds=0.0)
    assert any("s;" in w or "seconds" in w for w in slow.listing().warnings)


def test_a_link_to_a_folder_is_not_followed_and_the_listing_says_so(tmp_path):
    """Links to folders are never followed (one could lead anywhere); the Files tab said
    nothing of one, so the logs under it were missing without a word."""
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    (elsewhere / "far.mcap").write_bytes(b"x")
    data = tmp_path / "data"
    (data / "sub").mkdir(parents=True)
    (data / "drive.mcap").write_bytes(b"x")
    os.symlink(elsewhere, data / "sub" / "mounted")
    listing = DataFolders.of(data).listing()
    assert set(listing.logs) == {"data/drive.mcap"}
    assert [w for w in listing.warnings if "mounted" in w] == [
        f"{data / 'sub' / 'mounted'}: a link to a folder; links to folders are not followed "
        "(pass the folder itself with --data-dir); not listed"
    ]

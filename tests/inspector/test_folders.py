"""Which files the inspector offers and may open, and where uploads go."""

from __future__ import annotations

import os
import stat

import pytest
from fake_runs import data_folder

from estimator.errors import RoutefuseError
from inspector.folders import DataFolders, UploadFolder


def test_listing_offers_logs_and_routes_under_the_folders(tmp_path):
    folders = DataFolders.of(data_folder(tmp_path))
    listing = folders.listing()
    assert set(listing.logs) == {"data/drive.mcap", "data/sub/old.bag", "data/ros2_bag"}
    assert set(listing.routes) == {"data/drive.route.geojson", "data/sub/old.gpx"}
    assert folders.default_route("data/drive.mcap") == "data/drive.route.geojson"
    assert folders.resolve("data/sub/old.bag", "log") == (tmp_path / "data/sub/old.bag").resolve()


def test_names_outside_the_folders_cannot_be_opened(tmp_path):
    d = data_folder(tmp_path)
    secret = tmp_path / "secret.mcap"
    secret.write_bytes(b"x")
    (tmp_path / "outside").mkdir()
    (tmp_path / "outside" / "x.geojson").write_text("{}")
    os.symlink(secret, d / "link.mcap")
    os.symlink(tmp_path / "outside", d / "linked_dir")
    folders = DataFolders.of(d)
    listing = folders.listing()
    assert "data/link.mcap" not in listing.logs
    assert not any("linked_dir" in n for n in listing.routes)
    for name in ("data/../secret.mcap", "../secret.mcap", str(secret), "data/link.mcap"):
        with pytest.raises(RoutefuseError, match="no such log"):
            folders.resolve(name, "log")


def test_upload_folder_is_private_size_limited_and_sanitised(tmp_path):
    up = UploadFolder(max_bytes=1000)
    try:
        assert stat.S_IMODE(up.path.stat().st_mode) == 0o700
        path = up.save("../../etc/evil name.mcap", b"abc")
        assert path.parent == up.path and path.name.endswith("evil_name.mcap")
        with pytest.raises(RoutefuseError, match="exceeds the limit"):
            up.save("big.mcap", b"x" * 1001)
        with pytest.raises(RoutefuseError, match="not a log"):
            up.save("script.sh", b"rm -rf /")
        with pytest.raises(RoutefuseError, match="empty"):
            up.save("empty.bag", b"")
    finally:
        up.close()
    assert not up.path.exists()


def test_logs_are_what_the_format_registry_recognises(tmp_path):
    """The listing and the upload check take log formats from :mod:`estimator.io`: a loose
    ``.db3`` (a ROS 2 bag's part without its folder) is not offered, nor accepted."""
    from estimator.io import LOG_SUFFIXES_TEXT

    d = data_folder(tmp_path)
    (d / "loose.db3").write_bytes(b"x")
    assert "data/loose.db3" not in DataFolders.of(d).listing().logs
    up = UploadFolder()
    try:
        with pytest.raises(RoutefuseError, match=f"not a log \\({LOG_SUFFIXES_TEXT}\\)"):
            up.save("part.db3", b"x")
    finally:
        up.close()

"""The registry of log formats: one entry per format, and everything that names log files
(suffixes, wording, recognising a path, opening it) derived from it."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from estimator.errors import LogError
from estimator.io import (
    LOG_FORMATS,
    LOG_FORMATS_TEXT,
    LOG_SUFFIXES_TEXT,
    LogReader,
    describe_topics,
    is_log_path,
    log_suffixes,
    open_log_path,
    write_bag,
)
from estimator.log import GnssData, ImuData


def _drive(n: int = 400) -> tuple[ImuData, GnssData]:
    t = 1.7e9 + np.arange(n) * 0.01
    imu = ImuData(t, np.zeros((n, 3)), np.tile([0.0, 0.0, 9.81], (n, 1)))
    tg = t[::10]
    k = len(tg)
    gnss = GnssData(
        tg,
        np.full(k, 48.1),
        np.full(k, 11.5),
        np.full(k, 500.0),
        np.zeros(k, np.int8),
        np.full((k, 3), 1.0),
    )
    return imu, gnss


def test_every_format_is_a_log_reader_with_its_own_name_and_suffixes() -> None:
    seen: set[str] = set()
    for key, fmt in LOG_FORMATS.items():
        assert isinstance(fmt, LogReader)
        assert fmt.name == key and fmt.wording
        assert all(s.startswith(".") and s == s.lower() for s in fmt.suffixes)
        assert not seen & set(fmt.suffixes)
        seen |= set(fmt.suffixes)
    assert log_suffixes() == (".mcap", ".bag")


def test_wording_comes_from_the_formats() -> None:
    assert LOG_FORMATS_TEXT == "a ROS 2 bag folder, a .mcap file or a ROS 1 .bag"
    assert LOG_SUFFIXES_TEXT == ".mcap or .bag"
    for fmt in LOG_FORMATS.values():
        assert fmt.wording in LOG_FORMATS_TEXT


@pytest.mark.parametrize("storage", ["mcap", "ros1", "sqlite3", "mcap-folder"])
def test_each_storage_is_recognised_and_opened_by_one_format(tmp_path: Path, storage) -> None:
    imu, gnss = _drive()
    name = {"mcap": "drive.mcap", "ros1": "drive.bag"}.get(storage, "drive")
    path = tmp_path / name
    write_bag(path, imu=imu, gnss=gnss, storage=storage)
    claimed = [key for key, fmt in LOG_FORMATS.items() if fmt.recognises(path)]
    expected = {"mcap": "mcap", "ros1": "ros1"}.get(storage, "ros2")
    assert claimed == [expected] and is_log_path(path)
    fmt, source = open_log_path(path)
    assert fmt.name == expected
    assert source == path
    assert set(describe_topics(path)) == {"/imu/data", "/gnss/fix"}
    if path.is_dir():  # a file inside a bag folder is read with its folder
        member = next(p for p in path.iterdir() if p.suffix in (".db3", ".mcap"))
        assert is_log_path(member) and open_log_path(member) == (fmt, path)


def test_what_is_not_a_log(tmp_path: Path) -> None:
    (tmp_path / "notes.txt").write_text("x")
    (tmp_path / "loose.db3").write_bytes(b"x")
    (tmp_path / "plain").mkdir()
    for name in ("notes.txt", "loose.db3", "plain", "missing.db3"):
        assert not is_log_path(tmp_path / name)
    assert is_log_path(tmp_path / "upload.MCAP") and is_log_path(tmp_path / "upload.bag")
    with pytest.raises(LogError, match=f"expected {LOG_FORMATS_TEXT}"):
        open_log_path(tmp_path / "notes.txt")
    with pytest.raises(LogError, match="read with its bag folder"):
        open_log_path(tmp_path / "loose.db3")
    with pytest.raises(LogError, match=r"no metadata\.yaml"):
        open_log_path(tmp_path / "plain")
    with pytest.raises(LogError, match="no such file or folder"):
        open_log_path(tmp_path / "missing.mcap")


def test_a_folder_that_cannot_be_looked_into_is_a_one_line_log_error(tmp_path: Path, unreadable):
    locked = tmp_path / "bag"
    locked.mkdir()
    (locked / "metadata.yaml").write_text("x")
    unreadable(locked)
    with pytest.raises(LogError, match=r"bag: cannot open it \(Permission denied\)$"):
        open_log_path(locked)

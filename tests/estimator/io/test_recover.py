"""A ``.mcap`` cut off mid-write (no footer) is read up to its last whole record, with a warning
naming what was lost (:mod:`estimator.io.recover`); one with nothing whole is refused in one
line, at once when it has no mcap header."""

from __future__ import annotations

import re
import time
from pathlib import Path

import numpy as np
import pytest

from estimator.errors import LogError
from estimator.io import load_log
from estimator.io.recover import MCAP_MAGIC, ends_whole

SAMPLE = Path(__file__).resolve().parents[3] / "sample_logs" / "monaco_tunnel.mcap"
WARNING = re.compile(
    r"(?P<name>\S+): cut off \(no mcap footer: a recording stopped mid-write\?\): read its "
    r"(?P<n>\d+) whole messages, (?P<span>[\d.]+) s of log; the last (?P<lost>\d+) bytes, a "
    r"record cut in two, are lost$"
)


@pytest.fixture(scope="module")
def whole():
    return load_log(SAMPLE)


def _cut(tmp_path: Path, fraction: float) -> Path:
    data = SAMPLE.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: int(len(data) * fraction)])
    return cut


def test_a_cut_off_recording_is_read_up_to_its_last_whole_record(tmp_path, whole):
    cut = _cut(tmp_path, 0.6)
    assert ends_whole(SAMPLE) and not ends_whole(cut)
    log = load_log(cut, cache_dir=tmp_path / "cache")
    m = WARNING.match(log.warnings[0])
    assert m is not None, log.warnings
    assert m["name"] == "cut.mcap"
    assert 0 < int(m["lost"]) < cut.stat().st_size // 2
    assert float(m["span"]) == pytest.approx(log.t_end - log.t_start, abs=0.05)
    assert 60.0 < log.t_end - log.t_start < whole.t_end - whole.t_start - 60.0
    # what was read is the whole log's beginning, sample for sample
    n = len(log.imu.t)
    assert 1000 < n < len(whole.imu.t)
    np.testing.assert_array_equal(log.imu.t, whole.imu.t[:n])
    np.testing.assert_array_equal(log.imu.gyro, whole.imu.gyro[:n])
    k = len(log.gnss.t)
    np.testing.assert_array_equal(log.gnss.lat, whole.gnss.lat[:k])
    assert not any("cut off" in w for w in whole.warnings)


@pytest.mark.parametrize(
    ("content", "problem"),
    [
        (lambda data: data[:20], "not one whole message before the damage"),
        (lambda data: data[:200], "not one whole message before the damage"),
        (lambda data: MCAP_MAGIC + bytes(5_000_000), "no mcap header after the magic"),
    ],
    ids=["cut in the header", "cut before any message", "magic then zeros"],
)
def test_nothing_whole_is_refused_in_one_line_at_once(tmp_path, content, problem):
    path = tmp_path / "bad.mcap"
    path.write_bytes(content(SAMPLE.read_bytes()))
    t0 = time.perf_counter()
    with pytest.raises(LogError) as err:
        load_log(path, cache_dir=tmp_path / "cache")
    text = str(err.value)
    assert text.startswith(f"{path}: cannot read the bag, it is truncated or corrupt (")
    assert problem in text and "\n" not in text
    assert time.perf_counter() - t0 < 5.0

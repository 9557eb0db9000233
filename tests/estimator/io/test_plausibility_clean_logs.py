"""Every check at load stays quiet on a clean log: the bundled samples and the real logs (the
comma2k19 car, the Husky robot) read without a single warning. Each check added to
estimator.io.plausibility (clock offsets and steps, held or coasting fixes, the gyro's scale,
dead axes, far fixes, ...) is held to it at once, here, rather than each by a test of its own."""

from __future__ import annotations

from pathlib import Path

import pytest

from estimator.io import load_log

REPO = Path(__file__).resolve().parents[3]
SAMPLES = sorted((REPO / "sample_logs").glob("*.mcap"))
REAL_LOGS = ("comma2k19/i280.mcap", "robot_localization/test1.bag")


@pytest.mark.parametrize("sample", SAMPLES, ids=lambda p: p.stem)
def test_a_bundled_sample_reads_without_a_warning(sample: Path) -> None:
    assert load_log(sample, cache_dir=None).warnings == ()


@pytest.mark.parametrize("name", REAL_LOGS)
def test_a_real_log_reads_without_a_warning(shared_data: Path, name: str) -> None:
    path = shared_data / name
    if not path.exists():
        pytest.skip(f"real data not found: {path}")
    assert load_log(path, cache_dir=None).warnings == ()

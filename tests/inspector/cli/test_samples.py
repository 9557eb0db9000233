"""Finding the bundled sample logs in both install layouts, without building a venv: package
data beside ``inspector/`` (a ``pip install``) and ``sample_logs/`` at the top of a checkout."""

from __future__ import annotations

from pathlib import Path

import pytest

from inspector.cli.samples import DEFAULT_SAMPLE, find_sample_logs, sample_log_candidates


def _layout(root: Path, samples: Path | None) -> Path:
    inspector = root / "inspector"
    inspector.mkdir(parents=True)
    if samples is not None:
        samples.mkdir(parents=True)
        (samples / f"{DEFAULT_SAMPLE}.mcap").write_bytes(b"\x89MCAP0\r\n")
    return inspector


def test_installed_package_data_beside_the_package(tmp_path: Path) -> None:
    site = tmp_path / "site-packages"
    inspector = _layout(site, site / "inspector" / "sample_logs")
    assert find_sample_logs(inspector) == inspector / "sample_logs"


def test_source_checkout_top_level_folder(tmp_path: Path) -> None:
    inspector = _layout(tmp_path, tmp_path / "sample_logs")
    assert find_sample_logs(inspector) == tmp_path / "sample_logs"


def test_package_data_wins_over_a_stray_checkout_folder(tmp_path: Path) -> None:
    inspector = _layout(tmp_path, tmp_path / "inspector" / "sample_logs")
    (tmp_path / "sample_logs").mkdir()
    (tmp_path / "sample_logs" / f"{DEFAULT_SAMPLE}.mcap").write_bytes(b"")
    assert find_sample_logs(inspector) == inspector / "sample_logs"


def test_a_folder_without_the_default_sample_is_not_the_samples(tmp_path: Path) -> None:
    inspector = _layout(tmp_path, None)
    (tmp_path / "sample_logs").mkdir()
    assert find_sample_logs(inspector) is None
    assert sample_log_candidates(inspector) == (
        inspector / "sample_logs",
        tmp_path / "sample_logs",
    )


def test_this_checkout_has_its_samples_and_their_attribution() -> None:
    found = find_sample_logs()
    if found is None:
        pytest.skip("no sample logs in this checkout")
    assert (found / "ATTRIBUTION").is_file()
    assert (found / f"{DEFAULT_SAMPLE}.route.geojson").is_file()


def test_setup_ships_every_sample_file_as_package_data() -> None:
    """setup.py's package-data patterns cover every file of the samples folder."""
    import ast
    import fnmatch

    repo = Path(__file__).resolve().parents[3]
    setup = repo / "setup.py"
    if not setup.is_file():
        pytest.skip("not a source checkout")
    patterns = next(
        ast.literal_eval(node.value)
        for node in ast.walk(ast.parse(setup.read_text()))
        if isinstance(node, ast.Assign)
        and any(isinstance(t, ast.Name) and t.id == "SAMPLE_FILES" for t in node.targets)
    )
    samples = repo / "sample_logs"
    files = [p.relative_to(samples).as_posix() for p in samples.rglob("*") if p.is_file()]
    missed = [f for f in files if not any(fnmatch.fnmatch(f, pat) for pat in patterns)]
    assert files and not missed

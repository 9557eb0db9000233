"""Inputs that used to crash, hang or print unbounded messages: each is one line on stderr and
exit 3, through :func:`inspector.cli.main.main`."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

from inspector.cli.main import main

SAMPLES = Path(__file__).resolve().parents[3] / "sample_logs"
LOG = SAMPLES / "long_tunnel.mcap"
ROUTE = SAMPLES / "long_tunnel.route.geojson"


@pytest.fixture(autouse=True)
def _cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ROUTEFUSE_CACHE_DIR", str(tmp_path / "cache"))


PROGRESS = re.compile(r"routefuse \w+: [\w ]+ +\d+%")
"""a progress line, which a slow machine prints before the error (after a second of work)"""


def _fails(argv: list[str], capsys: pytest.CaptureFixture[str], *words: str) -> str:
    assert main(argv) == 3
    err = "".join(
        line
        for line in capsys.readouterr().err.splitlines(True)
        if not PROGRESS.fullmatch(line.strip())
    )
    assert err.count("\n") == 1 and len(err) < 500, err[:2000]
    for word in words:
        assert word in err, err
    return err


def _run(*extra: str) -> list[str]:
    return ["run", str(LOG), "--route", str(ROUTE), *extra]


@pytest.mark.parametrize(
    ("assignment", "word"),
    [
        ("sensors.initial_heading_deg=inf", "finite"),
        ("sensors.gnss_lever_arm_m=nan,0,0", "finite"),
        ("sensors.gnss_lever_arm_m=1e300,0,0", "outside"),
        ("no_such.parameter=1", "unknown parameter"),
    ],
)
def test_bad_parameter_values(
    assignment: str, word: str, capsys: pytest.CaptureFixture[str]
) -> None:
    _fails(_run("--set", assignment), capsys, word)


@pytest.mark.parametrize(
    "body",
    [",,,\n,,,\n", '"""\n"\n', "lat,lon\n" + "1" * 140_000 + ",2\n"],
    ids=["commas", "quotes", "long field"],
)
def test_csv_routes_that_are_not_routes(
    body: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    route = tmp_path / "route.csv"
    route.write_text(body)
    _fails(["run", str(LOG), "--route", str(route)], capsys, str(route))


def test_simulate_out_is_a_file(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "taken"
    out.write_text("x")
    _fails(["simulate", "short_tunnel", "--out", str(out)], capsys, str(out))


def test_simulate_negative_seed(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    _fails(["simulate", "short_tunnel", "--seed", "-1", "--out", str(tmp_path)], capsys, "seed")


@pytest.mark.parametrize(
    ("extra", "word"),
    [
        (["--max-upload-mb", "nan"], "max-upload-mb"),
        (["--port", "99999"], "port"),
        (["--host", "999.1.1.1"], "999.1.1.1"),
    ],
)
def test_serve_bad_options(
    extra: list[str], word: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    _fails(["serve", str(tmp_path), *extra], capsys, word)


@pytest.mark.parametrize("what", ["route", "config"])
def test_a_fifo_is_not_read(what: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    fifo = tmp_path / ("pipe.csv" if what == "route" else "pipe.toml")
    os.mkfifo(fifo)
    extra = (
        ["--route", str(fifo)]
        if what == "route"
        else ["--route", str(ROUTE), "--config", str(fifo)]
    )
    _fails(["run", str(LOG), *extra], capsys, str(fifo), "regular file")


def test_config_dev_zero(capsys: pytest.CaptureFixture[str]) -> None:
    _fails(_run("--config", "/dev/zero"), capsys, "/dev/zero", "regular file")


def test_symlink_loop_is_named(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    loop = tmp_path / "loop.mcap"
    loop.symlink_to(loop)
    _fails(["run", str(loop), "--route", str(ROUTE)], capsys, "symbolic links")


@pytest.mark.parametrize(("outage", "word"), [("30:inf", "finite"), ("-100:-50", "negative")])
def test_outage_causes(outage: str, word: str, capsys: pytest.CaptureFixture[str]) -> None:
    _fails(_run(f"--outage={outage}"), capsys, word)


def test_serve_names_a_symlink_loop(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    loop = tmp_path / "loop.mcap"
    loop.symlink_to(loop)
    _fails(["serve", str(loop), "--route", str(ROUTE)], capsys, "symbolic links")

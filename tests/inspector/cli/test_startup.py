"""Start-up is not the bottleneck (issue 15, property 11): building the parser, which is all
``routefuse --help`` does, imports none of the heavy libraries; each command imports what it
needs when it runs. Checked in a fresh interpreter, so this test's own imports do not count."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

HEAVY = ("numpy", "numba", "scipy", "pyproj", "rosbags", "viser", "matplotlib")
REPO = Path(__file__).resolve().parents[3]


def _imported_after(code: str) -> list[str]:
    probe = f"import sys\n{code}\nprint(' '.join(m for m in {HEAVY!r} if m in sys.modules))"
    out = subprocess.run(
        [sys.executable, "-c", probe], cwd=REPO, capture_output=True, text=True, check=True
    )
    return out.stdout.split()


def test_building_the_parser_imports_nothing_heavy() -> None:
    assert _imported_after("from inspector.cli.main import build_parser; build_parser()") == []


def test_the_log_registry_and_the_estimator_face_are_light() -> None:
    code = "import estimator, estimator.io; estimator.io.LOG_FORMATS_TEXT"
    assert _imported_after(code) == []


NOT_FOR_RUN = (
    "viser",
    "matplotlib",
    "dask",
    "rosbags",  # the log comes from the decoded-log cache on a warm start
    "scipy.ndimage",
    "scipy.signal",
    "scipy.stats",
    "scipy.spatial",
    "inspector.app",
    "inspector.controller",
    "estimator.sim",
    "inspector.cli.serve",  # nor the other commands' modules (their options are not built)
    "inspector.cli.export",
    "inspector.cli.bench",
    "inspector.cli.sweep",
    "inspector.cli.simulate",
    "tomllib",  # read only for --config
    "tomli_w",
)


def test_run_imports_only_what_the_estimation_needs(tmp_path: Path) -> None:
    """``routefuse run`` (started twice: the second start reads the decoded-log cache, as a
    warm start does) imports neither the inspector's browser side nor the simulator, nor any
    scipy module besides ``scipy.linalg``, which numba itself imports for BLAS, nor the other
    commands' modules."""
    log = REPO / "sample_logs" / "monaco_tunnel.mcap"
    route = REPO / "sample_logs" / "monaco_tunnel.route.geojson"
    code = (
        "import contextlib, io, sys\n"
        "from inspector.cli.main import main\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        f"    assert main(['run', {str(log)!r}, '--route', {str(route)!r}, '--quiet']) == 0\n"
        f"print(' '.join(m for m in {NOT_FOR_RUN!r} if m in sys.modules))"
    )
    env = dict(os.environ, ROUTEFUSE_CACHE_DIR=str(tmp_path))
    for _ in range(2):
        out = subprocess.run(
            [sys.executable, "-c", code], cwd=REPO, env=env, capture_output=True, text=True
        )
        assert out.returncode == 0, out.stderr
    assert out.stdout.split() == []


def test_help_prints_every_command() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "inspector", "--help"],
        cwd=REPO,
        capture_output=True,
        text=True,
        check=True,
    ).stdout
    for name in ("info", "run", "simulate", "serve", "export", "bench"):
        assert name in out


def test_a_parser_for_one_command_parses_it_as_the_whole_parser_does() -> None:
    from inspector.cli.main import _command_of, build_parser

    argv = ["--debug", "run", "a.mcap", "--route", "r.geojson", "--method", "proposed"]
    assert _command_of(argv) == "run" and _command_of(["--version"]) is None
    whole, one = build_parser().parse_args(argv), build_parser("run").parse_args(argv)
    assert vars(whole) == vars(one)
    assert build_parser("run").format_usage() == build_parser().format_usage()
    assert build_parser("nonsense").format_help() == build_parser().format_help()

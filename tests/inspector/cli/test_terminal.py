"""Names from the disk or the command line reach the terminal as text: an escape sequence in a
file or route line name cannot retitle, clear or recolour it, nor split a one-line error."""

from __future__ import annotations

import io
import json
from pathlib import Path

import pytest

from inspector.cli.main import main
from inspector.cli.terminal import ERASE_LINE, PrintableStream, one_line, printable

SAMPLES = Path(__file__).resolve().parents[3] / "sample_logs"
LOG = SAMPLES / "monaco_tunnel.mcap"
TITLE = "\x1b]0;pwned\x07"
CLEAR_RED = "\x1b[2J\x1b[31mRED\x1b[0m"


@pytest.fixture(autouse=True)
def _cache(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("ROUTEFUSE_CACHE_DIR", str(tmp_path / "cache"))


def _raw_control(text: str) -> list[str]:
    return [c for c in text if (ord(c) < 32 and c not in "\n\t") or 0x7F <= ord(c) <= 0x9F]


def test_controls_are_shown_as_escapes_and_text_is_kept() -> None:
    assert printable(f"a{TITLE}b\tc\nd") == "a\\x1b]0;pwned\\x07b\tc\nd"
    assert printable("\u202eevil\u202c \x9b") == "\\u202eevil\\u202c \\x9b"
    assert one_line("first\nsecond\r\u2028") == "first\\x0asecond\\x0d\\u2028"
    assert printable("Tübingen 5 °C, ±1 m") == "Tübingen 5 °C, ±1 m"


def test_the_stream_keeps_only_its_own_erase_line() -> None:
    raw = io.StringIO()
    stream = PrintableStream(raw)
    stream.write(f"\r{ERASE_LINE}{CLEAR_RED}: 50%")
    assert raw.getvalue() == f"\r{ERASE_LINE}\\x1b[2J\\x1b[31mRED\\x1b[0m: 50%"
    assert stream.getvalue() == raw.getvalue()  # the rest is the wrapped stream's


def test_a_route_file_named_with_a_terminal_title_sequence(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    route = tmp_path / f"bell{TITLE}.geojson"
    route.write_text("x")
    assert main(["info", str(LOG), "--route", str(route)]) == 3
    err = capsys.readouterr().err
    assert _raw_control(err) == []
    assert err.count("\n") == 1 and "bell\\x1b]0;pwned\\x07.geojson: not valid JSON" in err


def test_a_route_line_name_that_clears_the_screen_and_breaks_the_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    coords = [[7.4, 43.72], [7.41, 43.73]]
    features = [
        {
            "type": "Feature",
            "properties": {"name": name},
            "geometry": {"type": "LineString", "coordinates": coords},
        }
        for name in ("a", f"{CLEAR_RED}\nsecond line")
    ]
    route = tmp_path / "names.geojson"
    route.write_text(json.dumps({"type": "FeatureCollection", "features": features}))
    assert main(["info", str(LOG), "--route", str(route)]) == 3
    err = capsys.readouterr().err
    assert _raw_control(err) == []
    assert err.count("\n") == 1 and "\\x1b[2J\\x1b[31mRED\\x1b[0m\\x0asecond line" in err


def test_a_topic_typed_with_controls(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["info", str(LOG), "--imu-topic", f"/x{TITLE}\nline2"]) == 3
    captured = capsys.readouterr()
    assert _raw_control(captured.err + captured.out) == []
    assert captured.err.count("\n") == 1 and "/x\\x1b]0;pwned\\x07\\x0aline2" in captured.err

"""Peak memory and time of reading route files near the caps (``MAX_ROUTE_BYTES``,
``MAX_ROUTE_POINTS``): one file per format and shape, each read in a fresh Python process.

    python benchmarks/route_parse_memory.py [--dir DIR] [--only NAME ...] [--json]

The files are written once into ``DIR`` (default ``<routefuse cache>/bench/routes``) and reused.
Each is read by ``read_route_lines`` (every line, as ``routefuse info`` does) and by
``read_route_file`` (the route a run uses: a file of several lines is refused with its list of
lines, which is read whole too); a refusal is a result, named in the table. Peak RSS is the
reading process's VmHWM (interpreter and numpy included: :data:`IDLE_NOTE`); times are the
CPU time of the call (the stable figure on a shared machine) and its elapsed time.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import time
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TextIO

REPO = Path(__file__).resolve().parents[1]

LINE_POINTS = 1_900_000
"""Points of the one-line files: just under ``MAX_ROUTE_POINTS`` (2 M)."""
CSV_OVER_POINTS = 2_400_000
"""Rows of the CSV over the point cap (14 MB): refused for its point count."""
FEATURES = 130_000
"""GeoJSON features of :data:`FEATURE_POINTS` points each (39 MB)."""
FEATURE_POINTS = 10
WIDE_TRACKS = 800_000
"""GPX tracks of one or two points each (49 MB): the file of most lines (``read_route_lines``
refuses its second, of one point)."""
LONG_GPX_POINTS = 1_700_000
"""Track points of the one-track GPX (48 MB; 1.9 M would pass ``MAX_ROUTE_BYTES``)."""
PLACEMARKS = 450_000
"""KML placemarks of two points each (47 MB)."""
TRACKS = 600_000
"""GPX tracks of two points each (46 MB)."""
PEAK_RSS_TARGET_MB = 450.0
"""Goal for every file here and both readers (peak RSS of the reading process): GeoJSON sets it,
as ``json.loads`` of 1.3-1.9 M positions builds 300-350 MB of Python lists, floats and dicts
before a number is read; listing 600 k tracks (``read_route_lines``) comes near it too, with a
``RouteLine`` of three arrays each. Measured: 412 MB (docs/performance.md)."""
XML_CSV_ROUTE_TARGET_MB = 250.0
"""Goal for reading the route of a GPX, KML or CSV file (``read_route_file``): their parsers
hold the file's bytes and the points, not a tree or a row per point. Measured: 198 MB."""
IDLE_NOTE = "an idle reader process (Python, numpy, routefile imported) peaks at about 50 MB"
READERS = ("lines", "file")


@dataclass(frozen=True)
class RouteCase:
    """A route file of the benchmark: its name on disk, what it holds, how it is written."""

    name: str
    what: str
    write: Callable[[TextIO], None]


def _zigzag(n: int) -> Iterator[tuple[float, float]]:
    """(lat, lon) 1 m apart along a parallel, alternately 1 m north and south of it."""
    for i in range(n):
        yield 48.0 + (i % 2) * 1e-5, 11.0 + i * 1e-5


def _geojson_line(out: TextIO) -> None:
    out.write('{"type":"Feature","properties":{"name":"zigzag"},')
    out.write('"geometry":{"type":"LineString","coordinates":[')
    out.write(",".join(f"[{lon:.6f},{lat:.6f}]" for lat, lon in _zigzag(LINE_POINTS)))
    out.write("]}}\n")


def _geojson_features(out: TextIO) -> None:
    out.write('{"type":"FeatureCollection","features":[\n')
    for k in range(FEATURES):
        coords = ",".join(
            f"[{lon + k * 1e-4:.6f},{lat:.6f}]" for lat, lon in _zigzag(FEATURE_POINTS)
        )
        out.write(
            f'{"," if k else ""}{{"type":"Feature","properties":{{"name":"f{k}"}},'
            f'"geometry":{{"type":"LineString","coordinates":[{coords}]}}}}\n'
        )
    out.write("]}\n")


def _gpx_wide(out: TextIO) -> None:
    out.write('<?xml version="1.0" encoding="UTF-8"?>\n<gpx version="1.1">\n')
    for k in range(WIDE_TRACKS):
        second = '<trkpt lat="4.2" lon="1"/>' if k % 4 == 0 else ""
        out.write(f'<trk><trkseg><trkpt lat="4.1" lon="1"/>{second}</trkseg></trk>\n')
    out.write("</gpx>\n")


def _gpx_tracks(out: TextIO) -> None:
    out.write('<?xml version="1.0" encoding="UTF-8"?>\n<gpx version="1.1">\n')
    for _ in range(TRACKS):
        out.write(
            '<trk><trkseg><trkpt lat="4.1" lon="1"/><trkpt lat="4.2" lon="1"/></trkseg></trk>'
        )
    out.write("\n</gpx>\n")


def _gpx_long(out: TextIO) -> None:
    out.write('<?xml version="1.0" encoding="UTF-8"?>\n<gpx version="1.1"><trk><trkseg>\n')
    for k in range(LONG_GPX_POINTS):
        out.write(f'<trkpt lat="4.{1 + k % 2}" lon="1"/>')
    out.write("\n</trkseg></trk></gpx>\n")


def _kml_placemarks(out: TextIO) -> None:
    out.write('<?xml version="1.0" encoding="UTF-8"?>\n<kml><Document>\n')
    for k in range(PLACEMARKS):
        out.write(
            f"<Placemark><name>p{k}</name><LineString><coordinates>1,4 1,4.1"
            "</coordinates></LineString></Placemark>\n"
        )
    out.write("</Document></kml>\n")


def _csv_rows(n: int) -> Callable[[TextIO], None]:
    def write(out: TextIO) -> None:
        out.write("lat,lon\n")
        out.writelines(f"4.{1 + k % 2},1\n" for k in range(n))

    return write


ROUTE_CASES: tuple[RouteCase, ...] = (
    RouteCase("line.geojson", f"one LineString of {LINE_POINTS:,} points", _geojson_line),
    RouteCase(
        "features.geojson",
        f"{FEATURES:,} LineString features of {FEATURE_POINTS} points",
        _geojson_features,
    ),
    RouteCase("wide.gpx", f"{WIDE_TRACKS:,} tracks of 1-2 points", _gpx_wide),
    RouteCase("tracks.gpx", f"{TRACKS:,} tracks of 2 points", _gpx_tracks),
    RouteCase("long.gpx", f"one track of {LONG_GPX_POINTS:,} points", _gpx_long),
    RouteCase("placemarks.kml", f"{PLACEMARKS:,} placemarks of 2 points", _kml_placemarks),
    RouteCase("rows.csv", f"{LINE_POINTS:,} rows", _csv_rows(LINE_POINTS)),
    RouteCase(
        "over.csv", f"{CSV_OVER_POINTS:,} rows (over the point cap)", _csv_rows(CSV_OVER_POINTS)
    ),
)
CASE_NAMES = tuple(c.name for c in ROUTE_CASES)


def ensure_file(folder: Path, case: RouteCase) -> Path:
    path = folder / case.name
    if not path.exists():
        folder.mkdir(parents=True, exist_ok=True)
        part = path.with_name(path.name + ".part")
        with part.open("w", encoding="utf-8", newline="\n") as out:
            case.write(out)
        part.replace(path)
    return path


def _peak_rss_mb() -> float:
    """VmHWM, as :mod:`benchmarks.measures` reads it (``ru_maxrss`` inherits the parent's)."""
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return float(line.split()[1]) / 1024.0
    return float("nan")


def read_once(path: Path, reader: str) -> dict[str, Any]:
    """In the reading process: read ``path`` once; its figures and outcome."""
    from estimator.errors import RouteError
    from estimator.io.routefile import read_route_file, read_route_lines

    idle = _peak_rss_mb()
    started, cpu = time.perf_counter(), time.process_time()
    try:
        if reader == "lines":
            lines = read_route_lines(path)
            outcome = f"{len(lines)} lines, {sum(len(x.lat) for x in lines)} points"
        else:
            line = read_route_file(path)
            outcome = f"1 line, {len(line.lat)} points"
    except RouteError as exc:
        outcome = f"refused: {str(exc).split(': ', 1)[-1][:70]}"
    return {
        "wall_s": time.perf_counter() - started,
        "cpu_s": time.process_time() - cpu,
        "peak_rss_mb": _peak_rss_mb(),
        "idle_rss_mb": idle,
        "outcome": outcome,
    }


def measure(path: Path, reader: str) -> dict[str, Any]:
    """``read_once`` in a fresh process."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(REPO), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
    proc = subprocess.run(
        [sys.executable, str(Path(__file__).resolve()), "--read", str(path), reader],
        env=env,
        capture_output=True,
        text=True,
        check=False,
    )
    if proc.returncode != 0:
        tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
        raise RuntimeError(f"reading {path.name} failed: {tail}")
    result: dict[str, Any] = json.loads(proc.stdout.strip().splitlines()[-1])
    return result


def default_dir() -> Path:
    from estimator.io import default_cache_dir

    return default_cache_dir() / "bench" / "routes"


def run_cases(
    folder: Path, only: Sequence[str] = (), say: Callable[[str], None] = lambda _: None
) -> list[dict[str, Any]]:
    """Every chosen case (a name or its prefix), each reader: one row each."""
    rows = []
    for case in ROUTE_CASES:
        if only and not any(case.name.startswith(o) for o in only):
            continue
        path = ensure_file(folder, case)
        for reader in READERS:
            say(f"{case.name} ({reader})")
            row = {"file": case.name, "what": case.what, "mb": path.stat().st_size / 1e6}
            rows.append({**row, "reader": reader, **measure(path, reader)})
    return rows


def summary(rows: Sequence[dict[str, Any]]) -> dict[str, float]:
    """The figures of ``routefuse bench``'s ``route_parse`` item: each file's peak RSS and time
    per reader, the worst peak, and the worst of reading a GPX, KML or CSV file's route."""
    figures: dict[str, float] = {}
    for r in rows:
        key = f"{r['file'].replace('.', '_')}_{r['reader']}"
        figures[f"{key}_peak_rss_mb"] = r["peak_rss_mb"]
        figures[f"{key}_wall_s"] = r["wall_s"]
        figures[f"{key}_cpu_s"] = r["cpu_s"]
    if rows:
        figures["worst_peak_rss_mb"] = max(r["peak_rss_mb"] for r in rows)
    routes = [
        r["peak_rss_mb"]
        for r in rows
        if r["reader"] == "file" and not r["file"].endswith(".geojson")
    ]
    if routes:
        figures["xml_csv_route_peak_rss_mb"] = max(routes)
    return figures


def format_rows(rows: Sequence[dict[str, Any]]) -> str:
    head = ("file", "MB", "what", "reader", "peak MB", "cpu s", "wall s", "outcome")
    table = [head] + [
        (
            r["file"],
            f"{r['mb']:.1f}",
            r["what"],
            r["reader"],
            f"{r['peak_rss_mb']:.0f}",
            f"{r['cpu_s']:.2f}",
            f"{r['wall_s']:.2f}",
            r["outcome"],
        )
        for r in rows
    ]
    widths = [max(len(t[i]) for t in table) for i in range(len(head))]
    lines = ["  ".join(c.ljust(w) for c, w in zip(t, widths, strict=True)) for t in table]
    figures = summary(rows)
    for figure, target in (
        ("worst_peak_rss_mb", PEAK_RSS_TARGET_MB),
        ("xml_csv_route_peak_rss_mb", XML_CSV_ROUTE_TARGET_MB),
    ):
        value = figures.get(figure, float("nan"))
        verdict = "met" if value <= target else "MISSED"
        lines.append(f"{figure} {value:.0f}; target <= {target:.0f} MB: {verdict}")
    lines.append(IDLE_NOTE)
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--dir", type=Path, help="where the route files are written")
    parser.add_argument("--only", nargs="+", default=(), help="file names (or prefixes)")
    parser.add_argument("--json", action="store_true", help="rows as JSON")
    parser.add_argument("--read", nargs=2, metavar=("PATH", "READER"), help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.read:
        print(json.dumps(read_once(Path(args.read[0]), args.read[1])))
        return 0
    rows = run_cases(args.dir or default_dir(), args.only, say=lambda s: print(s, file=sys.stderr))
    print(json.dumps(rows, indent=1) if args.json else format_rows(rows))
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(REPO))
    with contextlib.suppress(BrokenPipeError):
        sys.exit(main())

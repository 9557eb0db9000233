"""What ``routefuse info`` reports about a log: its topics and rates, GNSS outages, distances
travelled, and how far it is from a route."""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from estimator.io.routefile import read_route_lines, route_in_frame
from estimator.log import Log, wheel_gap_s
from estimator.nav.frames import LocalFrame
from estimator.pipeline.inputs import Inputs, route_distances

MIN_OUTAGE_S = 1.0
ESTIMATED_RATE_NOTE = (
    "  rate: 1 / median interval between messages; ~: count / span (a topic routefuse does not "
    "decode)"
)
"""The line under the topic table when a rate is only count / span."""
SMOOTHING_FIXES = 5
SILENT_S = 5.0
"""every stream silent longer than this (the filter's IMU gap) is named in ``info``"""


@dataclass(frozen=True)
class TopicLine:
    topic: str
    msgtype: str
    count: int
    rate_hz: float
    role: str
    rate_measured: bool
    """True: 1 / the median interval between its messages; False: only count / span (a topic
    the estimator does not read, so its times are not decoded), shown with ``~``"""


@dataclass(frozen=True)
class RouteSummary:
    path: str
    name: str
    length_m: float
    vertices: int
    distance_median_m: float
    distance_p95_m: float
    distance_max_m: float


@dataclass(frozen=True)
class LogSummary:
    path: str
    t_start: float
    span_s: float
    topics: tuple[TopicLine, ...]
    gnss_fixes: int
    gnss_valid: int
    outages: tuple[tuple[float, float], ...]
    """(start, end) of each gap in valid fixes longer than the outage threshold, s after start"""
    outage_threshold_s: float
    distances: tuple[tuple[str, float], ...]
    """(source, metres) for every source the log has"""
    warnings: tuple[str, ...]
    route: RouteSummary | None = None


def _rate(t: NDArray[np.float64]) -> float:
    """The stream's own rate: 1 / the median interval between consecutive messages, so an
    outage (a GNSS receiver at 5 Hz silent for two minutes) or a pause does not lower it; NaN
    without two messages at distinct times."""
    dt = np.diff(t)
    dt = dt[dt > 0]
    return 1.0 / float(np.median(dt)) if len(dt) else float("nan")


def gnss_outages(log: Log) -> tuple[tuple[tuple[float, float], ...], float]:
    """Gaps without a valid fix longer than max(1 s, 2.5 fix intervals), in s after the start."""
    tv = log.gnss.t[log.gnss.valid]
    t0, t1 = log.t_start, log.t_end
    if len(tv) == 0:
        return ((0.0, t1 - t0),), MIN_OUTAGE_S
    interval = float(np.median(np.diff(tv))) if len(tv) > 1 else 0.0
    thr = max(MIN_OUTAGE_S, 2.5 * interval)
    edges = np.r_[min(t0, tv[0]), tv, max(t1, tv[-1])]
    gaps = np.flatnonzero(np.diff(edges) > thr)
    return tuple((float(edges[i] - t0), float(edges[i + 1] - t0)) for i in gaps), thr


def _path_length(xy: NDArray[np.float64]) -> float:
    return float(np.sum(np.hypot(*np.diff(xy, axis=0).T))) if len(xy) > 1 else 0.0


def _has_gaps(log: Log) -> bool:
    """Valid fixes more than 2 s apart: the fixes' path cuts across the gap."""
    t = log.gnss.t[log.gnss.valid]
    return len(t) > 1 and bool(np.max(np.diff(t)) > 2.0)


def distances_travelled(log: Log, frame: LocalFrame | None) -> tuple[tuple[str, float], ...]:
    """Distance travelled by every source the log has, each named (positions need a frame)."""
    out: list[tuple[str, float]] = []
    if log.wheel is not None and len(log.wheel.t) > 1:
        w = log.wheel
        dt_w = np.diff(w.t)
        bridged = dt_w <= wheel_gap_s(w.t)
        step = 0.5 * np.abs(w.speed[1:] + w.speed[:-1]) * dt_w
        skipped = int(np.count_nonzero(~bridged))
        label = "wheel-speed integral"
        if skipped:
            label += f" ({skipped} gap{'s' if skipped > 1 else ''} between samples left out)"
        out.append((label, float(np.sum(step[bridged]))))
    ok = log.gnss.valid
    if frame is not None and np.count_nonzero(ok) > SMOOTHING_FIXES:
        enu = frame.to_enu(log.gnss.lat[ok], log.gnss.lon[ok], log.gnss.alt[ok])[:, :2]
        kernel = np.ones(SMOOTHING_FIXES) / SMOOTHING_FIXES
        smooth = np.column_stack([np.convolve(enu[:, i], kernel, "valid") for i in range(2)])
        gaps = " (outages crossed in a straight line)" if _has_gaps(log) else ""
        out.append(
            (f"GNSS fixes, {SMOOTHING_FIXES}-fix moving average{gaps}", _path_length(smooth))
        )
    if frame is not None and log.truth is not None:
        tr = log.truth
        enu = frame.to_enu(tr.lat, tr.lon, tr.alt)[:, :2]
        out.append(("ground truth", _path_length(enu[np.all(np.isfinite(enu), axis=1)])))
    return tuple(out)


def _duration(seconds: float) -> str:
    for unit, size in (("days", 86400.0), ("h", 3600.0), ("min", 60.0)):
        if seconds >= 2 * size:
            return f"{seconds / size:.1f} {unit}"
    return f"{seconds:.1f} s"


def _silences(log: Log, streams: dict[str, NDArray[np.float64]]) -> tuple[str, ...]:
    """One line per stretch in which no stream has a sample (longer than :data:`SILENT_S`):
    a paused recording, or a clock that jumped forward. It shows otherwise only as a GNSS
    outage, which reads as a tunnel."""
    imu = streams["imu"]
    gaps = np.flatnonzero(np.diff(imu) > SILENT_S)
    lines = []
    for k in gaps:
        a, b = float(imu[k]), float(imu[k + 1])
        if any(np.any((t > a) & (t < b)) for t in streams.values()):
            continue
        lines.append(
            f"{Path(log.path).name}: every stream is silent at {a - log.t_start:.1f}-"
            f"{b - log.t_start:.1f} s ({_duration(b - a)}): the recording paused, or its "
            "clock jumped forward"
        )
    return tuple(lines)


def summarize(inputs: Inputs | Log) -> LogSummary:
    """What ``routefuse info`` prints; a bare Log (no position to place a frame at) gets
    neither GNSS nor truth distances."""
    if isinstance(inputs, Log):
        log, frame, route = inputs, None, None
    else:
        log, frame, route = inputs.log, inputs.frame, inputs.route
    streams = {"imu": log.imu.t, "gnss": log.gnss.t}
    if log.wheel is not None:
        streams["wheel"] = log.wheel.t
    if log.truth is not None:
        streams["truth"] = log.truth.t
    starts = [t[0] for t in streams.values() if len(t)]
    ends = [t[-1] for t in streams.values() if len(t)]
    span = float(max(ends) - min(starts))
    lines = []
    for info in log.topics:
        t = streams.get(info.role)
        measured = t is not None and len(t) > 1
        if t is not None and measured:
            rate = _rate(t)
        else:
            rate = info.count / span if span > 0 else float("nan")
        lines.append(TopicLine(info.topic, info.msgtype, info.count, rate, info.role, measured))
    outages, thr = gnss_outages(log)
    silences = _silences(log, streams)
    route_summary = None
    if route is not None and frame is not None:
        r = route
        d = route_distances(log, r, frame)
        stats = (np.median(d), np.percentile(d, 95), d.max()) if len(d) else (np.nan,) * 3
        route_summary = RouteSummary(
            r.source, r.name, r.length, len(r.xy), *(float(v) for v in stats)
        )
    return LogSummary(
        path=log.path,
        t_start=float(min(starts)),
        span_s=span,
        topics=tuple(lines),
        gnss_fixes=len(log.gnss.t),
        gnss_valid=int(np.count_nonzero(log.gnss.valid)),
        outages=outages,
        outage_threshold_s=thr,
        distances=distances_travelled(log, frame),
        warnings=log.warnings + silences + (route.warnings if route is not None else ()),
        route=route_summary,
    )


def _clock(t: float) -> str:
    if t > 1e8:  # Unix time
        stamp = dt.datetime.fromtimestamp(t, tz=dt.UTC)
        return stamp.strftime("%Y-%m-%d %H:%M:%S.") + f"{stamp.microsecond // 1000:03d} UTC"
    return f"{t:.3f} s"


def format_summary(s: LogSummary) -> str:
    out = [f"log       {s.path}", f"start     {_clock(s.t_start)}   span {s.span_s:.2f} s", ""]
    width = max((len(t.topic) for t in s.topics), default=5)
    twidth = max((len(t.msgtype) for t in s.topics), default=4)
    out.append(f"  {'topic':<{width}}  {'type':<{twidth}}  {'count':>7}  {'rate':>10}  role")
    for t in s.topics:
        rate = f"{t.rate_hz:.1f} Hz" if np.isfinite(t.rate_hz) else "-"
        rate = rate if t.rate_measured else f"~{rate}"
        out.append(
            f"  {t.topic:<{width}}  {t.msgtype:<{twidth}}  {t.count:>7}  {rate:>10}  "
            f"{t.role or '(unused)'}"
        )
    if any(not t.rate_measured for t in s.topics):
        out.append(ESTIMATED_RATE_NOTE)
    out.append("")
    out.append(f"GNSS      {s.gnss_valid} valid of {s.gnss_fixes} fixes")
    if s.outages:
        spans = ", ".join(f"{a:.1f}-{b:.1f} s ({b - a:.1f} s)" for a, b in s.outages)
        out.append(
            f"outages   {len(s.outages)} without a valid fix for more than "
            f"{s.outage_threshold_s:.1f} s: {spans}"
        )
    else:
        out.append(f"outages   none (no gap over {s.outage_threshold_s:.1f} s in valid fixes)")
    if s.distances:
        for i, (source, metres) in enumerate(s.distances):
            out.append(f"{'distance' if i == 0 else '':<9} {metres:.1f} m from {source}")
    else:
        out.append("distance  unknown (no wheel speed, too few fixes, no truth)")
    if s.route is not None:
        r = s.route
        out.append("")
        out.append(f"route     {r.path}: {r.name!r}, {r.length_m:.1f} m, {r.vertices} vertices")
        out.append(
            f"          positions from the route: median {r.distance_median_m:.1f} m, "
            f"95% {r.distance_p95_m:.1f} m, max {r.distance_max_m:.1f} m"
        )
    for w in s.warnings:
        out.append(f"warning   {w}")
    return "\n".join(out)


def format_route_file(path: Path) -> str:
    """The lines of a route file, each measured in a frame at its own first point."""
    lines = read_route_lines(path)
    out = [f"route file {path}: {len(lines)} line{'s' * (len(lines) != 1)}"]
    for i, line in enumerate(lines):
        route = route_in_frame(line, LocalFrame.at(line.lat, line.lon, line.alt))
        seg = np.diff(route.s)
        out.append(
            f"  {i:>3}  {line.name!r}: {route.length:.1f} m, {len(route.xy)} vertices, "
            f"segments {seg.min():.1f} to {seg.max():.1f} m, starts at "
            f"{line.lat[0]:.6f}, {line.lon[0]:.6f}"
        )
    return "\n".join(out)

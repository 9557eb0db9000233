"""What a sweep runs: the logs (from folders, globs or a manifest CSV), the parameter sets (TOML
configs, a grid of values, the methods) and one task per (log, set) with a stable id, so that a
second run of the same command finds the tasks it already finished.

Nothing here runs the estimator: a plan is built and checked on the client in well under a
second, before any worker is asked for anything."""

from __future__ import annotations

import csv
import functools
import glob
import hashlib
import itertools
import json
import re
import tomllib
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from estimator.errors import ConfigError, RoutefuseError
from estimator.io import (
    AUTO_TOPICS,
    LOG_FORMATS_TEXT,
    TopicChoice,
    is_log_path,
    is_route_path,
    route_beside,
)
from estimator.params import (
    Method,
    Params,
    for_method,
    get_param,
    load_params,
    param_specs,
    params_to_toml,
    with_values,
)

TASK_VERSION = 1
"""Part of every task id: raised when a task's row changes meaning, so old rows are re-run."""

Outages = tuple[tuple[float, float], ...]
SetKind = Literal["config", "grid", "method"]
MANIFEST_COLUMNS = ("log", "route", "outages", "tags")
MAX_MANIFEST_BYTES = 50_000_000
MAX_GRID_POINTS = 10_000


@dataclass(frozen=True)
class LogEntry:
    """One log of a sweep and what it is run with."""

    log: Path
    route: Path | None
    """None: no route beside the log (its tasks are failed rows naming the missing file)"""
    label: str
    """unique within the plan: the log's stem, ``-2`` ... on a clash (a folder name)"""
    outages: Outages = ()
    tags: tuple[str, ...] = ()
    route_problem: str = ""
    """why ``route`` is None when a manifest named one (it does not exist)"""

    @property
    def route_error(self) -> str | None:
        """Why this log's tasks cannot run for want of a route (None: it has one). A log that
        cannot be opened either is named for its own problem (unreadable, empty, not a log),
        as ``routefuse run`` does, not as a log without a route."""
        if self.route is not None:
            return None
        from estimator.io.registry import open_log_path

        try:
            open_log_path(self.log)
        except RoutefuseError as exc:
            return " ".join(str(exc).split())
        if self.route_problem:
            return self.route_problem
        stem = self.log.name.split(".")[0]
        return (
            f"{self.log}: no route {stem}.route.geojson beside the log "
            "(nor a .gpx, .kml or .csv named after it)"
        )


@dataclass(frozen=True)
class ParamSet:
    """One parameter set: the parameters and the method they run; the baseline runs beside it
    (``routefuse run``'s table), so each row has both."""

    name: str
    params: Params
    method: Method = "proposed"
    kind: SetKind = "config"
    source: str = ""
    """the TOML file, grid file or option it came from"""

    @property
    def effective(self) -> Params:
        """The parameters the set's method runs with (``paper``: every extension off)."""
        return for_method(self.params, self.method)

    @property
    def methods(self) -> tuple[Method, ...]:
        return tuple(dict.fromkeys(("baseline", self.method)))

    @property
    def slug(self) -> str:
        """The name as a file name (hostile characters replaced)."""
        return _slug(self.name)


@dataclass(frozen=True)
class Task:
    """One (log, set) of a plan."""

    id: str
    log: LogEntry
    set: ParamSet
    set_index: int


@dataclass(frozen=True)
class SweepPlan:
    logs: tuple[LogEntry, ...]
    sets: tuple[ParamSet, ...]
    topics: TopicChoice = field(default=AUTO_TOPICS)

    def __post_init__(self) -> None:
        if not self.logs:
            raise ConfigError(None, "the sweep has no logs")
        if not self.sets:
            raise ConfigError(None, "the sweep has no parameter sets")

    @property
    def reference(self) -> ParamSet:
        """The first set: every other set's deltas are against it."""
        return self.sets[0]

    def tasks(self) -> list[Task]:
        """Log-major order: the tasks of one log follow each other (its decode is shared)."""
        return [
            Task(task_id(entry, s, self.topics), entry, s, i)
            for entry in self.logs
            for i, s in enumerate(self.sets)
        ]

    def differing(self, s: ParamSet) -> dict[str, Any]:
        """The values of ``s`` that differ from the reference set's (``method`` included)."""
        return differing_values(s, self.reference)

    def varied_names(self) -> list[str]:
        """Every parameter some set changes against the reference, in declaration order."""
        names: dict[str, None] = {}
        for s in self.sets:
            names.update(dict.fromkeys(self.differing(s)))
        order = ["method", *(spec.name for spec in param_specs())]
        return [n for n in order if n in names]


# ---------------------------------------------------------------------------------------------
# logs


def find_logs(spec: str | Path) -> list[Path]:
    """The logs a folder holds (what the log-format registry recognises directly in it), or
    whatever a glob pattern matches (route files left out)."""
    p = Path(spec).expanduser()
    try:
        folder = p.is_dir()
    except OSError:  # a glob inside a folder that cannot be looked into: it matches nothing
        folder = False
    if folder:
        try:
            children = sorted(p.iterdir())
        except OSError as exc:
            raise RoutefuseError(spec, f"cannot list the folder ({exc.strerror or exc})") from None
        found = [c for c in children if _may_be_log(c)]
    else:
        found = [Path(m) for m in sorted(glob.glob(str(p)))]
        found = [m for m in found if not is_route_path(m)]
    if not found:
        raise RoutefuseError(
            spec, f"no logs found (expected a folder holding {LOG_FORMATS_TEXT}, or a glob)"
        )
    return found


def _may_be_log(path: Path) -> bool:
    """Whether ``path`` is a log (:func:`estimator.io.is_log_path`), or a folder that cannot be
    looked into (no permission): kept, so that its task fails naming the problem instead of the
    folder being skipped without a word or the whole sweep stopping."""
    try:
        return is_log_path(path)
    except OSError:
        return True


def is_manifest(path: Path) -> bool:
    """A CSV file whose header names a ``log`` column."""
    if path.suffix.lower() != ".csv" or not path.is_file():
        return False
    try:
        with path.open(newline="", encoding="utf-8") as fh:
            header = next(csv.reader(fh), [])
    except (OSError, UnicodeDecodeError):
        return False
    return "log" in (h.strip().lower() for h in header)


def read_manifest(path: Path) -> list[LogEntry]:
    """Rows ``log, route, outages, tags`` (only ``log`` required; relative paths are from the
    manifest's folder; outages ``20:50 80:95``, tags separated by ``;`` or spaces). An empty
    route is the one beside the log."""
    from inspector.cli.options import parse_outage

    try:
        if path.stat().st_size > MAX_MANIFEST_BYTES:
            raise ConfigError(path, f"manifest is over {MAX_MANIFEST_BYTES} bytes")
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise ConfigError(path, f"cannot read the manifest: {exc.strerror or exc}") from None
    except UnicodeDecodeError:
        raise ConfigError(path, "the manifest is not UTF-8 text") from None
    reader = csv.DictReader(text.splitlines())
    fields = [(f or "").strip().lower() for f in reader.fieldnames or ()]
    unknown = [f for f in fields if f not in MANIFEST_COLUMNS]
    if unknown:
        raise ConfigError(
            path, f"unknown column {unknown[0]!r} (columns: {', '.join(MANIFEST_COLUMNS)})"
        )
    entries: list[LogEntry] = []
    base = path.parent
    for n, raw in enumerate(reader, start=2):
        row = {(k or "").strip().lower(): (v or "").strip() for k, v in raw.items()}
        if not row.get("log"):
            raise ConfigError(path, f"line {n}: no log")
        # a row whose log or route is missing is a member whose tasks fail naming it (the
        # rest of a nightly manifest runs), not the end of the sweep
        log = _resolve(base, row["log"])
        route = _resolve(base, row["route"]) if row.get("route") else route_beside(log)
        problem = ""
        if route is not None and not route.is_file():
            problem = f"{route}: no such route file (manifest {path.name}, line {n})"
            route = None
        try:
            outages = tuple(
                parse_outage(o) for o in row.get("outages", "").replace(",", " ").split()
            )
        except ConfigError as exc:
            raise ConfigError(path, f"line {n}: outages {exc.problem}") from None
        tags = tuple(t for t in re.split(r"[;\s]+", row.get("tags", "")) if t)
        entries.append(LogEntry(log, route, "", outages, tags, problem))
    if not entries:
        raise ConfigError(path, "the manifest lists no log")
    return entries


def _resolve(base: Path, text: str) -> Path:
    p = Path(text).expanduser()
    return p if p.is_absolute() else base / p


def collect_logs(
    specs: Sequence[str | Path], *, outages: Iterable[tuple[float, float]] = ()
) -> tuple[LogEntry, ...]:
    """The logs of folders, globs, single logs and manifests; ``outages`` for every log whose
    manifest row gives none. Each gets a unique ``label``; a log named twice with the same
    outages is run once."""
    default_outages = tuple((float(a), float(b)) for a, b in outages)
    entries: list[LogEntry] = []
    for spec in specs:
        p = Path(spec).expanduser()
        if is_manifest(p):
            entries.extend(read_manifest(p))
            continue
        try:
            named = p.exists() and _may_be_log(p)
        except OSError:  # inside a folder that cannot be looked into: a glob matches nothing
            named = not any(c in str(spec) for c in "*?[")  # a path: a member named for it
        logs = [p] if named else find_logs(spec)
        entries.extend(LogEntry(log, route_beside(log), "") for log in logs)
    unique: dict[tuple[str, Outages], LogEntry] = {}
    for e in entries:
        route = None if e.route is None else e.route.absolute()
        e = LogEntry(
            e.log.absolute(), route, "", e.outages or default_outages, e.tags, e.route_problem
        )
        unique.setdefault((str(e.log.resolve()), e.outages), e)
    used: set[str] = set()
    labelled = []
    for e in unique.values():
        name = _slug(e.log.name.split(".")[0], "log")
        label, k = name, 2
        while label in used:
            label, k = f"{name}-{k}", k + 1
        used.add(label)
        labelled.append(LogEntry(e.log, e.route, label, e.outages, e.tags, e.route_problem))
    return tuple(labelled)


# ---------------------------------------------------------------------------------------------
# parameter sets


SetSpec = tuple[Literal["config", "grid", "method"], str]
"""(kind, value) as given on the command line, in order: a TOML file, a grid file, a method"""


def config_set(path: str | Path, *, base: Params | None = None) -> ParamSet:
    p = Path(path).expanduser()
    return ParamSet(p.stem, load_params(p, base), "proposed", "config", str(p))


def method_set(method: str, *, base: Params | None = None) -> ParamSet:
    if method not in ("baseline", "proposed", "paper"):
        raise ConfigError("--method", f"{method!r} is not one of baseline, proposed, paper")
    m: Method = method  # type: ignore[assignment]
    return ParamSet(m, base or Params(), m, "method", f"--method {m}")


def grid_sets(path: str | Path, *, base: Params | None = None) -> list[ParamSet]:
    """Every combination of a grid file's lists (``[gates] max_residual_m = [1.0, 2.5]``);
    a plain value is set in every combination; ``method = ["proposed", "paper"]`` at the top
    varies the method too. Combinations in the file's order, the last key varying fastest."""
    p = Path(path).expanduser()
    try:
        data = tomllib.loads(p.read_text(encoding="utf-8"))
    except OSError as exc:
        raise ConfigError(p, f"cannot read the grid: {exc.strerror or exc}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise ConfigError(p, f"not valid TOML: {exc}") from None
    return expand_grid(data, source=p, base=base)


def expand_grid(
    data: Mapping[str, Any], *, source: str | Path, base: Params | None = None
) -> list[ParamSet]:
    """The sets of a parsed grid (see :func:`grid_sets`)."""
    flat: dict[str, Any] = {}

    def walk(d: Mapping[str, Any], prefix: str) -> None:
        for k, v in d.items():
            if isinstance(v, dict):
                walk(v, f"{prefix}{k}.")
            else:
                flat[f"{prefix}{k}"] = v

    walk(data, "")
    known = {s.name: s for s in param_specs()}
    axes: list[tuple[str, list[Any]]] = []
    for name, value in flat.items():
        if name != "method" and name not in known:
            raise ConfigError(source, f"unknown parameter {name!r}")
        is_tuple_param = name in known and isinstance(known[name].default, tuple)
        values = value if isinstance(value, list) else [value]
        if is_tuple_param and values and not isinstance(values[0], list):
            values = [values]  # a lever arm given once, not a list of lever arms
        if not values:
            raise ConfigError(source, f"{name}: an empty list of values")
        axes.append((name, values))
    if not axes:
        raise ConfigError(source, "the grid varies nothing")
    combos = list(itertools.product(*(values for _, values in axes)))
    if len(combos) > MAX_GRID_POINTS:
        raise ConfigError(source, f"{len(combos)} combinations; at most {MAX_GRID_POINTS}")
    varied = [i for i, (_, values) in enumerate(axes) if len(values) > 1]
    sets = []
    for combo in combos:
        point = {name: v for (name, _), v in zip(axes, combo, strict=True)}
        method = str(point.pop("method", "proposed"))
        chosen = method_set(method, base=base)  # checks the method's name
        params = with_values(base or chosen.params, point, str(source))
        shown = [f"{axes[i][0].rsplit('.', 1)[-1]}={_text(combo[i])}" for i in varied]
        name = ",".join(shown) or Path(source).stem
        sets.append(ParamSet(name, params, chosen.method, "grid", str(source)))
    return sets


def build_sets(specs: Sequence[SetSpec], *, base: Params | None = None) -> tuple[ParamSet, ...]:
    """The sets in command-line order (the first is the reference); none given: the defaults
    with the proposed method. Names are made unique with ``-2``, ``-3`` ..."""
    sets: list[ParamSet] = []
    for kind, value in specs:
        if kind == "config":
            sets.append(config_set(value, base=base))
        elif kind == "grid":
            sets.extend(grid_sets(value, base=base))
        else:
            sets.append(method_set(value, base=base))
    if not sets:
        sets.append(ParamSet("default", base or Params(), "proposed", "method", "defaults"))
    used: set[str] = set()
    unique = []
    for s in sets:
        name, k = s.name, 2
        while name in used or _slug(name) in {_slug(u) for u in used}:
            name, k = f"{s.name}-{k}", k + 1
        used.add(name)
        unique.append(ParamSet(name, s.params, s.method, s.kind, s.source))
    return tuple(unique)


def differing_values(s: ParamSet, reference: ParamSet) -> dict[str, Any]:
    """Dotted name -> value of ``s`` for every parameter (as its method runs it) that differs
    from ``reference``'s, with ``method`` first when the methods differ."""
    out: dict[str, Any] = {}
    if s.method != reference.method:
        out["method"] = s.method
    mine, theirs = s.effective, reference.effective
    for spec in param_specs():
        a, b = get_param(mine, spec.name), get_param(theirs, spec.name)
        if a != b:
            out[spec.name] = a
    return out


def format_values(values: Mapping[str, Any]) -> str:
    """``gates.max_residual_m=2.5; method=paper`` (empty for the reference)."""
    return "; ".join(f"{k}={_text(v)}" for k, v in values.items())


def _text(v: Any) -> str:
    if isinstance(v, tuple | list):
        return ",".join(_text(x) for x in v)
    if isinstance(v, float):
        return f"{v:g}"
    return str(v)


def _slug(name: str, fallback: str = "set") -> str:
    """A file-name-safe form: letters and digits of any script, ``. _ = , + -``; the rest
    (spaces, slashes, markup) replaced by ``_``; ``fallback`` when nothing is left."""
    slug = re.sub(r"[^\w.=,+-]+", "_", name).strip("._") or fallback
    return slug[:80]


@functools.cache
def estimator_source() -> str:
    """A hash of the estimator's source files (``estimator/**/*.py``): the figures of a row are
    those of the code that ran it."""
    import estimator

    root = Path(estimator.__file__).resolve().parent
    digest = hashlib.sha256()
    for f in sorted(root.rglob("*.py")):
        digest.update(f.relative_to(root).as_posix().encode() + b"\0" + f.read_bytes() + b"\0")
    return digest.hexdigest()[:16]


def task_id(entry: LogEntry, s: ParamSet, topics: TopicChoice = AUTO_TOPICS) -> str:
    """A hash of everything a task's row depends on that the sweep knows: the log's and route's
    paths, outages, topics, the method, the parameters as TOML and the estimator's source
    (:func:`estimator_source`: a sweep resumed after a code change runs again, instead of
    keeping the earlier code's rows as if they were this code's). Renaming the set keeps it;
    changing a value or a file's path makes a new task."""
    key = json.dumps(
        [
            TASK_VERSION,
            estimator_source(),
            str(entry.log.resolve()),
            None if entry.route is None else str(entry.route.resolve()),
            [list(o) for o in entry.outages],
            [topics.imu, topics.gnss, topics.wheel, topics.truth],
            s.method,
            params_to_toml(s.params),
        ]
    )
    return hashlib.sha256(key.encode()).hexdigest()[:20]

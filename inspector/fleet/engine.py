"""The sweep engine: every (log, set) of a plan is a Dask task; the rows come back, the table and
the report are written from the per-task files.

Python API (the CLI's ``routefuse sweep`` and ``routefuse export --batch`` are thin callers)::

    from inspector.fleet import collect_logs, build_sets, SweepPlan, run_sweep

    plan = SweepPlan(collect_logs(["drives/"]), build_sets([("method", "proposed"),
                                                            ("method", "paper")]))
    result = run_sweep(plan, "out/", workers=2)          # a LocalCluster of 2 processes
    result = run_sweep(plan, "out/", scheduler="tcp://head:8786")   # an existing cluster
    result.parquet, result.csv, result.report, result.failed

Execution. ``workers=N`` starts a :class:`distributed.LocalCluster` of N single-threaded worker
processes (default one per core); ``scheduler=ADDRESS`` uses a running cluster (``dask
scheduler`` / ``dask worker``; routefuse must be importable on every worker). Each log is first
decoded by one task into the decoded-log cache (:func:`estimator.io.default_cache_dir` of the
client, or ``cache_dir``: on a cluster, a folder every node sees), and the (log, set) tasks of
that log depend on it, so a log is decoded once however many sets run on it. A task loads the
cached log, runs the baseline and the set's method, writes ``tasks/<id>.json`` (its row and the
results document) and returns only the row: a worker keeps nothing between tasks, and the client
keeps only counters and a bounded window of futures (``window``), so its memory does not grow
with the number of tasks.

Failures. An error in a task (a corrupt log, a missing route, any exception) is a row with the
one-line error; a worker that dies mid-task (killed, out of memory) has its tasks re-run on the
others by the scheduler (Dask's ``allowed-failures``), and ``retries`` re-runs a task whose
exception escaped (writing its file failed). Only a task that keeps killing workers ends as a
failed row, never the sweep.

Resume. A task whose file holds an ``ok`` row with the same task id is not run again (ids hash
the log's and route's paths, the outages, topics, method, parameters and the client's estimator
source: :func:`inspector.fleet.plan.task_id`); failed tasks are retried on the next run. On a
running cluster every worker must run the client's estimator source (:func:`check_workers`
before any task, and each task again), or its rows would be kept as this code's.

Output folder::

    results.parquet  results.csv  report.html  plan.json
    sets/<set>.toml                 the parameters of each set (routefuse serve --config)
    tasks/<id>.json                 one per task: row, results document
    exports/<set>/<log>/            the replay export of each task, with export=ReplayOptions()
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import json
import logging
import os
import resource
import signal
import socket
import sys
import threading
import time
import uuid
from collections import deque
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, Protocol

from estimator.errors import RoutefuseError
from estimator.io import TopicChoice
from estimator.params import params_to_toml
from inspector.fleet.plan import SweepPlan, Task, estimator_source, format_values
from inspector.fleet.table import failed_row, one_line, read_task_file, task_row
from inspector.library_warnings import library_warnings_recorded

if TYPE_CHECKING:
    from distributed import Client, Future

    from estimator.results import Run
    from inspector.export.replay import ReplayOptions

ExportLayout = Literal["by-set", "flat"]
"""where a task's replay export goes: ``exports/<set>/<log>/`` or ``<log>/`` (one set)"""

STALE_OUTPUTS = ("results.parquet", "results.csv", "report.html", "summary.csv")
"""what a sweep or a batch export writes once all its tasks are done"""
CONNECT_TIMEOUT_S = 30.0
WORKERS_TIMEOUT_S = 60.0
WAITING_NOTE_S = 10.0
"""while no worker has joined a running scheduler, a line says so this often: a sweep that
printed nothing for a minute looked hung"""


@dataclass(frozen=True)
class SweepLayout:
    """The files of a sweep's output folder."""

    out: Path
    export: ExportLayout = "by-set"

    def task_file(self, task: Task) -> Path:
        return self.out / "tasks" / f"{task.id}.json"

    def export_dir(self, task: Task) -> Path:
        if self.export == "flat":
            return self.out / task.log.label
        return self.out / "exports" / task.set.slug / task.log.label

    def set_config(self, set_slug: str) -> Path:
        return self.out / "sets" / f"{set_slug}.toml"


@dataclass(frozen=True)
class TaskJob:
    """What a worker needs for one task (pickled to it; small)."""

    task: Task
    topics: TopicChoice
    cache_dir: str
    task_file: str
    export_dir: str | None
    replay: ReplayOptions | None
    estimator_source: str | None = None
    """the client's :func:`estimator_source`: a worker on other code fails the task rather than
    write a row under an id that hashes the client's code (a worker that joined after
    :func:`check_workers`); None: not checked"""


@dataclass(frozen=True)
class SweepResult:
    out_dir: Path
    total: int
    ran: int
    """tasks run now (the rest were finished by an earlier run)"""
    skipped: int
    failed: int
    parquet: Path
    csv: Path
    report: Path | None
    seconds: float
    dashboard: str | None


class SweepProgress(Protocol):
    """What the engine tells about progress (:class:`TerminalProgress` on the terminal)."""

    def start(self, *, total: int, done: int, failed: int, dashboard: str | None) -> None: ...

    def advance(self, row: Mapping[str, Any]) -> None: ...

    def note(self, text: str) -> None:
        """What the sweep waits for before its first task (a scheduler, its workers)."""

    def close(self) -> None: ...


class TerminalProgress:
    """A tqdm bar (done/total, failed, ETA) on a terminal; elsewhere one line per finished task
    (``[3/16] drive proposed: done``), so logs of a nightly job stay readable."""

    def __init__(self, *, stream: Any = None, bar: bool | None = None) -> None:
        self.stream = stream if stream is not None else sys.stderr
        self.use_bar = self.stream.isatty() if bar is None else bar
        self.total = self.done = self.failed = 0
        self.bar: Any = None

    def start(self, *, total: int, done: int, failed: int, dashboard: str | None) -> None:
        self.total, self.done, self.failed = total, done, failed
        if dashboard:
            print(f"Dask dashboard: {dashboard}", file=self.stream, flush=True)
        if done:
            print(f"{done} of {total} tasks finished before: skipped", file=self.stream)
        if self.use_bar:
            from tqdm import tqdm

            self.bar = tqdm(
                total=total, initial=done, file=self.stream, unit="task", dynamic_ncols=True
            )
            self.bar.set_postfix(failed=failed)

    def advance(self, row: Mapping[str, Any]) -> None:
        self.done += 1
        ok = row.get("status") == "ok"
        self.failed += 0 if ok else 1
        line = f"[{self.done}/{self.total}] {Path(str(row['log'])).name} {row['set']}: " + (
            "done" if ok else f"failed: {row.get('error', '')}"
        )
        if self.bar is not None:
            if not ok:
                self.bar.write(line, file=self.stream)
            self.bar.set_postfix(failed=self.failed, refresh=False)
            self.bar.update(1)
        else:
            print(line, file=self.stream, flush=True)

    def note(self, text: str) -> None:
        print(text, file=self.stream, flush=True)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


class QuietProgress:
    def start(self, *, total: int, done: int, failed: int, dashboard: str | None) -> None:
        pass

    def advance(self, row: Mapping[str, Any]) -> None:
        pass

    def note(self, text: str) -> None:
        pass

    def close(self) -> None:
        pass


# ---------------------------------------------------------------------------------------------
# on the workers


def worker_ready() -> str:
    """Run on every worker before a sweep on an existing cluster: that routefuse imports; the
    hash of the estimator's source the worker runs (:func:`estimator_source`)."""
    import estimator.pipeline  # noqa: F401

    return estimator_source()


def decode_log(log: str, topics: TopicChoice, cache_dir: str) -> str | None:
    """Decode ``log`` into the cache (nothing if it is there); the one-line error, or None."""
    from estimator.io import load_log

    try:
        load_log(log, topics=topics, cache_dir=Path(cache_dir))
    except RoutefuseError as exc:
        return one_line(str(exc))
    except Exception as exc:  # a broken log is a failed row, not a failed sweep
        return one_line(f"{log}: internal error: {type(exc).__name__}: {exc}")
    return None


def run_task(job: TaskJob, decode_error: str | None) -> dict[str, Any]:
    """One (log, set): run it (or export it), write its task file, return its row."""
    task = job.task
    started = time.perf_counter()
    document: dict[str, Any] | None = None
    files: list[str] = []
    try:
        if decode_error is not None:
            raise RoutefuseError(None, decode_error)
        if job.estimator_source not in (None, estimator_source()):
            raise RoutefuseError(
                _worker_name(),
                f"this worker runs another routefuse (estimator source {estimator_source()}, "
                f"the client's {job.estimator_source}): install the client's on every worker",
            )
        if task.log.route is None:
            raise RoutefuseError(None, task.log.route_error or "no route")
        with library_warnings_recorded() as told:
            if job.export_dir is not None:
                document, seconds, files = _export(job)
            else:
                document, seconds = _run(job)
        if told:
            said = document.get("warnings", [])
            document["warnings"] = [*said, *(w for w in told if w not in said)]
        seconds["total_s"] = time.perf_counter() - started
        row = task_row(
            task,
            document,
            seconds=seconds,
            worker=_worker_name(),
            peak_rss_mb=_peak_rss_mb(),
            rss_mb=_rss_mb(),
            export_dir=job.export_dir or "",
        )
    except RoutefuseError as exc:
        row = _failed(task, str(exc), started)
    except Exception as exc:  # one broken task must not stop the sweep
        row = _failed(task, f"{task.log.log}: internal error: {type(exc).__name__}: {exc}", started)
    replay = None if job.replay is None else dataclasses.asdict(job.replay)
    write_task_file(
        Path(job.task_file), {"row": row, "document": document, "files": files, "replay": replay}
    )
    return row


def _failed(task: Task, error: str, started: float) -> dict[str, Any]:
    return failed_row(
        task,
        error,
        total_s=time.perf_counter() - started,
        worker=_worker_name(),
        worker_peak_rss_mb=_peak_rss_mb(),
    )


def _run(job: TaskJob) -> tuple[dict[str, Any], dict[str, float]]:
    from estimator.evaluation import method_metrics, results_document
    from estimator.pipeline import open_inputs, run_methods

    task = job.task
    assert task.log.route is not None
    t0 = time.perf_counter()
    inputs = open_inputs(
        task.log.log, task.log.route, topics=job.topics, cache_dir=Path(job.cache_dir)
    )
    load_s = time.perf_counter() - t0
    session = run_methods(
        inputs, task.set.params, methods=task.set.methods, outages=task.log.outages
    )
    t1 = time.perf_counter()
    assert inputs.route is not None
    runs: dict[str, Run] = dict(session.runs.items())
    metrics = {
        m: method_metrics(r, inputs.route, inputs.log, params=r.params) for m, r in runs.items()
    }
    doc = results_document(
        task.log.log,
        task.log.route,
        inputs.log,
        runs,
        metrics,
        outages=session.outages,
    )
    seconds = {
        "load_s": load_s,
        "baseline_s": session.seconds.get("baseline", 0.0),
        "method_s": session.seconds.get(task.set.method, 0.0),
        "metrics_s": time.perf_counter() - t1,
    }
    return doc, seconds


def _export(job: TaskJob) -> tuple[dict[str, Any], dict[str, float], list[str]]:
    from inspector.export.replay import ReplayOptions, export_log

    task = job.task
    assert task.log.route is not None and job.export_dir is not None
    result = export_log(
        task.log.log,
        task.log.route,
        job.export_dir,
        params=task.set.params,
        method=task.set.method,
        outages=task.log.outages,
        topics=job.topics,
        replay=job.replay or ReplayOptions(),
        cache_dir=Path(job.cache_dir),
    )
    t = result.timings
    seconds = {
        "load_s": t.get("load_s", 0.0),
        "method_s": t.get("run_s", 0.0),
        "export_s": sum(v for k, v in t.items() if k not in ("load_s", "run_s")),
    }
    doc = dict(result.metrics)
    doc["export"] = {"frames": result.frames, "files": [str(f) for f in result.files]}
    return doc, seconds, [str(f) for f in result.files]


def _worker_name() -> str:
    return f"{socket.gethostname()}:{os.getpid()}"


def _peak_rss_mb() -> float:
    """The worker process's peak resident set so far (Linux reports kB)."""
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    return peak / (1024.0 * 1024.0) if sys.platform == "darwin" else peak / 1024.0


def _rss_mb() -> float | None:
    try:
        import psutil
    except ImportError:
        return None
    return float(psutil.Process().memory_info().rss) / 2**20


def write_task_file(path: Path, data: Mapping[str, Any]) -> None:
    """Atomically (a reader never sees half a file; two writers of one task agree)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".tmp-{uuid.uuid4().hex}.json")  # created with the user's umask
    try:
        with tmp.open("x", encoding="utf-8") as fh:
            json.dump(data, fh, allow_nan=True)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        raise


# ---------------------------------------------------------------------------------------------
# on the client


@contextlib.contextmanager
def open_client(
    *, workers: int | None, scheduler: str | None, note: Callable[[str], None] | None = None
) -> Iterator[Client]:
    """A client of a new LocalCluster (``workers`` single-threaded processes, default one per
    core), or of the running cluster at ``scheduler``; closed (and the cluster stopped) on
    exit. On a running cluster, ``note`` is told what the sweep waits for, and every worker
    must run the client's estimator (:func:`check_workers`)."""
    from distributed import Client, LocalCluster

    say = note if note is not None else (lambda text: None)
    if scheduler is not None:
        say(f"connecting to the Dask scheduler at {scheduler} (up to {CONNECT_TIMEOUT_S:g} s)")
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
        except (OSError, TimeoutError, ValueError) as exc:
            raise RoutefuseError(
                scheduler, f"cannot reach the Dask scheduler: {one_line(str(exc), 200)}"
            ) from None
        try:
            _wait_for_a_worker(client, scheduler, say)
            check_workers(client, scheduler)
            say(f"{len(client.scheduler_info()['workers'])} Dask workers ready")
            yield client
        finally:
            client.close()
        return
    n = workers if workers is not None else (os.cpu_count() or 1)
    if n < 1:
        raise RoutefuseError("--workers", f"{n}: at least one worker")
    with _workers_ignore_ctrl_c():
        cluster = LocalCluster(
            n_workers=n,
            threads_per_worker=1,
            processes=True,
            dashboard_address=":0",
            silence_logs=logging.ERROR,
        )
    try:
        with Client(cluster) as client:
            yield client
    finally:
        cluster.close()


def _wait_for_a_worker(client: Client, scheduler: str, say: Callable[[str], None]) -> None:
    """Until a worker has joined, a line every :data:`WAITING_NOTE_S`; one line and the end
    after :data:`WORKERS_TIMEOUT_S`."""
    if client.scheduler_info()["workers"]:
        return
    say(f"waiting for a Dask worker to join (up to {WORKERS_TIMEOUT_S:g} s)")
    started = time.monotonic()
    while True:
        left = WORKERS_TIMEOUT_S - (time.monotonic() - started)
        if left <= 0:
            raise RoutefuseError(scheduler, f"no Dask worker joined within {WORKERS_TIMEOUT_S:g} s")
        try:
            client.wait_for_workers(1, timeout=min(WAITING_NOTE_S, left))
            return
        except TimeoutError:
            waited = time.monotonic() - started
            if waited < WORKERS_TIMEOUT_S:
                say(f"no Dask worker yet after {waited:.0f} s")


def check_workers(client: Client, scheduler: str) -> None:
    """Every worker imports routefuse and runs the client's estimator source: a task's id (and
    so what a resumed sweep keeps) hashes the client's source, so a worker on other code
    would write rows that a later run takes for this code's."""
    try:
        sources = client.run(worker_ready)
    except Exception as exc:
        raise RoutefuseError(
            scheduler,
            "a worker cannot import routefuse (install it on every worker): "
            + one_line(f"{type(exc).__name__}: {exc}", 200),
        ) from None
    mine = estimator_source()
    other = sorted(address for address, source in sources.items() if source != mine)
    if other:
        raise RoutefuseError(
            scheduler,
            f"{len(other)} of {len(sources)} Dask workers run another routefuse (estimator "
            f"source {sources[other[0]]} on {other[0]}, this client's {mine}): install this "
            "routefuse on every worker",
        )


@contextlib.contextmanager
def _workers_ignore_ctrl_c() -> Iterator[None]:
    """SIGINT ignored while the local worker processes start, so they inherit it ignored: Ctrl-C
    on the terminal reaches the whole process group, and the workers, interrupted mid-task,
    printed a KeyboardInterrupt traceback each; only the client is to stop, and it closes the
    cluster (its workers with it)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def dashboard_link(client: Client) -> str | None:
    """The dashboard's address when the scheduler serves one (bokeh installed there)."""
    import importlib.util

    services = client.scheduler_info().get("services", {})
    if "dashboard" not in services or importlib.util.find_spec("bokeh") is None:
        return None
    link = client.dashboard_link
    return str(link) if link else None


def prepare_output(plan: SweepPlan, layout: SweepLayout) -> None:
    """The output folder, each set's parameters as TOML, and the plan as JSON."""
    out = layout.out
    try:
        out.mkdir(parents=True, exist_ok=True)
        (out / "tasks").mkdir(exist_ok=True)
        (out / "sets").mkdir(exist_ok=True)
    except OSError as exc:
        raise RoutefuseError(
            out, f"cannot create the output folder: {exc.strerror or exc}"
        ) from None
    # the table and report of an earlier run are written again at the end from every task
    # file: removed now, so that a run stopped midway (Ctrl-C) leaves none that looks like
    # this run's (the finished tasks' files stay, and the next run resumes from them)
    for stale in STALE_OUTPUTS:
        with contextlib.suppress(FileNotFoundError):
            (out / stale).unlink()
    for s in plan.sets:
        layout.set_config(s.slug).write_text(
            f"# routefuse sweep set {s.name!r} (method {s.method}, from {s.source})\n"
            + params_to_toml(s.effective).split("\n", 1)[1],
            encoding="utf-8",
        )
    doc = {
        "estimator_source": estimator_source(),
        "reference": plan.reference.name,
        "sets": [
            {
                "name": s.name,
                "method": s.method,
                "source": s.source,
                "config": str(layout.set_config(s.slug)),
                "differs": format_values(plan.differing(s)),
            }
            for s in plan.sets
        ],
        "logs": [
            {
                "log": str(e.log),
                "route": None if e.route is None else str(e.route),
                "label": e.label,
                "outages": [list(o) for o in e.outages],
                "tags": list(e.tags),
            }
            for e in plan.logs
        ],
    }
    (out / "plan.json").write_text(json.dumps(doc, indent=2) + "\n", encoding="utf-8")


def finished(task: Task, layout: SweepLayout, *, export: ReplayOptions | None) -> bool:
    """An ``ok`` row of this very task is on disk (and its export with the same replay
    options, when one is asked)."""
    data = read_task_file(layout.task_file(task))
    if data is None:
        return False
    row = data["row"]
    if row.get("task_id") != task.id or row.get("status") != "ok":
        return False
    if export is None:
        return True
    same = data.get("replay") == dataclasses.asdict(export)
    return same and (layout.export_dir(task) / "replay.html").is_file()


def run_sweep(
    plan: SweepPlan,
    out_dir: str | Path,
    *,
    workers: int | None = None,
    scheduler: str | None = None,
    export: ReplayOptions | None = None,
    export_layout: ExportLayout = "by-set",
    progress: SweepProgress | None = None,
    cache_dir: str | Path | None = None,
    retries: int = 2,
    window: int | None = None,
    report: bool = True,
    on_row: Callable[[Mapping[str, Any]], None] | None = None,
) -> SweepResult:
    """Run every task of ``plan`` not finished in ``out_dir`` before, then write the table
    (``results.parquet``, ``results.csv``) and, with ``report``, ``report.html``.

    ``export``: also write each task's replay export (:func:`inspector.export.export_log`).
    ``window``: futures in flight at once (default three per worker thread). ``on_row`` is
    called with each row as it arrives (besides ``progress``)."""
    from estimator.io import default_cache_dir
    from inspector.fleet.table import iter_rows, table_columns, write_table

    started = time.perf_counter()
    layout = SweepLayout(Path(out_dir).expanduser(), export_layout)
    prepare_output(plan, layout)
    cache = str(Path(cache_dir).expanduser() if cache_dir is not None else default_cache_dir())
    progress = progress if progress is not None else TerminalProgress()
    tasks = plan.tasks()
    todo = [t for t in tasks if not finished(t, layout, export=export)]
    skipped = len(tasks) - len(todo)
    failed = 0
    dashboard: str | None = None
    fallback: dict[str, dict[str, Any]] = {}

    def record(row: Mapping[str, Any]) -> None:
        nonlocal failed
        failed += row.get("status") != "ok"
        progress.advance(row)
        if on_row is not None:
            on_row(row)

    try:
        runnable = []
        for task in todo:
            if task.log.route is None:  # known on the client: no worker needed
                row = failed_row(task, task.log.route_error or "no route")
                write_task_file(layout.task_file(task), {"row": row, "document": None})
                fallback[task.id] = row
            else:
                runnable.append(task)
        if runnable:
            with open_client(workers=workers, scheduler=scheduler, note=progress.note) as client:
                dashboard = dashboard_link(client)
                progress.start(total=len(tasks), done=skipped, failed=0, dashboard=dashboard)
                for task_id in fallback:
                    record(fallback[task_id])
                _drive(
                    client,
                    plan,
                    runnable,
                    layout,
                    cache=cache,
                    export=export,
                    retries=retries,
                    window=window,
                    record=record,
                )
        else:
            progress.start(total=len(tasks), done=skipped, failed=0, dashboard=None)
            for row in fallback.values():
                record(row)
    finally:
        progress.close()
    parquet, csv_path = write_table(
        iter_rows(plan, tasks, layout.task_file, fallback=fallback),
        table_columns(plan),
        layout.out,
    )
    report_path = None
    if report:
        from inspector.fleet.report import write_report

        report_path = write_report(plan, layout, parquet)
    return SweepResult(
        out_dir=layout.out,
        total=len(tasks),
        ran=len(todo),
        skipped=skipped,
        failed=failed,
        parquet=parquet,
        csv=csv_path,
        report=report_path,
        seconds=time.perf_counter() - started,
        dashboard=dashboard,
    )


def _drive(
    client: Client,
    plan: SweepPlan,
    tasks: list[Task],
    layout: SweepLayout,
    *,
    cache: str,
    export: ReplayOptions | None,
    retries: int,
    window: int | None,
    record: Callable[[Mapping[str, Any]], None],
) -> None:
    """Submit ``tasks`` through a bounded window and record each row as it comes back."""
    from distributed import as_completed

    submit: Any = client.submit  # typed for one return type per client; tasks return two

    threads = sum(w.get("nthreads", 1) for w in client.scheduler_info()["workers"].values())
    limit = window if window is not None else max(4, 3 * threads)
    # keys are unique per output folder: two sweeps on one scheduler never share a task
    salt = hashlib.sha256(layout.out.resolve().as_posix().encode()).hexdigest()[:10]
    source = estimator_source()
    pending = deque(tasks)
    in_flight: dict[Future[dict[str, Any]], Task] = {}
    decode: tuple[str, Future[str | None]] | None = None
    completed = as_completed()

    def submit_more() -> None:
        nonlocal decode
        while pending and len(in_flight) < limit:
            task = pending.popleft()
            log = str(task.log.log)
            if decode is None or decode[0] != log:
                # log-major order: the previous log's decode future is dropped here, and Dask
                # forgets it once the tasks that depend on it have run
                future = submit(
                    decode_log,
                    log,
                    plan.topics,
                    cache,
                    key=f"decode-{task.log.label}-{task.id}-{salt}",
                    retries=retries,
                )
                decode = (log, future)
            job = TaskJob(
                task=task,
                topics=plan.topics,
                cache_dir=cache,
                task_file=str(layout.task_file(task)),
                export_dir=None if export is None else str(layout.export_dir(task)),
                replay=export,
                estimator_source=source,
            )
            future = submit(
                run_task,
                job,
                decode[1],
                key=f"task-{task.log.label}-{task.set.slug}-{task.id}-{salt}",
                retries=retries,
            )
            in_flight[future] = task
            completed.add(future)

    submit_more()
    for future in completed:
        task = in_flight.pop(future)
        try:
            row = future.result()
        except Exception as exc:  # the task's workers died (KilledWorker), or it kept raising
            row = failed_row(task, f"{task.log.log}: {type(exc).__name__}: {exc}")
            with contextlib.suppress(OSError):
                write_task_file(layout.task_file(task), {"row": row, "document": None})
        future.release()
        if not layout.task_file(task).is_file():  # a worker that cannot see the folder
            write_task_file(layout.task_file(task), {"row": row, "document": None})
        record(row)
        submit_more()

"""One session over one log: check the outages, run the baseline and the method(s) in order,
each resuming from the previous session's run of the same method when there is one (only
parameters changed) and else from the run before it. Every caller (the CLI, the inspector, the
export, the scripts) runs methods through :func:`run_methods`."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Protocol

from estimator.errors import ConfigError
from estimator.params import Method, Params, for_method
from estimator.pipeline.driver import ProgressFn, run
from estimator.pipeline.inputs import Inputs
from estimator.results import Run

Outages = tuple[tuple[float, float], ...]
MethodProgress = Callable[[Method, float], None]
"""called with the method running and the fraction of its run done"""

DEFAULT_METHODS: tuple[Method, ...] = ("baseline", "proposed")


class MethodRunner(Protocol):
    """How one method is run (:func:`run_method`; tests substitute a fake)."""

    def __call__(
        self,
        inputs: Inputs,
        params: Params,
        method: Method,
        progress: ProgressFn,
        reuse: Run | None,
        *,
        outages: Outages,
    ) -> Run: ...


def run_method(
    inputs: Inputs,
    params: Params,
    method: Method,
    progress: ProgressFn,
    reuse: Run | None,
    *,
    outages: Outages,
) -> Run:
    """:func:`estimator.pipeline.run` of one method over opened inputs."""
    return run(
        inputs.log,
        inputs.route,
        params,
        method=method,
        frame=inputs.frame,
        outages=outages,
        progress=progress,
        reuse=reuse,
    )


@dataclass(frozen=True)
class MethodRuns:
    """The runs of one session, in the order they ran."""

    inputs: Inputs
    """what they ran on"""
    outages: Outages
    runs: Mapping[Method, Run]
    seconds: Mapping[Method, float]
    """wall time of each method's run (0 for a run taken over unchanged)"""

    def __getitem__(self, method: Method) -> Run:
        return self.runs[method]

    @property
    def methods(self) -> tuple[Method, ...]:
        return tuple(self.runs)


def checked_outages(
    outages: Iterable[tuple[float, float]], duration_s: Callable[[], float], *, where: str
) -> Outages:
    """``outages`` as float pairs, refusing one that starts after the log ends (``where``
    names the option or field in the error). ``duration_s`` is asked only if there are
    outages."""
    checked = tuple((float(a), float(b)) for a, b in outages)
    for a, b in checked:
        if a >= (duration := duration_s()):
            raise ConfigError(where, f"{a:g}:{b:g} starts after the log ends ({duration:.1f} s)")
    return checked


def run_methods(
    inputs: Inputs,
    params: Params,
    *,
    methods: Sequence[Method] = DEFAULT_METHODS,
    outages: Iterable[tuple[float, float]] = (),
    progress: MethodProgress | None = None,
    reuse: MethodRuns | None = None,
    outage_option: str = "--outage",
    run_one: MethodRunner = run_method,
) -> MethodRuns:
    """Run ``methods`` (duplicates once) over ``inputs`` (from :func:`open_inputs`).

    ``outages``: (start, end) seconds after the log start where GNSS is removed; one starting
    after the log ends is a :class:`ConfigError` naming ``outage_option``. ``reuse``: the
    previous session; its runs count only on the same inputs object and outages. A method
    whose previous run had the same parameters is taken over as it is; otherwise it resumes
    from the previous session's run of that method, else from the run before it here."""
    checked = checked_outages(outages, lambda: float(inputs.log.duration_s), where=outage_option)
    prior: Mapping[Method, Run] = {}
    if reuse is not None and reuse.inputs is inputs and reuse.outages == checked:
        prior = reuse.runs
    runs: dict[Method, Run] = {}
    seconds: dict[Method, float] = {}
    previous: Run | None = None
    for method in dict.fromkeys(methods):
        old = prior.get(method)
        t0 = time.perf_counter()
        if old is not None and old.params == for_method(params, method):
            result = old
        else:
            report = _reporter(progress, method)
            report(0.0)
            result = run_one(inputs, params, method, report, old or previous, outages=checked)
        seconds[method] = time.perf_counter() - t0
        runs[method] = previous = result
    return MethodRuns(inputs=inputs, outages=checked, runs=runs, seconds=seconds)


def _reporter(progress: MethodProgress | None, method: Method) -> ProgressFn:
    def report(fraction: float, *_: object) -> None:
        if progress is not None:
            progress(method, fraction)

    return report

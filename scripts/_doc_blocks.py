"""What the measuring scripts share: a marked block of a markdown document replaced by a new
table (``<!-- script.py: name begin -->`` ... ``<!-- script.py: name end -->``), their rows
written as CSV, and their cases run as Dask tasks."""

from __future__ import annotations

import argparse
import csv
import re
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, TypeVar

T = TypeVar("T")


def replace_block(text: str, mark: str, name: str, body: str) -> str:
    """``text`` with the block between ``mark.format(name + ' begin')`` and its end replaced
    by ``body``; SystemExit naming the marker when it is missing."""
    begin, end = mark.format(f"{name} begin"), mark.format(f"{name} end")
    pattern = re.compile(re.escape(begin) + r".*?" + re.escape(end), re.S)
    if not pattern.search(text):
        raise SystemExit(f"marker {begin!r} not found")
    return pattern.sub(lambda _: f"{begin}\n{body}\n{end}", text)


def write_block(doc: Path, mark: str, name: str, body: str) -> None:
    """:func:`replace_block` on the file ``doc``."""
    old = doc.read_text(encoding="utf-8")
    doc.write_text(replace_block(old, mark, name, body), encoding="utf-8")


def write_rows(path: Path, rows: list[dict[str, Any]]) -> None:
    """``rows`` as CSV, the columns in the order they first appear."""
    path.parent.mkdir(parents=True, exist_ok=True)
    columns = list(dict.fromkeys(k for r in rows for k in r))
    with open(path, "w", newline="", encoding="utf-8") as f:
        writer = csv.DictWriter(f, columns)
        writer.writeheader()
        writer.writerows(rows)


def run_in_workers(
    task: Callable[[T], dict[str, Any]], items: Sequence[T], *, workers: int, label: str
) -> list[dict[str, Any]]:
    """``task`` on each of ``items`` in a local Dask cluster of ``workers`` single-threaded
    workers (one retry), the rows in the order of ``items``; progress on stderr as
    ``label: done/total``."""
    import sys

    from distributed import Client, LocalCluster, as_completed

    with (
        LocalCluster(n_workers=workers, threads_per_worker=1, dashboard_address=None) as cluster,
        Client(cluster) as client,
    ):
        futures = client.map(task, items, pure=False, retries=1)
        order = {f.key: i for i, f in enumerate(futures)}
        done: list[tuple[int, dict[str, Any]]] = []
        for n, future in enumerate(as_completed(futures), 1):
            done.append((order[future.key], future.result()))
            print(f"{label}: {n}/{len(items)}", file=sys.stderr, flush=True)
    return [row for _, row in sorted(done, key=lambda d: d[0])]


def check_values(
    parser: argparse.ArgumentParser, values: dict[str, Any] | None, *, write: bool
) -> None:
    """``--values`` (parameter values, JSON) checked before any task runs: every name known,
    every value of its type, and not with ``--write`` (the docs' figures are the defaults')."""
    if not values:
        return
    if write:
        parser.error("--values: the docs' figures are of the defaults; leave out --write")
    from estimator.errors import RoutefuseError
    from estimator.params import Params, with_values

    try:
        with_values(Params(), values)
    except (RoutefuseError, TypeError, ValueError, AttributeError) as exc:
        parser.error(f"--values: {exc}")

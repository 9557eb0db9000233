"""What the measuring scripts share: a marked block of a markdown document replaced by a new
table (``<!-- script.py: name begin -->`` ... ``<!-- script.py: name end -->``), and their rows
written as CSV."""

from __future__ import annotations

import csv
import re
from pathlib import Path
from typing import Any


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

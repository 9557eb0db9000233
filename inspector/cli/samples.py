"""Where the bundled sample logs are: installed as package data beside the ``inspector``
package (``pip install``: setup.py maps the repository's ``sample_logs/`` to
``inspector/sample_logs``), or at the top of the source checkout the package runs from (an
editable install, or ``python -m inspector`` in a clone)."""

from __future__ import annotations

from pathlib import Path

DEFAULT_SAMPLE = "long_tunnel"
"""The sample ``routefuse serve`` opens when given no log."""
DEFAULT_TRAP_ROUTE = "long_tunnel_parallel_bore.route.geojson"
"""The route it opens the sample with: the middle of the tunnel drawn along the parallel bore
(``scripts/make_trap_route.py``), so the first view shows the rejection workflow."""
SAMPLES_FOLDER = "sample_logs"

_INSPECTOR = Path(__file__).resolve().parents[1]


def sample_log_candidates(inspector_dir: Path = _INSPECTOR) -> tuple[Path, ...]:
    """Where the samples may be, in the order they are looked for."""
    return (inspector_dir / SAMPLES_FOLDER, inspector_dir.parent / SAMPLES_FOLDER)


def find_sample_logs(inspector_dir: Path = _INSPECTOR) -> Path | None:
    """The folder holding the bundled samples (the default one among them), or None."""
    for folder in sample_log_candidates(inspector_dir):
        if (folder / f"{DEFAULT_SAMPLE}.mcap").is_file():
            return folder
    return None

"""How good a run is (:mod:`.metrics`) and the results document (:mod:`.document`)."""

from estimator.evaluation.document import distance_m, results_document
from estimator.evaluation.metrics import (
    MethodMetrics,
    deviation_series,
    format_table,
    map_bias_notes,
    match_summary,
    method_metrics,
    portal_notes,
    run_notes,
    unattempted_notes,
)

__all__ = [
    "MethodMetrics",
    "deviation_series",
    "distance_m",
    "format_table",
    "map_bias_notes",
    "match_summary",
    "method_metrics",
    "portal_notes",
    "results_document",
    "run_notes",
    "unattempted_notes",
]

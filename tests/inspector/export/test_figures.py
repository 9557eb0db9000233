"""The report's figures on a run of one epoch (the audit found it on an IMU whose stamps span
7.5 ms, which the loader now refuses): matplotlib warned of identical x limits, a warning with
its source line on export's stderr."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

from inspector.export.figures import deviation_figure
from inspector.plots import DeviationPlot


@pytest.mark.parametrize("epochs", [np.array([12.5]), np.array([12.5, 12.5]), np.array([])])
def test_a_deviation_figure_of_one_instant_warns_nothing(epochs: np.ndarray) -> None:
    flat = np.zeros(len(epochs))
    plot = DeviationPlot(epochs, (flat, flat), (flat, flat), ())
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        fig = deviation_figure(plot)
        fig.canvas.draw()
    lo, hi = fig.axes[1].get_xlim()
    assert hi > lo and (not len(epochs) or lo == epochs[0])

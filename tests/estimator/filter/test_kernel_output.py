"""The output grid of the compiled loop: the next output time after a sample."""

from __future__ import annotations

import numpy as np

from estimator.filter import layout as ly
from estimator.filter.kernel import OUTPUT_STEPS_WALKED, _next_output_after


def _next_after(next_out: float, t: float, out_dt: float) -> float:
    aux = np.zeros(ly.NA)
    aux[ly.A_NEXT_OUT] = next_out
    _next_output_after(aux, t, out_dt)
    return float(aux[ly.A_NEXT_OUT])


def test_the_next_output_is_walked_past_the_sample_on_the_grid() -> None:
    walked = 100.0
    while walked <= 100.26:
        walked += 0.05
    assert _next_after(100.0, 100.26, 0.05) == walked


def test_a_clock_jump_of_years_is_crossed_in_one_step_on_the_grid() -> None:
    """10 years at 20 Hz is 6e9 output intervals: a loop iteration each (audit F2); a million
    times that would never end."""
    out_dt = 0.05
    t = 100.0 + 1e6 * 10 * 365.25 * 86400.0
    nxt = _next_after(100.0, t, out_dt)
    assert t < nxt <= t + out_dt * (1 + 1e-6)
    assert (t - 100.0) / out_dt > OUTPUT_STEPS_WALKED

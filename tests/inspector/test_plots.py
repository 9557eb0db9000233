"""The deviation plots' payloads, as the Plots tab and the export draw them."""

from __future__ import annotations

import pytest
from fake_runs import FakeInputs, make_route, make_run

from inspector.plots import DeviationPlot


def test_plot_payloads_carry_their_own_titles_units_and_time_marker():
    base, prop = make_run(drift=30, method="baseline"), make_run()
    plot = DeviationPlot.build(FakeInputs(None, make_route(), prop.frame), base, prop)
    assert plot.kinds == ("position", "heading")  # no truth in these runs
    titles = set()
    for which in plot.kinds:
        kw = plot.uplot(which, 50.0)
        titles.add(kw["title"])
        xs, _, _, shade, now = kw["data"]
        assert len({len(a) for a in kw["data"]}) == 1 and len(kw["series"]) == 5
        k = int(abs(xs - 50.0).argmin())
        assert now.max() == 2.0 and xs[now.argmax()] == 50.0  # the marker spans the plot
        assert shade[k] == 1.0 and shade[0] == 0.0  # 50 s is inside the outage
        unit = "deg" if which == "heading" else "m"
        assert kw["series"][1]["label"] == f"baseline [{unit}]"
    assert len(titles) == 2
    assert plot.position[0].max() > 20 > plot.position[1].max()  # baseline drifts 30 m


def test_the_truth_plot_draws_the_proposed_runs_own_sigma_beside_its_error():
    """Against truth the proposed run's horizontal 1-sigma is drawn too (dashed): corpus drive
    32's trace, accepted on the route all the way, is 191 m off along the road at 389 s with a
    sigma of 134 m, which the user can read off the plot; without truth there is no such
    series (the position and heading plots keep their five)."""
    import numpy as np

    from estimator.params import Params
    from estimator.pipeline import run_methods
    from estimator.sim.stress import build, drive_spec

    drive = build(drive_spec(32))
    runs = run_methods(drive.inputs, Params())
    base, prop = runs["baseline"], runs["proposed"]
    plot = DeviationPlot.build(drive.inputs, base, prop)
    assert plot.kinds == ("position", "heading", "truth") and plot.sigma is not None
    kw = plot.uplot("truth", 389.0)
    assert len(kw["data"]) == len(kw["series"]) == 6
    assert len({len(a) for a in kw["data"]}) == 1
    assert kw["series"][5]["label"] == "proposed 1-sigma [m]" and kw["series"][5]["dash"]
    xs, sigma = kw["data"][0], kw["data"][5]
    e = prop.epochs
    own = np.hypot(e.position_sigma[:, 0], e.position_sigma[:, 1])
    k = int(np.argmin(np.abs(xs - 389.0)))
    assert sigma[k] == pytest.approx(own[e.index_at(prop.t0 + 389.0)], rel=0.02)
    assert 100.0 < sigma[k] < kw["data"][2][k]  # the error is above the sigma there
    assert len(plot.uplot("position", 389.0)["data"]) == 5
